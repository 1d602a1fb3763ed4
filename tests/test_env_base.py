"""The shared env machinery (satenv.envs.base, rollout, metrics) on a minimal toy core."""

from dataclasses import dataclass

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

from satenv import metrics
from satenv.baselines.base import RandomPolicy, ZeroPolicy
from satenv.envs.base import BatchedCore, SatenvError, SatParallelEnv, StepResult
from satenv.rollout import Trajectory, rollout


@dataclass(frozen=True)
class ToyScenario:
    n_agents: int = 3
    dt: float = 1.0
    max_steps: int = 20
    u_max: float = 0.5
    thrust_mode: str = "box"
    success_tol: float = 1.0
    collision_voids_success: bool = True
    max_distance: float = 100.0


class ToyCore(BatchedCore):
    """Double integrators that should reach the origin; collision if two are within 0.1 m."""

    obs_dim = 6

    def sample_initial_state(self, rng, n):
        x = np.zeros((n, self.n_agents, 6))
        x[..., :3] = rng.uniform(-5, 5, size=(n, self.n_agents, 3))
        return x

    def reset(self, x0, idx=None, rng=None):
        if idx is None:
            self.x = np.array(x0, dtype=float)
            self.t[:] = 0
        else:
            self.x[idx] = x0
            self.t[idx] = 0
        return self._info(np.zeros((len(x0), self.n_agents, 3)), idx)

    def _info(self, accel, idx=None):
        x = self.x if idx is None else self.x[idx]
        d = np.linalg.norm(x[:, :, None, :3] - x[:, None, :, :3], axis=-1)
        d[:, np.arange(self.n_agents), np.arange(self.n_agents)] = np.inf
        sep = d.min(axis=-1)
        return {"state": x.copy(), "accel": accel, "delta_v": np.linalg.norm(accel, axis=-1),
                "tracking_error": x.copy(), "min_separation": sep, "collision": sep < 0.1,
                "violations": np.zeros(sep.shape, int), "cost": np.zeros(sep.shape)}

    def step(self, accel, rng=None):
        self.x[..., 3:] += accel
        self.x[..., :3] += self.x[..., 3:]
        self.t += 1
        info = self._info(accel)
        rewards = -np.linalg.norm(self.x[..., :3], axis=-1)
        return StepResult(rewards, info["collision"].any(axis=-1), info)

    def observe(self):
        return (self.x / 10.0).astype(np.float32)

    def global_state(self):
        return self.x.reshape(self.batch, -1)

    def render_scene(self, b=0):
        return {"positions": self.x[b, :, :3], "title": "toy"}


class ToyEnv(SatParallelEnv):
    metadata = {**SatParallelEnv.metadata, "name": "toy_v0"}
    core_class = ToyCore

    def __init__(self, render_mode=None, **kwargs):
        super().__init__(ToyScenario(**kwargs), render_mode=render_mode)


def test_pettingzoo_api_and_seeding():
    parallel_api_test(ToyEnv(), num_cycles=30)
    parallel_seed_test(ToyEnv)


def test_bad_actions_get_clear_errors_and_do_not_corrupt_state():
    env = ToyEnv()
    env.reset(seed=0)
    before = env.state().copy()
    good = {a: np.zeros(3) for a in env.agents}
    for bad, match in [
        ({**good, "sat_1": np.array([np.nan, 0, 0])}, "must be finite"),
        ({**good, "sat_1": np.zeros(2)}, r"shape \(3,\)"),
        ({a: v for a, v in good.items() if a != "sat_2"}, r"missing \['sat_2'\]"),
        ({**good, "sat_9": np.zeros(3)}, r"unknown \['sat_9'\]"),
        ([np.zeros(3)] * 3, "must be a dict"),
    ]:
        with pytest.raises(SatenvError, match=match):
            env.step(bad)
        np.testing.assert_array_equal(env.state(), before)


