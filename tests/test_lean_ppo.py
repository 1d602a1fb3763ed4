"""The lean batched PPO (satenv.training.rl.ppo): tiny runs write a loadable policy folder, a seed
fixes the run, a resumed run equals the uninterrupted one; the slow test compares it with SB3 PPO."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

pytest.importorskip("torch")

from satenv import tasks  # noqa: E402
from satenv.training.rl import ppo  # noqa: E402

TASK = "platoon-tplf30-random-cw"
TINY = {"task": TASK, "num_envs": 4, "n_steps": 8, "minibatch_size": 64, "n_epochs": 2, "test_seeds": (900000,),
        "eval_baselines": ("zero",), "workers": 1, "progress": False, "checkpoint_every": 0}
"""128 agent-steps an iteration; the final evaluation on one test seed beside zero thrust."""


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))


def _weights(folder):
    from safetensors.numpy import load_file

    return load_file(str(folder / "weights.safetensors"))


def test_tiny_run_writes_a_loadable_policy_folder(tmp_path, capsys):
    import satenv
    from satenv.training import load

    out = tmp_path / "run"
    code = ppo.main(["--task", TASK, "--budget", "3000", "--num-envs", "4", "--n-steps", "8",
                     "--minibatch-size", "64", "--test-seeds", "900000", "--eval-baselines", "zero",
                     "--workers", "1", "--no-progress", "--out-dir", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    assert "budget 3,000 agent-steps" in err and "24 iterations" in err and "expected" in err
    final = out / "final"
    for name in ("policy.json", "weights.safetensors", "manifest.json", "eval.json", "obs_norm.json", "env.json"):
        assert (final / name).is_file(), name
    env = satenv.make("platoon_v0", **tasks.get(TASK).env_kwargs)
    policy = load(final, env=env)
    obs, _ = env.reset(seed=900001)
    actions = policy.act(obs)
    assert set(actions) == set(env.possible_agents)
    assert all(a.shape == (3,) and np.all(np.abs(a) <= 1) for a in actions.values())
    rows = [json.loads(line) for line in (out / "progress.jsonl").read_text().splitlines()]
    assert [r["agent_steps"] for r in rows] == [128 * k for k in range(1, 25)]
    assert json.loads((final / "eval.json").read_text())["steps"] == 3072
    assert list((out / "tb").iterdir())


@pytest.mark.parametrize("norm_obs", [False, True])
def test_exported_actor_is_the_trained_mean(tmp_path, norm_obs):
    import torch

    from satenv.training import load

    cfg = ppo.LeanConfig(**TINY, budget=256, norm_obs=norm_obs, out_dir=str(tmp_path / "run"))
    ppo.train(cfg)
    policy = load(tmp_path / "run" / "final")
    norm = json.loads((tmp_path / "run" / "final" / "obs_norm.json").read_text())
    obs = np.random.default_rng(0).normal(size=(5, policy.obs_shape[0])) * 10
    run = ppo.Run(cfg, __import__("satenv.vector", fromlist=["x"]).SatVectorEnv(
        tasks.get(TASK).make_env(), 4, autoreset=False), 0.99)
    ckpt = ppo.latest_checkpoint(tmp_path / "run")
    ppo.load_checkpoint(run, ckpt)
    if norm_obs:
        x = np.clip((obs - np.array(norm["mean"])) / np.sqrt(np.array(norm["var"]) + 1e-8), -10, 10)
    else:   # the envs' own scales: the folder says so and the actor reads the observation as it is
        assert norm == {"identity": True}
        x = obs
    with torch.no_grad():
        mean = run.net.mean(torch.as_tensor(x, dtype=torch.float32)[:, None]).numpy()[:, 0]
    assert np.allclose(policy.predict(obs), mean, atol=1e-6)


def test_a_seed_fixes_the_run_and_resume_equals_uninterrupted(tmp_path):
    whole = ppo.train(ppo.LeanConfig(**TINY, budget=512, out_dir=str(tmp_path / "a")))
    again = ppo.train(ppo.LeanConfig(**TINY, budget=512, out_dir=str(tmp_path / "b")))
    ppo.train(ppo.LeanConfig(**TINY, budget=256, out_dir=str(tmp_path / "c")))
    assert ppo.main(["--out-dir", str(tmp_path / "c"), "--resume", "--budget", "512"]) == 0
    other = ppo.train(ppo.LeanConfig(**{**TINY, "seed": 1}, budget=512, out_dir=str(tmp_path / "d")))
    w = _weights(whole)
    for folder in (again, tmp_path / "c" / "final"):
        assert all(np.array_equal(w[k], v) for k, v in _weights(folder).items())
    assert not all(np.array_equal(w[k], v) for k, v in _weights(other).items())
    lines = (tmp_path / "c" / "progress.jsonl").read_text().splitlines()
    assert [json.loads(x)["agent_steps"] for x in lines] == [128, 256, 384, 512]


def test_resume_without_a_checkpoint_starts_the_run_fresh(tmp_path, capsys):
    """An "always --resume" loop is never stuck: a folder with no run, or with a run killed before
    its first checkpoint (its config.json written), starts fresh, says so, and ends as a run
    without --resume."""
    argv = ["--task", TASK, "--num-envs", "4", "--n-steps", "8", "--minibatch-size", "64", "--n-epochs", "2",
            "--test-seeds", "900000", "--eval-baselines", "zero", "--workers", "1", "--no-progress",
            "--checkpoint-every", "0", "--budget", "128"]
    assert ppo.main([*argv, "--out-dir", str(tmp_path / "plain")]) == 0
    assert ppo.main([*argv, "--out-dir", str(tmp_path / "none"), "--resume"]) == 0
    assert "config.json does not exist" in capsys.readouterr().err
    killed = tmp_path / "killed"
    assert ppo.main([*argv, "--out-dir", str(killed)]) == 0
    for folder in ("checkpoints", "final"):        # as a kill before the first checkpoint leaves it
        shutil.rmtree(killed / folder)
    assert ppo.main([*argv, "--out-dir", str(killed), "--resume"]) == 0
    assert "no checkpoint under" in capsys.readouterr().err
    w = _weights(tmp_path / "plain" / "final")
    for folder in (tmp_path / "none", killed):
        assert all(np.array_equal(w[k], v) for k, v in _weights(folder / "final").items())
    with pytest.raises(ValueError, match="already has checkpoints"):
        ppo.train(ppo.LeanConfig(**TINY, budget=128, out_dir=str(killed)))


@pytest.mark.parametrize("variant", ["ippo", "mappo"])
def test_variants_train_and_write_their_folders(tmp_path, variant):
    from satenv.training import load

    final = ppo.train(ppo.LeanConfig(**TINY, variant=variant, budget=256, out_dir=str(tmp_path / "run")))
    env = tasks.get(TASK).make_env()
    if variant == "ippo":   # one policy folder per agent, each its own actor
        folders = [final / "agents" / a for a in env.possible_agents]
        ws = [_weights(f) for f in folders]
        assert not all(np.array_equal(ws[0][k], ws[1][k]) for k in ws[0])
        assert (final / "eval.json").is_file()
    else:
        folders = [final]
    for f in folders:
        assert load(f).predict(np.zeros((2, 36))).shape == (2, 3)


def test_gamma_follows_the_horizon_and_bad_input_is_named(tmp_path, capsys):
    assert math.isclose(ppo.horizon_gamma(180, 3.0), 1 - 3 / 180)
    with pytest.raises(ValueError, match="variant"):
        ppo.LeanConfig(task=TASK, variant="sac")
    with pytest.raises(ValueError, match="minibatch_size"):
        ppo.LeanConfig(task=TASK, minibatch_size=0)
    assert ppo.main(["--task", TASK, "--gamma-k", "500", "--budget", "128", "--num-envs", "4", "--n-steps", "8",
                     "--out-dir", str(tmp_path / "x")]) == 2
    assert "gamma_k" in capsys.readouterr().err
    assert ppo.main(["--task", TASK, "--env-kwargs", '{"nope": 1}', "--out-dir", str(tmp_path / "k")]) == 2
    assert "error: --env-kwargs: platoon_v0: unknown keyword argument(s) ['nope']" in capsys.readouterr().err
    assert not (tmp_path / "k").exists()
    with pytest.raises(SystemExit):
        ppo.main(["--budg", "10"])      # no abbreviations


def test_untrained_mean_is_near_zero_thrust(tmp_path):
    import torch

    from satenv.training.rl.nets import ActorCritic

    torch.manual_seed(0)
    net = ActorCritic(36, 3, 36, (64, 64), 1, 0.25)
    with torch.no_grad():
        mean = net.mean(torch.randn(256, 4, 36) * 3)
    assert float(mean.abs().max()) < 0.1 and math.isclose(float(net.log_std.detach().exp().mean()), 0.25, rel_tol=1e-6)


# ------------------------------------------------------------------------------------ slow
SB3_MATCH_BUDGET = 3_000_000
"""Agent-steps per run of the slow comparison (the same for both learners)."""
SB3_MATCH_TASK = "platoon-tplf30-rung1-near"
"""The first rung of the TPLF platoon's ladder (``tasks.ladder("platoon-pereira2023")[0]``), on its
training reward: the rung where PPO is expected to reach success."""
SB3_MATCH_SEEDS = (0, 1, 2)
SB3_MATCH_TEST_SEEDS = tuple(range(900000, 900020))


@pytest.mark.slow
def test_lean_ppo_matches_sb3_ppo_on_the_platoon(tmp_path):
    """Same task (the platoon ladder's first rung), budget, seeds, network, batch and discount: the
    lean learner's mean test success is within the seeds' spread of SB3 PPO's (the larger of the two
    standard deviations, and at least one test episode's worth)."""
    from satenv.training.config import TrainConfig
    from satenv.training.train import train as sb3_train

    assert tasks.ladder("platoon-pereira2023")[0] == SB3_MATCH_TASK
    shared = {"task": SB3_MATCH_TASK, "test_seeds": SB3_MATCH_TEST_SEEDS, "eval_baselines": ("zero",), "workers": 1,
              "progress": False, "net_arch": (64, 64), "lr": 3e-4}
    gamma = ppo.horizon_gamma(tasks.get(SB3_MATCH_TASK).make_env().scenario.max_steps, 3.0)
    lean, sb3 = [], []
    for seed in SB3_MATCH_SEEDS:
        f = ppo.train(ppo.LeanConfig(**shared, seed=seed, budget=SB3_MATCH_BUDGET, num_envs=64, n_steps=32,
                                     minibatch_size=4096, n_epochs=2, out_dir=str(tmp_path / f"lean{seed}")))
        lean.append(json.loads((f / "eval.json").read_text())["aggregate"]["learned"])
        f = sb3_train(TrainConfig(**shared, seed=seed, total_timesteps=SB3_MATCH_BUDGET, num_envs=64, n_steps=32,
                                  batch_size=4096, n_epochs=2, gamma=gamma, log_std_init=math.log(0.25),
                                  eval_every=0, checkpoint_every=0, out_dir=str(tmp_path / f"sb3{seed}")))
        sb3.append(json.loads((f / "eval.json").read_text())["aggregate"]["learned"])
    report = {name: {k: [r[k] for r in rows] for k in ("success_rate", "final_error_m", "rmse")}
              for name, rows in (("lean", lean), ("sb3", sb3))}
    print(json.dumps(report))
    s_lean, s_sb3 = np.array(report["lean"]["success_rate"]), np.array(report["sb3"]["success_rate"])
    spread = max(s_lean.std(), s_sb3.std(), 1 / len(SB3_MATCH_TEST_SEEDS))
    assert abs(s_lean.mean() - s_sb3.mean()) <= spread + 1e-12, report   # 1e-12: float rounding of k / 20


def test_tuned_configs_are_valid_and_flags_override_them():
    import dataclasses

    fields = {f.name for f in dataclasses.fields(ppo.LeanConfig)}
    files = sorted(ppo.TUNED_DIR.glob("*.json"))
    assert files
    for path in files:
        doc = json.loads(path.read_text())
        assert doc["task"] == path.stem and doc["task"] in tasks.TASKS
        assert doc["chosen_on"]["split"] == "validation" and set(doc["config"]) <= fields
        ppo.LeanConfig(task=doc["task"], **doc["config"])
    assert ppo.tuned("platoon-tplf30-near10") == {"lr": 0.001} and ppo.tuned(TASK) == {}
    cfg, _ = ppo.config_from_args(["--task", "platoon-tplf30-near10", "--tuned"])
    assert cfg.lr == 0.001
    cfg, _ = ppo.config_from_args(["--task", "platoon-tplf30-near10", "--tuned", "--lr", "0.0002"])
    assert cfg.lr == 0.0002


def test_warm_start_takes_the_network_and_statistics_and_refuses_another_shape(tmp_path, capsys):
    """A run warm-started from another starts from its weights (the first rung's run into the
    second rung: the same shapes), with a fresh step counter; a network of another shape is refused
    with the source named, before anything trains."""
    import torch

    src = tmp_path / "rung1"
    ppo.train(ppo.LeanConfig(**TINY, budget=256, seed=3, out_dir=str(src)))
    ckpt = ppo.latest_checkpoint(src)
    cfg = ppo.LeanConfig(**TINY, budget=128, seed=4, warm_start=str(src), out_dir=str(tmp_path / "rung2"))
    vec = __import__("satenv.vector", fromlist=["x"]).SatVectorEnv(tasks.get(TASK).make_env(), 4, autoreset=False)
    run = ppo.Run(cfg, vec, 0.99)
    fresh = {k: v.clone() for k, v in run.net.state_dict().items()}
    assert ppo.warm_start(run, src) == ckpt
    saved = ppo.Run(cfg, vec, 0.99)
    ppo.load_checkpoint(saved, ckpt)
    for k, v in run.net.state_dict().items():
        assert torch.equal(v, saved.net.state_dict()[k]), k
    assert any(not torch.equal(v, fresh[k]) for k, v in run.net.state_dict().items())
    assert run.steps == 0
    ppo.train(cfg)
    assert "warm start from" in capsys.readouterr().err
    assert json.loads((tmp_path / "rung2" / "config.json").read_text())["warm_start"] == str(src)

    wide = ppo.LeanConfig(**TINY, budget=128, net_arch=(8, 8), warm_start=str(src), out_dir=str(tmp_path / "w"))
    with pytest.raises(ValueError, match="warm_start: the network of .*step_256.* does not fit"):
        ppo.train(wide)
    assert not (tmp_path / "w" / "checkpoints").exists()
    with pytest.raises(ValueError, match="holds no lean checkpoint"):
        ppo.train(ppo.LeanConfig(**TINY, budget=128, warm_start=str(tmp_path / "none"), out_dir=str(tmp_path / "n")))
    with pytest.raises(ValueError, match="warm_start must be"):
        ppo.LeanConfig(**TINY, warm_start="")


def test_init_actor_starts_from_a_policy_folder_in_its_layout(relu_policy_folder, tmp_path, monkeypatch):
    """A run seeded from a policy folder (``init_actor``: an imitation network's layout, features,
    frozen normalisation, action map and terminal feedback) acts as the folder does; through the
    critic's warm-up its actor keeps its values, after it the actor learns; the final folder reloads
    as the same policy. A seed that does not fit the env, or with running observation statistics, is
    refused naming the problem."""
    from satenv.training.policy import load

    seed = relu_policy_folder(tmp_path / "seed", TASK, terminal=True)
    assert load(seed).terminal is not None and load(seed).action_map is not None
    env = tasks.get(TASK).make_env()
    obs, _ = env.reset(seed=900001)
    before = load(seed).act(obs)
    warm = ppo.train(ppo.LeanConfig(**TINY, budget=256, init_actor=str(seed), critic_warmup=256,
                                    out_dir=str(tmp_path / "warm")))
    after = load(warm).act(obs)
    assert all(np.allclose(before[a], after[a], atol=1e-6) for a in obs)
    saved = json.loads((warm / "config.json").read_text())
    assert saved["obs_symlog_scale"] == 10.0 and saved["terminal"]["radius"] == 2.0 and saved["action_power"] == 2.0
    moved = ppo.train(ppo.LeanConfig(**TINY, budget=256, init_actor=str(seed), out_dir=str(tmp_path / "moved")))
    assert not all(np.allclose(before[a], load(moved).act(obs)[a], atol=1e-6) for a in obs)

    from satenv.vector import SatVectorEnv  # the rollout gives the env what the folder's policy gives it
    cfg = ppo.LeanConfig(**TINY, init_actor=str(seed), init_std=1e-6)
    run = ppo.Run(cfg, SatVectorEnv(env, 4, autoreset=False), 0.99)
    obs0, sent = run.obs.copy(), []
    step = run.vec.step
    run.vec.step = lambda act: sent.append(act.copy()) or step(act)
    ppo.collect(run, {"env": 0.0, "forward": 0.0})
    expected = load(seed).predict(obs0.reshape(-1, obs0.shape[-1])).reshape(sent[0].shape)
    assert np.allclose(sent[0], expected, atol=1e-4)

    other = relu_policy_folder(tmp_path / "other", "servicing-pereira2022")
    with pytest.raises(ValueError, match=r"init_actor .*observation / action shapes"):
        ppo.train(ppo.LeanConfig(**TINY, budget=128, init_actor=str(other), out_dir=str(tmp_path / "o")))
    with monkeypatch.context() as m:   # a copy that missed the weights is caught before training
        m.setattr(ppo, "_copy_actor", lambda net, actor: None)
        with pytest.raises(ValueError, match="does not reproduce the folder's actions"):
            ppo.train(ppo.LeanConfig(**TINY, budget=128, init_actor=str(seed), out_dir=str(tmp_path / "c")))
    with pytest.raises(ValueError, match="not with norm_obs"):
        ppo.LeanConfig(**TINY, init_actor=str(seed), norm_obs=True)
    with pytest.raises(ValueError, match="critic_warmup must be an int >= 0"):
        ppo.LeanConfig(**TINY, critic_warmup=-1)


def test_target_kl_stops_the_epochs_at_the_first_minibatch_too_far(tmp_path):
    """A step of lr 1 moves the policy far past a target KL of 1e-3: each iteration makes one gradient
    step (its first minibatch is at the collecting policy: KL 0 up to rounding); without a target,
    every epoch's minibatches."""
    def steps(**kw):
        out = tmp_path / str(len(kw))
        ppo.train(ppo.LeanConfig(**TINY, budget=256, out_dir=str(out), **kw))
        return [json.loads(ln)["gradient_steps"] for ln in (out / "progress.jsonl").read_text().splitlines()]

    assert steps() == [2 * 128 // 64] * 2                  # n_epochs x minibatches of an iteration
    assert steps(target_kl=1e-3, lr=1.0) == [1, 1]
    with pytest.raises(ValueError, match="target_kl must be a number in"):
        ppo.LeanConfig(**TINY, target_kl=0.0)


def test_actor_lr_sets_the_actors_rate_apart_from_the_critics(tmp_path):
    """``actor_lr`` moves the actor's weights and std at its own rate, the critic's at ``lr``: at a
    rate 1e-6 of ``lr`` the actor moves about a millionth as far as at ``lr``; the critic about as far."""
    def moved(**kw):
        vec = __import__("satenv.vector", fromlist=["x"]).SatVectorEnv(tasks.get(TASK).make_env(), 4, autoreset=False)
        run = ppo.Run(ppo.LeanConfig(**TINY, **kw), vec, 0.99)
        before = {k: v.clone() for k, v in run.net.state_dict().items()}
        timers = {"env": 0.0, "forward": 0.0, "update": 0.0}
        ppo.update(run, ppo.collect(run, timers), timers)
        after = run.net.state_dict()
        return {part: sum(float((after[k] - before[k]).abs().sum()) for k in after if k.startswith(part))
                for part in ("actor", "critic", "log_std")}

    same, slow = moved(), moved(actor_lr=3e-10)
    assert math.isclose(slow["critic"], same["critic"], rel_tol=0.05)   # one gradient-norm clip over both
    for part in ("actor", "log_std"):
        assert slow[part] < 1e-5 * same[part] and same[part] > 0
    with pytest.raises(ValueError, match="actor_lr must be a number in"):
        ppo.LeanConfig(**TINY, actor_lr=-1.0)
    with pytest.raises(ValueError, match="actor_lr must be a finite number > 0, got inf"):
        ppo.LeanConfig(**TINY, actor_lr=math.inf)
