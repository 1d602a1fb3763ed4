"""satenv.make_vec: the batched numpy vector env reproduces the PettingZoo env copy by copy."""

import numpy as np
import pytest

import satenv
from satenv.envs.base import SatenvError
from satenv.vector import FINAL_ALIASES, SatVectorEnv

B = 3


def _stack(d, agents):
    return np.stack([d[a] for a in agents])


CASES = [
    ("platoon_v0", {"randomize": True}),
    ("cluster_v0", {"disturbance": "random"}),  # in-step randomness: per-copy streams
    ("cluster_v0", {"preset": "li2022-case1", "randomize": True}),  # random target slots per copy
    ("servicing_v0", {"randomize": True}),
    ("formation_v0", {"randomize": True}),
]


@pytest.mark.parametrize(("env_id", "kwargs"), CASES, ids=[c[0] + "-" + "-".join(c[1]) for c in CASES])
def test_copy_b_reproduces_the_pettingzoo_env_across_an_auto_reset(env_id, kwargs):
    steps, seed = 3, 11
    kw = {**kwargs, "max_steps": steps}
    vec = satenv.make_vec(env_id, B, seed=seed, **kw)
    envs = [satenv.make(env_id, **kw) for _ in range(B)]
    agents = envs[0].possible_agents
    obs, infos = vec.reset()
    assert obs.shape == (B, len(agents), *vec.single_observation_space.shape) and obs.dtype == np.float32
    assert vec.state().shape == (B, *envs[0].state().shape)
    pz_obs = [env.reset(seed=seed + b)[0] for b, env in enumerate(envs)]
    rng = np.random.default_rng(0)
    for k in range(2 * steps):  # crosses one auto-reset
        for b, env in enumerate(envs):
            np.testing.assert_array_equal(obs[b], _stack(pz_obs[b], agents))
            np.testing.assert_array_equal(vec.state()[b], env.state())
        act = rng.uniform(-1.2, 1.2, size=vec.action_shape)
        obs, rew, term, trunc, infos = vec.step(act)
        assert rew.shape == term.shape == trunc.shape == (B, len(agents))
        for b, env in enumerate(envs):
            o, r, te, tr, inf = env.step({a: act[b, i] for i, a in enumerate(agents)})
            np.testing.assert_array_equal(rew[b], [r[a] for a in agents])
            assert term[b].tolist() == [te[a] for a in agents] and trunc[b].tolist() == [tr[a] for a in agents]
            step_info = infos["final_info"] if "_final_obs" in infos else infos
            np.testing.assert_array_equal(step_info["state"][b], _stack({a: inf[a]["state"] for a in agents}, agents))
            if te[agents[0]] or tr[agents[0]]:
                assert infos["_final_obs"][b] and infos["_final_info"][b]
                np.testing.assert_array_equal(infos["final_obs"][b], _stack(o, agents))
                o, _ = env.reset()  # the PettingZoo env continues its own stream
            pz_obs[b] = o
        assert ((k + 1) % steps == 0) == ("_final_obs" in infos)


def test_auto_reset_infos_and_partial_termination():
    from test_env_base import ToyEnv

    vec = SatVectorEnv(ToyEnv(), 4, seed=5)
    vec.reset()
    vec.core.x[1] = 0.0  # copy 1: agents at rest almost on top of each other -> collision
    vec.core.x[1, :, 0] = [0.0, 0.05, 3.0]
    obs, _, term, trunc, infos = vec.step(np.zeros(vec.action_shape))
    assert term.tolist() == [[False] * 3, [True] * 3, [False] * 3, [False] * 3] and not trunc.any()
    assert infos["_final_obs"].tolist() == infos["_final_info"].tolist() == [False, True, False, False]
    for old, new in FINAL_ALIASES.items():     # the former names: the same arrays, for one release
        assert infos[old] is infos[new]
    assert infos["final_info"]["collision"][1].any()
    assert not infos["collision"][1].any()  # the reset info of copy 1's new episode
    assert vec.core.t.tolist() == [1, 0, 1, 1]
    np.testing.assert_array_equal(obs, vec.core.observe())
    assert not np.allclose(obs[1], infos["final_obs"][1])


def test_seeding_reset_without_seed_continues_and_fresh_entropy():
    vec = satenv.make_vec("formation_v0", 2, seed=3, randomize=True)
    first, _ = vec.reset()
    again, _ = vec.reset()
    assert not np.array_equal(first, again)  # the per-copy streams continue
    np.testing.assert_array_equal(vec.reset(seed=3)[0], first)
    a, _ = satenv.make_vec("formation_v0", 2, randomize=True).reset()
    b, _ = satenv.make_vec("formation_v0", 2, randomize=True).reset()
    assert not np.array_equal(a, b)


