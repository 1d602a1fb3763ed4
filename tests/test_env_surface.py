"""One env surface: the same keywords, spaces and conventions in all four envs; the env registry
and its Gymnasium ids; the one success rule shared by metrics, the scoreboard and evaluation."""

import importlib
import subprocess
import sys

import numpy as np
import pytest
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

import satenv
from satenv import metrics
from satenv.envs.base import SatenvError, SatParallelEnv
from satenv.rollout import Trajectory, rollout

SURFACE = {"max_steps": 3, "dt": None, "u_max": None, "randomize": False,
           "terminate_on_collision": False, "success_tol": 2.0, "collision_voids_success": False}


def _zero(env):
    return {a: np.zeros(env.action_space(a).shape) for a in env.agents}


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_same_keywords_in_every_env(env_id):
    default = satenv.make(env_id)
    kwargs = {k: v for k, v in SURFACE.items() if v is not None}
    kwargs["dt"] = default.scenario.dt * 2
    env = satenv.make(env_id, **kwargs)
    sc = env.scenario
    assert isinstance(env, SatParallelEnv) and env.metadata["name"] == env_id
    assert (sc.max_steps, sc.dt, sc.randomize, sc.terminate_on_collision) == (3, kwargs["dt"], False, False)
    assert (sc.success_tol, sc.collision_voids_success) == (2.0, False)
    env.reset(seed=0)
    steps = 0
    while env.agents:
        _, _, terms, truncs, _ = env.step(_zero(env))
        steps += 1
    assert steps == 3 and all(truncs.values()) and not any(terms.values())
    with pytest.raises(SatenvError, match="max_steps"):
        satenv.make(env_id, max_steps=0)
    with pytest.raises(SatenvError, match="n_steps"):
        satenv.make(env_id, n_steps=10)   # the old name is an unknown keyword now


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_u_max_scales_the_action(env_id):
    def accel(scale):
        env = satenv.make(env_id, terminate_on_collision=False, dynamics="cw")
        u = np.asarray(env.scenario.u_max) * scale
        env = satenv.make(env_id, terminate_on_collision=False, dynamics="cw", u_max=u.tolist() if u.ndim else float(u))
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        _, _, _, _, infos = env.step({a: rng.uniform(-0.5, 0.5, env.action_space(a).shape) for a in env.agents})
        return np.array([infos[a]["accel"] for a in env.possible_agents])

    np.testing.assert_allclose(accel(2.0), 2.0 * accel(1.0), rtol=1e-12)
    assert np.abs(accel(1.0)).max() > 0


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_pettingzoo_conventions(env_id):
    env = satenv.make(env_id)
    obs, _ = env.reset(seed=1)
    assert env.state() in env.state_space and env.state_space.dtype == np.float64
    env.step({a: env.action_space(a).sample() for a in env.agents})
    assert env.state() in env.state_space
    assert env.observation_spaces == {a: env.observation_space(a) for a in env.possible_agents}
    assert env.action_spaces == {a: env.action_space(a) for a in env.possible_agents}
    assert all(obs[a] in env.observation_spaces[a] for a in obs)
    assert env.metadata["render_fps"] == pytest.approx(type(env).render_speedup / env.scenario.dt)
    slow = satenv.make(env_id, dt=env.scenario.dt * 2)
    assert slow.metadata["render_fps"] == pytest.approx(env.metadata["render_fps"] / 2)
    assert type(env).metadata["render_fps"] == 10   # the class default is untouched
    module = sys.modules[type(env).__module__]
    raw = module.raw_env()
    assert isinstance(raw, parallel_to_aec_wrapper) and isinstance(module.env(), OrderEnforcingWrapper)


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_randomize_draws_from_the_seed(env_id):
    env = satenv.make(env_id, randomize=True)
    s0 = env.reset(seed=3) and env.state()
    s0b = env.reset(seed=3) and env.state()
    s1 = env.reset(seed=4) and env.state()
    np.testing.assert_array_equal(s0, s0b)
    assert not np.allclose(s0, s1)
    fixed = satenv.make(env_id)
    assert np.array_equal(fixed.reset(seed=3) and fixed.state(), fixed.reset(seed=4) and fixed.state())


