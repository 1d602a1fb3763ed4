"""satenv.training.vec_env.SatVecEnv: the parameter-shared SB3 VecEnv over a batched core (toy core)."""

import numpy as np
import pytest
from test_env_base import ToyEnv

from satenv.envs.base import SatenvError
from satenv.training.vec_env import SatVecEnv, env_version, make_env

B, M = 4, 3


def _rows(vec, x):  # (B*M, ...) -> (B, M, ...)
    return x.reshape(vec.n_copies, vec.n_agents, *x.shape[1:])


def test_shapes_spaces_and_row_layout():
    vec = SatVecEnv(ToyEnv(), n_copies=B, seed=0)
    assert vec.num_envs == B * M and vec.n_agents == M
    assert vec.observation_space == ToyEnv().observation_space("sat_1")
    assert vec.action_space == ToyEnv().action_space("sat_1")
    obs = vec.reset()
    assert obs.shape == (B * M, 6) and obs.dtype == np.float32
    # row r = agent r % M of copy r // M
    np.testing.assert_array_equal(_rows(vec, obs), vec.core.observe())
    obs, rew, done, infos = vec.step(np.zeros((B * M, 3), dtype=np.float32))
    assert obs.shape == (B * M, 6) and rew.shape == (B * M,) and done.shape == (B * M,)
    assert rew.dtype == np.float32 and done.dtype == bool and len(infos) == B * M
    assert vec.last_info["state"].shape == (B, M, 6)


@pytest.mark.parametrize("mode", ["box", "norm"])
def test_matches_the_pettingzoo_env_copy_by_copy(mode):
    """Copy b with vec seed s reproduces ToyEnv.reset(seed=s+b) + the same actions (scaling too)."""
    kwargs = {"thrust_mode": mode, "u_max": 0.5}
    vec = SatVecEnv(ToyEnv(**kwargs), n_copies=B, seed=10)
    envs = [ToyEnv(**kwargs) for _ in range(B)]
    obs = _rows(vec, vec.reset())
    for b, env in enumerate(envs):
        o, _ = env.reset(seed=10 + b)
        np.testing.assert_array_equal(obs[b], np.stack([o[a] for a in env.possible_agents]))
    rng = np.random.default_rng(1)
    for _ in range(5):
        act = rng.uniform(-1.5, 1.5, size=(B, M, 3))  # out-of-range entries are clipped
        obs, rew, _, _ = vec.step(act.reshape(B * M, 3))
        obs, rew = _rows(vec, obs), _rows(vec, rew)
        for b, env in enumerate(envs):
            o, r, *_ = env.step({a: act[b, i] for i, a in enumerate(env.possible_agents)})
            np.testing.assert_allclose(obs[b], np.stack([o[a] for a in env.possible_agents]), rtol=1e-6)
            np.testing.assert_allclose(rew[b], [r[a] for a in env.possible_agents], rtol=1e-6)


def test_one_batched_core_step_per_vec_step(monkeypatch):
    vec = SatVecEnv(ToyEnv(), n_copies=8, seed=0)
    vec.reset()
    calls = []
    original = vec.core.step
    monkeypatch.setattr(vec.core, "step", lambda accel, rng=None: calls.append(accel.shape) or original(accel, rng))
    vec.step(np.zeros((8 * M, 3)))
    assert calls == [(8, M, 3)]


def test_truncation_auto_reset_and_terminal_observation():
    vec = SatVecEnv(ToyEnv(max_steps=5), n_copies=B, seed=3)
    env = ToyEnv(max_steps=5)
    vec.reset()
    for k in range(5):
        obs, _, done, infos = vec.step(np.full((B * M, 3), 0.3))
        if k < 4:
            assert not done.any() and all(i == {} for i in infos)
    assert done.all()
    # terminal observation = the PettingZoo env's last observation of copy 0
    env.reset(seed=3)
    for _ in range(5):
        last, *_ = env.step({a: np.full(3, 0.3) for a in env.possible_agents})
    for m, a in enumerate(env.possible_agents):
        np.testing.assert_allclose(infos[m]["terminal_observation"], last[a], rtol=1e-6)
        assert infos[m]["TimeLimit.truncated"] is True
    # returned obs: fresh episodes (step counters back to 0), not the terminal ones
    assert (vec.core.t == 0).all()
    np.testing.assert_array_equal(_rows(vec, obs), vec.core.observe())
    assert not np.allclose(obs[0], infos[0]["terminal_observation"])
    assert vec.episode_count == B


