"""The lean learner's hand-written numpy forward, backward and Adam (satenv.training.rl.nets,
satenv.training.rl.ppo._ppo_grad) against torch's autograd and optimizer on random inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from satenv import tasks  # noqa: E402
from satenv.training.rl import nets, ppo  # noqa: E402
from satenv.vector import SatVectorEnv  # noqa: E402

TASK = "platoon-tplf30-random-cw"


def _run(variant: str, **kw) -> ppo.Run:
    cfg = ppo.LeanConfig(task=TASK, variant=variant, num_envs=4, n_steps=4, **kw)
    return ppo.Run(cfg, SatVectorEnv(tasks.get(TASK).make_env(), cfg.num_envs, autoreset=False), 0.99)


def _perturb(run: ppo.Run, seed: int) -> None:
    """Random weights of a trained-looking size (the actor's head is initialised near zero)."""
    rng = np.random.default_rng(seed)
    run.params.buf[:] = rng.normal(0.0, 0.3, run.params.buf.shape)


def test_parameters_are_views_of_the_flat_buffer():
    net = nets.ActorCritic(36, 3, 36, (64, 64), 4, 0.25)
    flat = net.flat
    total = 0
    for p in net.parameters():
        assert flat.data_ptr() <= p.data_ptr() < flat.data_ptr() + 4 * flat.numel()
        total += p.numel()
    assert total == flat.numel()
    other = nets.ActorCritic(36, 3, 36, (64, 64), 4, 0.5)
    net.load_state_dict(other.state_dict())              # a checkpoint's restore writes into the buffer
    assert torch.equal(flat, other.flat) and math.isclose(float(net.log_std.detach().exp().mean()), 0.5, rel_tol=1e-6)


@pytest.mark.parametrize(("copies", "rows"), [(1, 50), (4, 50), (1, 1024), (4, 1024)])
def test_numpy_forward_is_the_torch_forward(copies, rows):
    """Small batches and large ones (the biases added in tiles: nets._add_bias)."""
    torch.manual_seed(0)
    net = nets.ActorCritic(36, 3, 40, (64, 32), copies, 0.25)
    arrays = nets.FlatArrays(net, net.flat.numpy())
    arrays.buf[:] = np.random.default_rng(1).normal(0.0, 0.3, arrays.buf.shape)
    x = np.random.default_rng(2).normal(size=(rows, 4, 40)).astype(np.float32)
    with torch.no_grad():
        mean = net.mean(torch.from_numpy(x[..., 4:])).numpy()
        value = net.value(torch.from_numpy(x)).numpy()
    out = nets.mlp_forward(arrays.actor_w, arrays.actor_b, nets.to_copies(x[..., 4:], copies), {}, "a")[-1]
    assert np.allclose(nets.from_copies(np.tanh(out), rows), mean, rtol=1e-5, atol=1e-6)
    out = nets.mlp_forward(arrays.critic_w, arrays.critic_b, nets.to_copies(x, copies))[-1]
    assert np.allclose(nets.from_copies(out, rows)[..., 0], value, rtol=1e-5, atol=1e-6)


def _autograd_loss(run: ppo.Run, cin, actions, old_logp, adv, returns) -> torch.Tensor:
    """The clipped-PPO loss as the learner wrote it with autograd (the reference)."""
    cfg, net = run.cfg, run.net
    cin, actions, old_logp, adv, returns = map(torch.from_numpy, (cin, actions, old_logp, adv, returns))
    mean = net.mean(cin[..., run.state_dim:])
    log_std = net.log_std
    z = (actions - mean) / log_std.exp()
    logp = -0.5 * (z * z).sum(-1) - log_std.sum(-1) - 0.5 * run.act_dim * math.log(2 * math.pi)
    ratio = (logp - old_logp).exp()
    a = (adv - adv.mean()) / (adv.std() + 1e-8)
    pg = torch.max(-a * ratio, -a * ratio.clamp(1 - cfg.clip_range, 1 + cfg.clip_range)).mean()
    v_loss = 0.5 * (net.value(cin) - returns).pow(2).mean()
    entropy = (log_std.sum(-1) + 0.5 * run.act_dim * (1 + math.log(2 * math.pi))).mean()
    return pg + cfg.vf_coef * v_loss - cfg.ent_coef * entropy


@pytest.mark.parametrize(("variant", "rows", "onednn"), [("ppo", 300, True), ("ippo", 300, True), ("mappo", 300, True),
                                                         ("ppo", 1024, True), ("ippo", 1024, True), ("ppo", 300, False),
                                                         ("mappo", 1024, False), ("seeded", 1024, True),
                                                         ("seeded", 300, False)])
def test_ppo_gradient_equals_autograd(variant, rows, onednn, monkeypatch, relu_policy_folder, tmp_path):
    """Both product paths: oneDNN's (nets.LINEAR, where this torch has it) and numpy's; ``seeded``: a
    PPO actor seeded from a ReLU policy folder (``init_actor``: its own layout, the critic tanh)."""
    if not onednn:
        monkeypatch.setattr(nets, "LINEAR", None)
    if variant == "seeded":
        run = _run("ppo", ent_coef=0.01, init_actor=str(relu_policy_folder(tmp_path / "seed", TASK)))
        assert run.net.actor.activation == "relu" and run.net.actor_hidden == (16, 16) and run.net.hidden == (64, 64)
    else:
        run = _run(variant, ent_coef=0.01)
    _perturb(run, 3)
    rng = np.random.default_rng(4)
    m = run.vec.n_agents
    cin = rng.normal(size=(rows, m, run.state_dim + run.obs_dim)).astype(np.float32)
    actions = rng.normal(0.0, 0.5, size=(rows, m, run.act_dim)).astype(np.float32)
    with torch.no_grad():   # old log-probabilities near the current ones: some ratios inside the clip range
        mean = run.net.mean(torch.from_numpy(cin[..., run.state_dim:])).numpy()
    z = (actions - mean) / np.exp(run.params.log_std)
    logp = -0.5 * (z * z).sum(-1) - run.params.log_std.sum(-1) - 0.5 * run.act_dim * math.log(2 * math.pi)
    old_logp = (logp + rng.normal(0.0, 0.3, logp.shape)).astype(np.float32)
    adv, returns = (rng.normal(size=(rows, m)).astype(np.float32) for _ in range(2))
    loss = _autograd_loss(run, cin, actions, old_logp, adv, returns)
    run.net.zero_grad()
    loss.backward()
    expected = torch.cat([p.grad.reshape(-1) for p in run.net.parameters()]).numpy()
    grads = nets.FlatArrays(run.net, np.zeros_like(run.params.buf))
    pg, v_loss, clip_fraction, _ = ppo._ppo_grad(run, grads, cin, actions, old_logp, adv, returns)
    assert 0.05 < clip_fraction < 0.95                 # both branches of the clip are exercised
    assert math.isclose(pg + run.cfg.vf_coef * v_loss - run.cfg.ent_coef * (
        float(run.net.log_std.detach().sum(-1).mean()) + 0.5 * run.act_dim * (1 + math.log(2 * math.pi))),
        float(loss), rel_tol=1e-5)
    # the parameters in order of net.parameters() are contiguous in the flat buffer: the same order
    assert np.allclose(grads.buf, expected, rtol=1e-5, atol=1e-5 * np.abs(expected).max())
    assert np.linalg.norm(grads.buf - expected) <= 1e-5 * np.linalg.norm(expected)


def test_onednn_products_equal_numpy():
    if nets.LINEAR is None:
        pytest.skip("this torch build has no oneDNN linear")
    rng = np.random.default_rng(6)
    x = rng.normal(size=(1, 2048, 40)).astype(np.float32)
    w_t, b = rng.normal(size=(1, 64, 40)).astype(np.float32), rng.normal(size=(1, 1, 64)).astype(np.float32)
    expected = x @ w_t.transpose(0, 2, 1) + b
    for operand in (x, x[..., :36], np.asfortranarray(x[0])[None]):     # contiguous or not
        got = nets._times_transposed(operand, w_t[..., :operand.shape[-1]], b)
        assert np.allclose(got, operand @ w_t[..., :operand.shape[-1]].transpose(0, 2, 1) + b, rtol=1e-5, atol=1e-5)
    assert np.allclose(nets._times_transposed(x, w_t.transpose(0, 2, 1).copy().transpose(0, 2, 1), b), expected,
                       rtol=1e-5, atol=1e-5)


def test_adam_step_is_torch_adam():
    rng = np.random.default_rng(5)
    param = torch.from_numpy(rng.normal(size=1000).astype(np.float32))
    p = torch.nn.Parameter(param.clone())
    opt = torch.optim.Adam([p], lr=3e-4, eps=1e-5)
    mine, m, v = param.numpy().copy(), np.zeros(1000, np.float32), np.zeros(1000, np.float32)
    for step in range(1, 6):
        grad = rng.normal(size=1000).astype(np.float32)
        p.grad = torch.from_numpy(grad.copy())
        opt.step()
        nets.adam_step(mine, grad, m, v, step, 3e-4, (0.9, 0.999), 1e-5)
    assert np.allclose(mine, p.detach().numpy(), rtol=0, atol=1e-6)
    assert np.allclose(m, opt.state[p]["exp_avg"].numpy(), rtol=1e-5, atol=1e-8)


def test_update_equals_the_autograd_update():
    """Two epochs of minibatch steps of ``ppo.update`` against the same steps with autograd,
    ``clip_grad_norm_`` and ``torch.optim.Adam`` (the same minibatches: the generator's state copied)."""
    run = _run("ppo", n_epochs=2, minibatch_size=32)
    batch = ppo.collect(run, {"env": 0.0, "forward": 0.0, "update": 0.0})
    ref_net = nets.ActorCritic(run.obs_dim, run.act_dim, run.obs_dim, run.cfg.net_arch, 1, run.cfg.init_std)
    ref_net.load_state_dict(run.net.state_dict())
    ref_opt = torch.optim.Adam(ref_net.parameters(), lr=run.cfg.lr, eps=1e-5)
    gen = torch.Generator()
    gen.set_state(run.gen.get_state())
    T, B, M = batch["rewards"].shape
    rewards = batch["rewards"].copy()
    values = ppo._value(run, batch["critic_obs"].reshape(T * B, M, -1)).reshape(T, B, M)
    for t, copies, c in batch["boot"]:
        rewards[t, copies] += run.gamma * ppo._value(run, c)
    adv, ret = ppo.gae(rewards, values, ppo._value(run, batch["last"]), batch["dones"], run.gamma,
                       run.cfg.gae_lambda)
    n = T * B
    data = [batch["critic_obs"].reshape(n, M, -1), batch["actions"].reshape(n, M, -1), batch["logp"].reshape(n, M),
            adv.reshape(n, M), ret.reshape(n, M)]
    rows = run.cfg.minibatch_size // M
    ppo.update(run, batch, {"update": 0.0})
    ref_run = type("R", (), {"cfg": run.cfg, "net": ref_net, "state_dim": 0, "act_dim": run.act_dim})
    for _ in range(run.cfg.n_epochs):
        perm = torch.randperm(n, generator=gen).numpy()
        for start in range(0, n - rows + 1, rows):
            mb = perm[start:start + rows]
            loss = _autograd_loss(ref_run, *(x[mb] for x in data))
            ref_opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(ref_net.parameters(), run.cfg.max_grad_norm)
            ref_opt.step()
    assert torch.allclose(run.net.flat, ref_net.flat, rtol=0, atol=1e-6)
    for p, q in zip(run.net.parameters(), ref_net.parameters(), strict=True):   # what a checkpoint saves
        assert float(run.opt.state[p]["step"]) == float(ref_opt.state[q]["step"])
        assert torch.allclose(run.opt.state[p]["exp_avg_sq"], ref_opt.state[q]["exp_avg_sq"], rtol=1e-4, atol=1e-12)


def test_large_minibatches_are_deterministic():
    """A seed fixes the run on the oneDNN path too (4,096-row minibatches; the tiny runs of
    tests/test_lean_ppo.py stay below nets.LINEAR_MIN_ROWS)."""
    flats = []
    for _ in range(2):
        vec = SatVectorEnv(tasks.get(TASK).make_env(), 64, autoreset=False)
        run = ppo.Run(ppo.LeanConfig(task=TASK, num_envs=64, n_steps=32, n_epochs=2, minibatch_size=4096), vec, 0.99)
        timers = {"env": 0.0, "forward": 0.0, "update": 0.0}
        ppo.update(run, ppo.collect(run, timers), timers)
        flats.append(run.net.flat.clone())
    assert torch.equal(flats[0], flats[1])
