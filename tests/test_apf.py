"""satenv.baselines.APF: saturation, repulsion geometry, collision-free short runs on both presets."""

import numpy as np
import pytest

from satenv import metrics
from satenv.baselines.apf import APF
from satenv.envs.cluster_v0 import parallel_env
from satenv.rollout import rollout

SHORT_STEPS = 60   # 300 s of the li2022 scenarios (the full run is in satenv/bench/reproductions/li2022.py)


def test_accelerations_are_saturated_and_point_at_the_target():
    env = parallel_env()
    env.reset(seed=0)
    apf = APF(env)
    u = apf.accelerations()
    assert np.all(np.linalg.norm(u, axis=1) <= env.scenario.u_max * (1 + 1e-12))
    # from rest, far from everything, the attraction dominates: thrust toward the target
    e = env.targets() - env.state()[:60].reshape(10, 6)[:, :3]
    cos = np.sum(u * e, axis=1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(e, axis=1))
    assert np.all(cos > 0.9)
    actions = apf.act({})
    assert set(actions) == set(env.agents) and all(np.linalg.norm(a) <= 1 + 1e-12 for a in actions.values())


def test_repulsion_pushes_away_from_the_obstacle():
    env = parallel_env(initial_positions=[[1000.0, 0.0, 0.0]], targets=[[-1000.0, 0.0, 0.0]])
    x0 = np.zeros((1, 6))
    x0[0, :3] = [1015.0, 0.0, 0.0]            # 15 m outside the 400 m keep-out of the obstacle at x = 600
    env.reset(options={"initial_state": x0})
    u = APF(env, k_swirl=0.0).accelerations()[0]
    assert u[0] > 0.0                          # pushed away (+x) although the target is at -x


def test_options_are_validated():
    env = parallel_env()
    with pytest.raises(ValueError, match="unknown option"):
        APF(env, gain=1.0)
    with pytest.raises(ValueError, match="att_fraction"):
        APF(env, att_fraction=1.5)
    with pytest.raises(ValueError, match="k_att"):
        APF(env, k_att=-1.0)
    with pytest.raises(TypeError, match="cluster_v0"):
        APF(object())


@pytest.mark.parametrize("preset", ["li2022-case1", "li2022-case2"])
def test_short_run_is_collision_free(preset):
    env = parallel_env(preset=preset, terminate_on_collision=False)
    traj = rollout(env, APF(env), seed=0, max_steps=SHORT_STEPS)
    sc = env.scenario
    assert metrics.collisions(traj) == 0
    assert traj.info["pair_distance"].min() >= sc.pair_distance
    assert traj.info["obstacle_distance"].min() >= sc.obstacle_distance
    assert traj.info["target_distance"].min() >= sc.target_distance
    assert np.max(traj.info["thrust_peak"]) <= sc.u_max * (1 + 1e-9)
    err = np.linalg.norm(traj.info["tracking_error"][..., :3], axis=-1)
    assert np.all(err[-1] < err[0])


def test_single_satellite_avoids_the_moving_obstacle():
    env = parallel_env(initial_positions=[[1300.0, 0.0, 0.0]], targets=[[-400.0, 0.0, 0.0]],
                       terminate_on_collision=False, max_steps=120)
    traj = rollout(env, APF(env), seed=0)
    assert traj.info["obstacle_distance"].min() >= env.scenario.obstacle_distance
    assert np.linalg.norm(traj.info["tracking_error"][-1, 0, :3]) < 1000.0   # from 1700 m: past it