def test_bad_input_errors():
    with pytest.raises(SatenvError, match="num_envs"):
        satenv.make_vec("platoon_v0", 0)
    with pytest.raises(ValueError, match="unknown env id"):
        satenv.make_vec("nope_v0", 2)
    with pytest.raises(SatenvError, match="satenv env"):
        SatVectorEnv(object(), 2)
    with pytest.raises(SatenvError, match="seed"):
        satenv.make_vec("platoon_v0", 2, seed=-1)
    with pytest.raises(SatenvError, match="unknown keyword"):
        satenv.make_vec("platoon_v0", 2, bogus=1)
    vec = satenv.make_vec("platoon_v0", 2, seed=0)
    with pytest.raises(SatenvError, match="before reset"):
        vec.step(np.zeros(vec.action_shape))
    vec.reset()
    before = vec.state()
    with pytest.raises(SatenvError, match=r"shape \(2, 4, 3\)"):
        vec.step(np.zeros((8, 3)))
    bad = np.zeros(vec.action_shape)
    bad[1, 2, 0] = np.nan
    with pytest.raises(SatenvError, match="finite"):
        vec.step(bad)
    for wrong, kind in ((np.zeros(vec.action_shape) + 1j, TypeError), (np.zeros(vec.action_shape, bool), TypeError),
                        (np.ma.masked_array(np.zeros(vec.action_shape), mask=True), TypeError),
                        (np.full(vec.action_shape, 10**400, dtype=object), ValueError), ("0", TypeError)):
        with pytest.raises(kind, match="actions"):
            vec.step(wrong)
    np.testing.assert_array_equal(vec.state(), before)
    with pytest.raises(SatenvError, match="MAX_COPIES"):
        satenv.make_vec("platoon_v0", 10**9)
    with pytest.raises(TypeError, match="num_envs"):
        satenv.make_vec("platoon_v0", 2.0)


@pytest.mark.parametrize("autoreset", [True, False])
def test_finiteness_guard_names_copy_agent_step_and_quantity(autoreset):
    vec = SatVectorEnv(satenv.platoon_v0(), 3, seed=0, autoreset=autoreset)
    vec.reset()
    vec.step(np.zeros(vec.action_shape))
    vec.core.x[2, 1, 0] = np.nan          # corrupt one copy's state from outside (as a bug would)
    with pytest.raises(SatenvError, match=r"copy 2: .*state of follower_2.* at step 2; those episodes are over"):
        vec.step(np.zeros(vec.action_shape))
    with pytest.raises(SatenvError, match=r"copies \[2\] have ended"):
        vec.step(np.zeros(vec.action_shape))
    vec.reset(indices=[2])                # the copy starts over; the others go on
    obs, rew, *_ = vec.step(np.zeros(vec.action_shape))
    assert np.isfinite(obs).all() and np.isfinite(rew).all()


def test_one_batched_core_step_per_step(monkeypatch):
    vec = satenv.make_vec("platoon_v0", 8, seed=0)
    vec.reset()
    calls = []
    original = vec.core.step_observe   # the step and its observations: one batched call
    monkeypatch.setattr(vec.core, "step_observe",
                        lambda accel, rng=None: calls.append(accel.shape) or original(accel, rng))
    vec.step(np.zeros(vec.action_shape))
    assert calls == [(8, 4, 3)]


@pytest.mark.parametrize(("env_id", "kwargs"), [
    ("platoon_v0", {}), ("platoon_v0", {"dynamics": "j2", "inclination": 0.9}),
    ("cluster_v0", {}), ("cluster_v0", {"method": "sparse"}), ("servicing_v0", {}), ("formation_v0", {})])
def test_observe_copies_are_the_rows_of_observe(env_id, kwargs):
    """What the auto-reset observes (only the copies that reset) equals the full observation's rows,
    bit for bit, with copies at different steps."""
    kwargs = dict(kwargs)
    method = kwargs.pop("method", None)
    vec = satenv.make_vec(env_id, 6, seed=0, **kwargs)
    if method is not None:   # the cluster core's sparse neighbour path
        vec.core = type(vec.core)(vec.scenario, batch=6, method=method)
    vec.reset()
    rng = np.random.default_rng(0)
    for k in range(3):
        vec.step(rng.uniform(-1, 1, vec.action_shape))
        vec.reset(indices=[k])
    idx = np.array([4, 0, 2])
    np.testing.assert_array_equal(vec.core.observe_copies(idx), vec.core.observe()[idx])


def test_the_episode_state_round_trips_with_the_training_rewards_memory():
    """``get_state`` / ``set_state``: a fresh batch given a batch's state mid-episode steps on to
    the same observations and training rewards (the reward's per-copy memory included); a state
    without that memory, or of another batch size, is refused naming the entry, the batch unchanged."""
    from satenv import tasks

    env = tasks.get("platoon-pereira2022-random").make_env()
    a, b = SatVectorEnv(env, 3, seed=4), SatVectorEnv(env, 3, seed=9)
    assert a.reward_state is not None
    rng = np.random.default_rng(0)
    a.reset(), b.reset()
    for _ in range(5):
        a.step(rng.uniform(-1, 1, a.action_shape))
    state = a.get_state()
    assert any(k.startswith("reward.") for k in state)
    b.set_state(state)
    for _ in range(5):
        act = rng.uniform(-1, 1, a.action_shape)
        one, two = a.step(act), b.step(act)
        assert np.array_equal(one[0], two[0]) and np.array_equal(one[1], two[1])
    before = b.get_state()
    key = next(k for k in state if k.startswith("reward."))
    with pytest.raises(SatenvError, match=f"no '{key}' entry"):
        b.set_state({k: v for k, v in state.items() if k != key})
    with pytest.raises(SatenvError, match="copies|does not match"):
        b.set_state(_state_of(SatVectorEnv(env, 2, seed=1)))
    after = b.get_state()
    assert all(np.array_equal(before[k], after[k]) for k in before)


def _state_of(vec):
    vec.reset()
    return vec.get_state()