def test_cluster_randomizes_target_slots():
    from satenv.scenarios.cluster import LI2022_TARGETS

    env = satenv.make("cluster_v0", randomize=True)
    sc = env.scenario
    env.reset(seed=0)
    t0 = env.core.all_targets[0].copy()
    env.reset(seed=0)
    np.testing.assert_array_equal(env.core.all_targets[0], t0)
    env.reset(seed=1)
    assert not np.allclose(env.core.all_targets[0], t0)
    np.testing.assert_allclose(np.linalg.norm(t0 - np.asarray(sc.target_spacecraft), axis=-1), 300.0)
    d = np.linalg.norm(t0[:, None] - t0[None], axis=-1)[np.triu_indices(len(t0), 1)]
    assert d.min() >= 2 * sc.sat_radius + 10.0
    # the observation and the tracking error follow the drawn slots
    _, infos = env.reset(seed=1)
    x = env.state()[:6 * sc.n_agents].reshape(-1, 6)
    np.testing.assert_allclose([infos[a]["tracking_error"][:3] for a in env.possible_agents],
                               x[:, :3] - env.targets())
    plain = satenv.make("cluster_v0", random_position_spread=30.0)   # no randomize: the preset
    plain.reset(seed=1)
    np.testing.assert_array_equal(plain.core.all_targets[0], LI2022_TARGETS)
    np.testing.assert_array_equal(plain.state()[:6 * sc.n_agents].reshape(-1, 6), sc.initial_array())


def test_cluster_u_max_is_an_acceleration():
    sc = satenv.make("cluster_v0").scenario
    assert sc.u_max == 0.02 and sc.thrust_max == pytest.approx(1.0)   # li2022: 1 N on 50 kg
    with pytest.raises(SatenvError, match="thrust_max"):
        satenv.make("cluster_v0", thrust_max=2.0)


def test_servicing_u_max_one_or_six_limits():
    env = satenv.make("servicing_v0", u_max=[1, 2, 3, 4, 5, 6])
    assert env.scenario.u_max == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert satenv.make("servicing_v0").scenario.u_max == (3.0,) * 6
    with pytest.raises(SatenvError, match="u_max"):
        satenv.make("servicing_v0", u_max=[1, 2])


# ------------------------------------------------------------------ registry and Gymnasium ids
def test_registry_and_gymnasium_ids_are_registered_lazily():
    code = ("import sys, satenv, gymnasium\n"
            "assert satenv.ENV_IDS == ('platoon_v0', 'cluster_v0', 'servicing_v0', 'formation_v0')\n"
            "assert set(satenv.GYM_IDS) <= set(gymnasium.registry)\n"
            "assert not [m for m in sys.modules if m.startswith(('satenv.envs', 'satenv.gym_env', 'pettingzoo'))]\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    with pytest.raises(ValueError, match="unknown env id"):
        satenv.make("platoon_v1")


@pytest.mark.parametrize("gym_id", sorted(satenv.GYM_IDS))
def test_gymnasium_view_passes_check_env(gym_id):
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    env = gym.make(gym_id, max_steps=4)
    inner = env.unwrapped
    assert inner.env.metadata["name"] == satenv.GYM_IDS[gym_id] and inner.env.scenario.max_steps == 4
    check_env(inner, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    done, steps = False, 0
    while not done:
        obs, _, term, trunc, _ = env.step(env.action_space.sample())
        done, steps = term or trunc, steps + 1
    assert steps <= 4 and obs in env.observation_space


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_env_modules_as_pettingzoo_users_write_them(env_id):
    module = getattr(satenv, env_id)
    assert isinstance(module.parallel_env(max_steps=3), SatParallelEnv)   # platoon_v0.parallel_env()
    assert module(max_steps=3).scenario.max_steps == 3                      # satenv.platoon_v0() too
    assert module.env is __import__(f"satenv.envs.{env_id}", fromlist=["env"]).env  # the AEC view
    with pytest.raises(AttributeError):
        getattr(module, "no_such_name")  # noqa: B009


@pytest.mark.parametrize("gym_id", sorted(satenv.GYM_IDS))
def test_gymnasium_ids_have_max_episode_steps_and_render_warns(gym_id):
    import gymnasium as gym

    env_id = satenv.GYM_IDS[gym_id]
    presets = importlib.import_module(f"satenv.scenarios.{env_id.removesuffix('_v0')}").PRESETS
    env = gym.make(gym_id)
    assert satenv.GYM_MAX_EPISODE_STEPS[env_id] == max(p.max_steps for p in presets.values())
    assert env.spec.max_episode_steps == env.unwrapped.env.scenario.max_steps   # where it truncates
    if env_id == "platoon_v0":  # each runs to its own truncation: the preset's, or max_steps= above it
        for kwargs, expected in (({}, 300), ({"max_steps": 500}, 500)):
            long = gym.make(gym_id, preset="pereira2022", terminate_on_collision=False, **kwargs)
            assert long.spec.max_episode_steps == expected
            long.reset(seed=0)
            steps, done = 0, False
            while not done:
                _, _, term, trunc, _ = long.step(np.zeros(long.action_space.shape, np.float32))
                steps, done = steps + 1, term or trunc
            assert steps == expected
        capped = gym.make(gym_id, max_episode_steps=7)      # an explicit TimeLimit still applies
        assert capped.spec.max_episode_steps == 7
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    penv = satenv.make(env.unwrapped.env.metadata["name"])   # the PettingZoo env warns too
    penv.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert penv.render() is None


@pytest.mark.parametrize("mode", [3, 1.5, "rgb", b"human", ["human"]])
def test_gymnasium_make_checks_render_mode_as_the_env_does(mode):
    """``gymnasium.make(id, render_mode=...)``: any bad mode is the env's typed error naming it."""
    import gymnasium as gym

    with pytest.raises(SatenvError, match="render_mode"):
        gym.make("satenv/Servicing-v0", render_mode=mode)


def test_gymnasium_make_rgb_array_list_collects_frames():
    import gymnasium as gym

    env = gym.make("satenv/Platoon-v0", render_mode="rgb_array_list")
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, np.float32))
    frames = env.render()
    assert len(frames) == 2 and frames[0].ndim == 3
    env.close()