def test_termination_resets_only_that_copy_and_is_not_a_truncation():
    vec = SatVecEnv(ToyEnv(), n_copies=B, seed=5)
    vec.reset()
    vec.core.x[1] = 0.0  # copy 1: all agents at rest at the origin -> collision after the step
    vec.core.x[1, :, 0] = [0.0, 0.05, 3.0]
    before = vec.core.x.copy()
    obs, _, done, infos = vec.step(np.zeros((B * M, 3)))
    assert done.tolist() == [False] * M + [True] * M + [False] * (2 * M)
    for r in range(M, 2 * M):
        assert infos[r]["TimeLimit.truncated"] is False
        np.testing.assert_allclose(infos[r]["terminal_observation"], (before[1, r - M] / 10).astype(np.float32))
    assert vec.core.t.tolist() == [1, 0, 1, 1]
    assert not np.allclose(vec.core.x[1], before[1])


def test_seeding_is_reproducible_and_applies_at_next_reset():
    def run(seed):
        vec = SatVecEnv(ToyEnv(max_steps=3), n_copies=B)
        vec.seed(seed)
        out = [vec.reset()]
        for _ in range(7):  # crosses two auto-resets
            out.append(vec.step(np.ones((B * M, 3)) * 0.1)[0])
        return np.stack(out)

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.allclose(run(7), run(8))
    vec = SatVecEnv(ToyEnv(), n_copies=B, seed=7)
    first = vec.reset()
    assert not np.allclose(vec.reset(), first)  # no pending seed: the streams continue
    assert vec.seed(7)[:M + 1] == [7] * M + [8]
    np.testing.assert_array_equal(vec.reset(), first)


def test_bad_input_errors():
    with pytest.raises(SatenvError, match="n_copies"):
        SatVecEnv(ToyEnv(), n_copies=0)
    with pytest.raises(SatenvError, match="SatParallelEnv"):
        SatVecEnv(object(), n_copies=2)
    vec = SatVecEnv(ToyEnv(), n_copies=2)
    with pytest.raises(SatenvError, match="before reset"):
        vec.step(np.zeros((2 * M, 3)))
    vec.reset()
    with pytest.raises(SatenvError, match=r"shape \(6, 3\)"):
        vec.step(np.zeros((5, 3)))
    with pytest.raises(SatenvError, match="seed"):
        vec.seed(-1)


def test_make_env_and_versions():
    env = make_env("test_env_base:ToyEnv", max_steps=4)
    assert env.scenario.max_steps == 4
    with pytest.raises(SatenvError, match="unknown env id"):
        make_env("nope_v0")
    with pytest.raises(SatenvError, match="SatParallelEnv"):
        make_env("test_env_base:ToyScenario")
    assert env_version("platoon_v0") == "v0" and env_version("test_env_base:ToyEnv") == ""


def test_sb3_wrappers_and_ppo_step():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    vec = VecNormalize(VecMonitor(SatVecEnv(ToyEnv(max_steps=8), n_copies=2, seed=0)))
    model = PPO("MlpPolicy", vec, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=2 * 16 * 2 * M)
    assert model.num_timesteps == 2 * 16 * 2 * M


def test_action_obs_and_reward_maps():
    from satenv.training.shaping import ActionMap, ObsFeatures

    calls = []

    def reward_fn(rewards, info):
        calls.append((rewards.shape, info["state"].shape))
        return rewards * 0 + 7.0

    vec = SatVecEnv(ToyEnv(), n_copies=2, seed=4, reward_fn=reward_fn, obs_fn=ObsFeatures(10.0, 6),
                    action_fn=ActionMap(3.0))
    env = ToyEnv()
    assert vec.observation_space.shape == (12,)
    obs = vec.reset()
    o, _ = env.reset(seed=4)
    np.testing.assert_allclose(obs[:M, :6], np.stack([o[a] for a in env.possible_agents]))
    act = np.full((2 * M, 3), 0.5)
    obs, rew, _, _ = vec.step(act)
    o, *_ = env.step({a: np.full(3, 0.125) for a in env.possible_agents})  # 0.5 ** 3
    np.testing.assert_allclose(obs[:M, :6], np.stack([o[a] for a in env.possible_agents]), rtol=1e-6)
    assert calls == [((2, M), (2, M, 6))] and np.all(rew == 7.0)