def test_reset_options_and_errors():
    env = ToyEnv()
    x0 = np.zeros((3, 6))
    x0[:, 0] = [1.0, 2.0, 3.0]
    _, infos = env.reset(options={"initial_state": x0})
    np.testing.assert_array_equal(infos["sat_3"]["state"], x0[2])
    with pytest.raises(SatenvError, match=r"shape \(3, 6\)"):
        env.reset(options={"initial_state": np.zeros((2, 6))})
    with pytest.warns(UserWarning, match="unknown reset option"):
        env.reset(options={"x0": x0})
    with pytest.raises(SatenvError, match="seed"):
        env.reset(seed=-1)
    with pytest.raises(SatenvError, match="unknown agent"):
        env.observation_space("sat_7")
    with pytest.raises(SatenvError, match="render_mode"):
        ToyEnv(render_mode="video")


def test_rollout_records_arrays_and_metrics():
    env = ToyEnv()
    traj = rollout(env, ZeroPolicy(env), seed=3)
    assert traj.states.shape == (21, 3, 6) and traj.actions.shape == (20, 3, 3)
    assert traj.info["accel"].shape == (21, 3, 3) and traj.truncated and not traj.terminated
    # coasting from rest: no thrust, no delta-v, error constant => RMSE == FOE == |x0|
    np.testing.assert_allclose(metrics.rmsee(traj), 0.0)
    np.testing.assert_allclose(metrics.rmse(traj), np.linalg.norm(traj.states[0], axis=-1))
    np.testing.assert_allclose(metrics.foe(traj), np.linalg.norm(traj.states[0], axis=-1))
    s = metrics.summary(traj)
    assert s["delta_v"] == 0.0 and s["steps"] == 20
    traj2 = rollout(env, RandomPolicy(env), seed=3)
    assert metrics.delta_v_total(traj2).min() > 0
    assert traj2.compute_time.shape == (traj2.steps,)


def test_trajectory_save_load(tmp_path):
    env = ToyEnv()
    traj = rollout(env, RandomPolicy(env), seed=1)
    traj.save(tmp_path / "t.npz")
    back = Trajectory.load(tmp_path / "t.npz")
    np.testing.assert_array_equal(back.states, traj.states)
    assert back.agents == traj.agents and back.info.keys() == traj.info.keys()


def test_render_rgb_array():
    env = ToyEnv(render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: np.ones(3) for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    env.close()


def test_time_to_converge():
    class T:  # a minimal trajectory-like object
        t = np.arange(5.0)
        info = {"tracking_error": np.array([[[3, 0, 0]], [[0.5, 0, 0]], [[2, 0, 0]], [[0.5, 0, 0]], [[0.2, 0, 0]]])}
    assert metrics.time_to_converge(T, tol=1.0)[0] == 3.0
    assert np.isnan(metrics.time_to_converge(T, tol=0.1)[0])


def test_trajectory_plot_and_gif(tmp_path):
    from satenv.render import plot_trajectory, save_gif

    env = ToyEnv(max_steps=6)
    traj = rollout(env, RandomPolicy(env), seed=2)
    png = plot_trajectory(traj, tmp_path / "traj.png")
    gif = save_gif(traj, tmp_path / "traj.gif", every=2)
    assert png.stat().st_size > 1000 and gif.stat().st_size > 1000
    from PIL import Image

    with Image.open(gif) as im:
        assert im.n_frames == 4  # frames 0, 2, 4, 6


@pytest.mark.parametrize("name", ["platoon_v0", "cluster_v0", "servicing_v0", "formation_v0"])
def test_infos_are_not_changed_by_later_steps_or_resets(name):
    """The env hands out views of the core's info arrays: the core must never write into them."""
    import copy

    import satenv

    e = getattr(satenv, name)()

    def act(value):
        return {a: np.full(e.action_space(a).shape, value, np.float32) for a in e.agents}

    _, at_reset = e.reset(seed=0)
    kept_reset = copy.deepcopy(at_reset)
    e.reset(seed=1)
    _, _, _, _, at_step = e.step(act(0.5))
    kept_step = copy.deepcopy(at_step)
    e.reset(seed=2)
    e.step(act(-0.5))
    for got, want in ((at_reset, kept_reset), (at_step, kept_step)):
        for agent, info in want.items():
            for key, value in info.items():
                np.testing.assert_array_equal(got[agent][key], value, err_msg=f"{name} {agent} {key}")