@pytest.mark.parametrize("gym_id", ["satenv/Platoon-v0", "satenv/Servicing-v0"])
def test_make_vec_is_a_gymnasium_vector_env_over_the_batched_core(gym_id):
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode, VectorEnv

    vec = gym.make_vec(gym_id, num_envs=3, max_steps=6)
    assert isinstance(vec, VectorEnv) and vec.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert type(vec.unwrapped).__module__ == "satenv.gym_vector" and vec.unwrapped.vec.num_envs == 3
    singles = [gym.make(gym_id, max_steps=6) for _ in range(3)]
    obs, _ = vec.reset(seed=10)
    for b, env in enumerate(singles):  # copy b is the single env seeded 10 + b
        np.testing.assert_array_equal(obs[b], env.reset(seed=10 + b)[0])
    rng = np.random.default_rng(0)
    for _ in range(6):
        act = rng.uniform(-1, 1, vec.action_space.shape).astype(np.float32)
        obs, rew, term, trunc, info = vec.step(act)
        for b, env in enumerate(singles):
            o, r, te, tr, _ = env.step(act[b])
            assert (te, tr) == (term[b], trunc[b]) and r == pytest.approx(rew[b])
            if te or tr:  # same-step autoreset: the last observation is in final_obs
                assert info["_final_obs"][b]
                np.testing.assert_array_equal(info["final_obs"][b], o)
                np.testing.assert_array_equal(obs[b], env.reset()[0])  # the next episode, same generator
            else:
                np.testing.assert_array_equal(obs[b], o)
    assert "final_observation" not in info
    assert obs in vec.observation_space
    with pytest.raises(SatenvError, match="shape"):
        vec.step(np.zeros((2, 3)))
    with pytest.raises(SatenvError, match="render"):
        gym.make_vec(gym_id, num_envs=2, render_mode="human")
    vec.close()


def test_training_gym_view_is_the_same_class():
    from satenv.gym_env import CentralisedEnv
    from satenv.training.gym_view import CentralisedEnv as Reexported

    assert Reexported is CentralisedEnv


# ------------------------------------------------------------------ the one success rule
def _traj(final_error, collisions, tol=1.0, voids=True):
    err = np.zeros((3, 2, 6))
    err[-1, :, 0] = final_error
    coll = np.zeros((3, 2), bool)
    coll[1, 0] = collisions
    info = {"tracking_error": err, "collision": coll, "accel": np.zeros((3, 2, 3)),
            "delta_v": np.zeros((3, 2)), "min_separation": np.ones((3, 2)),
            "violations": np.zeros((3, 2), int), "cost": np.zeros((3, 2))}
    return Trajectory(env_id="x", agents=["a", "b"], dt=1.0, t=np.arange(3.0), states=np.zeros((3, 2, 6)),
                      actions=np.zeros((2, 2, 3)), rewards=np.zeros((2, 2)), info=info,
                      success_tol=tol, collision_voids_success=voids)


def test_success_rule_reads_the_trajectory():
    assert metrics.success(_traj(0.9, False))
    assert not metrics.success(_traj(1.1, False))
    assert metrics.success(_traj(1.1, False, tol=1.2))
    assert not metrics.success(_traj(1.1, False, tol=1.2), tol=1.0)
    assert not metrics.success(_traj(0.5, True))
    assert metrics.success(_traj(0.5, True, voids=False))
    assert metrics.summary(_traj(0.5, True, voids=False))["success"]


def test_trajectory_keeps_the_rule_when_saved(tmp_path):
    traj = _traj(0.5, True, tol=0.25, voids=False)
    traj.save(tmp_path / "t.npz")
    back = Trajectory.load(tmp_path / "t.npz")
    assert (back.success_tol, back.collision_voids_success) == (0.25, False)


def test_platoon_derives_whether_a_collision_voids_success():
    from satenv.scenarios.platoon import resolve_scenario

    table1 = resolve_scenario("pereira2023")
    assert not table1.collision_voids_success        # its target formation overlaps
    assert resolve_scenario("pereira2023", formation="chain").collision_voids_success
    assert resolve_scenario("pereira2023", topology="TPLF",
                            desired_error=(0, -30, 0, 0, 0, 0)).collision_voids_success
    assert resolve_scenario("pereira2022").collision_voids_success
    assert resolve_scenario("pereira2023", collision_voids_success=True).collision_voids_success
    declared = resolve_scenario("pereira2023", collision_voids_success=False)
    assert not declared.with_overrides(formation="chain").collision_voids_success   # stays declared
    assert table1.with_overrides(formation="chain").collision_voids_success         # derived again
    assert {s.success_tol for s in (table1, satenv.make("servicing_v0").scenario)} == {1.0, 0.5}


def test_same_episode_same_answer_in_metrics_scoreboard_and_evaluation():
    """The DMPC reaches the Table I formation (bodies overlap there): success everywhere; a
    collision in the chain formation voids it everywhere."""
    baselines = pytest.importorskip("satenv.baselines")
    pytest.importorskip("daqp")
    from satenv.bench.scoreboard import Job, run_episode
    from satenv.bench.scoreboard.registry import POLICIES, TASKS
    from satenv.training.evaluate import evaluate

    spec = TASKS["platoon-PLF-cw"]
    env = spec.make()
    traj = rollout(env, baselines.DMPC(env), seed=0)
    summary = metrics.summary(traj)
    record = run_episode(Job(spec, POLICIES["dmpc"], 0))
    env2 = spec.make()
    evaluated = evaluate(env2, baselines.DMPC(env2), [0])["episodes"][0]
    assert summary["collisions"] > 0 and summary["final_error_m"] <= 1.0
    assert summary["success"] is record["success"] is evaluated["success"] is True
    assert record["collisions"] == summary["collisions"] == evaluated["collisions"]

    from satenv.baselines.base import ZeroPolicy
    from satenv.bench.scoreboard import TaskSpec

    x0 = [[0.0, -8.0 * (k + 1), 0.0, 0, 0, 0] for k in range(4)]
    x0[1][1] = -9.0                      # 1 m from follower 1: a collision at reset
    for voids in (True, False):
        kwargs = {"formation": "chain", "terminate_on_collision": False, "max_steps": 3,
                  "initial_state": x0, "success_tol": 100.0, "collision_voids_success": voids}
        env = satenv.make("platoon_v0", **kwargs)
        summary = metrics.summary(rollout(env, ZeroPolicy(env), seed=0))
        record = run_episode(Job(TaskSpec("chain", "platoon_v0", kwargs), POLICIES["zero"], 0))
        assert summary["collisions"] > 0 and record["collisions"] == summary["collisions"]
        assert summary["success"] is record["success"] is (not voids)


RL_READY = {"platoon_v0": {}, "cluster_v0": {}, "servicing_v0": {"preset": "pereira2022-rl"}, "formation_v0": {}}
"""The kwargs a new RL user needs for episodes of a useful length under random actions."""


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_random_actions_give_episodes_of_a_useful_length(env_id):
    lengths = []
    for seed in range(3):
        env = satenv.make(env_id, **RL_READY[env_id])
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        steps = 0
        while env.agents:
            env.step({a: rng.uniform(-1, 1, env.action_space(a).shape) for a in env.agents})
            steps += 1
        lengths.append(steps)
    assert min(lengths) >= 40, lengths
    if env_id == "servicing_v0":  # the paper's preset stays exact: its start touches the keep-out sphere
        paper = satenv.make(env_id).scenario
        assert paper.name == "pereira2022" and paper.initial_position[0] == (0.0, -15.0, 0.0)
