"""satenv.envs.servicing_v0: API, seeding, physics, waypoints, attitude reference, constraints."""

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import parallel_to_aec

from satenv.dynamics import Orbit, cw_matrices, simulate
from satenv.dynamics.attitude import (
    attitude_step,
    matrix_to_quat,
    pointing_frame,
    quat_to_matrix,
    thruster_matrices,
)
from satenv.envs.base import SatenvError
from satenv.envs.servicing_v0 import ServicingCore, parallel_env, unpack_global_state
from satenv.scenarios.servicing import PRESETS, resolve_scenario

FAR = [[0.0, -40.0, 0.0], [0.0, 0.0, -40.0]]   # well clear of the keep-out sphere


def far_state(q=None, w=None):
    x = np.zeros((2, 13))
    x[:, :3] = FAR
    x[:, 6] = 1.0
    if q is not None:
        x[:, 6:10] = q
    if w is not None:
        x[:, 10:] = w
    return x


@pytest.mark.parametrize("kwargs", [{}, {"randomize": True}, {"terminate_on_collision": False},
                                    {"thrust_frame": "body", "dynamics": "cw", "substeps": 2}])
def test_pettingzoo_api(kwargs):
    parallel_api_test(parallel_env(**kwargs), num_cycles=40)
    api_test(parallel_to_aec(parallel_env(**kwargs)), num_cycles=20)


def test_seeding():
    parallel_seed_test(lambda: parallel_env(randomize=True, max_steps=30), num_cycles=20)
    a, b = parallel_env(randomize=True), parallel_env(randomize=True)
    oa, _ = a.reset(seed=7)
    ob, _ = b.reset(seed=7)
    np.testing.assert_array_equal(oa["sat_1"], ob["sat_1"])
    oc, _ = b.reset(seed=8)
    assert not np.array_equal(oa["sat_1"], oc["sat_1"])


def test_spaces_preset_and_bad_kwargs():
    env = parallel_env()
    assert env.possible_agents == ["sat_1", "sat_2"]
    assert env.action_space("sat_1").shape == (6,)
    assert env.observation_space("sat_2").shape == (22,)
    sc = env.scenario
    assert sc is PRESETS["pereira2022"]
    np.testing.assert_array_equal(sc.u_max, np.full(6, 3.0))
    assert (sc.v_max, sc.omega_max, sc.keepout_radius, sc.separation_radius) == (5.0, 0.7, 15.0, 6.0)
    np.testing.assert_allclose(np.linalg.norm(sc.initial_quaternion, axis=1), 1.0)
    with pytest.raises(SatenvError, match="unknown keyword"):
        parallel_env(horizonn=3)
    with pytest.raises(SatenvError, match="unknown preset"):
        parallel_env(preset="nope")
    with pytest.raises(SatenvError, match="thrust_frame"):
        parallel_env(thrust_frame="inertial")
    with pytest.raises(SatenvError, match="waypoint_times"):
        parallel_env(waypoint_times=(80.0, 40.0))
    with pytest.raises(SatenvError, match="keep-out|r_sigma"):
        parallel_env(initial_position=[[0, 1, 0], [0, 0, -15]])
    env.reset()
    bad = far_state()
    bad[0, 6:10] = 0.0
    with pytest.raises(SatenvError, match="quaternion"):
        env.reset(options={"initial_state": bad})
    with pytest.raises(SatenvError, match=r"shape \(6,\)"):
        env.step({a: np.zeros(3) for a in env.agents})


def test_waypoint_schedule_eq50():
    sc = PRESETS["pereira2022"]
    np.testing.assert_array_equal(sc.phase([0, 400, 401, 800, 801, 1199]), [0, 0, 1, 1, 2, 2])
    env = parallel_env(waypoint_times=(0.3, 0.6), terminate_on_collision=False)
    _, info = env.reset(options={"initial_state": far_state()})
    seen = [info["sat_2"]["waypoint"]]
    for _ in range(8):
        _, _, _, _, info = env.step({a: np.zeros(6) for a in env.agents})
        seen.append(info["sat_2"]["waypoint"])
    wp = sc.waypoint_array()[:, 1]
    for k, expected in enumerate([0, 0, 0, 0, 1, 1, 1, 2, 2]):
        np.testing.assert_array_equal(seen[k], wp[expected])
    _, goals, t = unpack_global_state(env.state(), 2)
    np.testing.assert_array_equal(goals, sc.waypoint_array()[2])
    assert t == pytest.approx(0.8)


def test_translation_uses_satenv_dynamics_and_thruster_map():
    env = parallel_env(terminate_on_collision=False)
    x0 = far_state()
    env.reset(options={"initial_state": x0})
    for _ in range(5):
        _, _, _, _, info = env.step({a: np.zeros(6) for a in env.agents})
    ref = simulate("nonlinear", x0[:, :6], orbit=Orbit.circular(6621e3), dt=0.1, steps=5)
    np.testing.assert_allclose(info["sat_1"]["state"][:6], ref[-1, 0], atol=1e-9)
    np.testing.assert_allclose(info["sat_2"]["state"][:6], ref[-1, 1], atol=1e-9)
    # one step of thruster 3 (+x force) at full thrust under the CW model: exact ZOH response
    env = parallel_env(terminate_on_collision=False, dynamics="cw")
    env.reset(options={"initial_state": x0})
    a = np.array([0, 0, 1.0, 0, 0, 0])
    _, _, _, _, info = env.step({"sat_1": a, "sat_2": np.zeros(6)})
    f_t, f_r = thruster_matrices([2, 2, 2])
    a_d, b_d = cw_matrices(PRESETS["pereira2022"].mean_motion, 0.1)
    np.testing.assert_allclose(info["sat_1"]["state"][:6], a_d @ x0[0, :6] + b_d @ (f_t @ (3 * a)), atol=1e-12)
    np.testing.assert_allclose(info["sat_1"]["accel"], [3.0, 0, 0])
    np.testing.assert_allclose(info["sat_1"]["torque"], f_r @ (3 * a))
    np.testing.assert_allclose(info["sat_1"]["delta_v"], 0.3)
    # the attitude follows satenv.dynamics.attitude under the torque F_r u
    sc = env.scenario
    q, w = attitude_step(x0[0, 6:10], x0[0, 10:], f_r @ (3 * a), 0.1, np.array(sc.inertia),
                         np.array(sc.object_inertia), np.array([0, 0, sc.mean_motion]))
    np.testing.assert_allclose(info["sat_1"]["state"][6:], np.r_[q, w], atol=1e-14)


def test_body_fixed_thrusters_rotate_the_force():
    qz = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])   # body x = LVLH y
    env = parallel_env(terminate_on_collision=False, dynamics="cw", thrust_frame="body")
    env.reset(options={"initial_state": far_state(q=qz)})
    _, _, _, _, info = env.step({"sat_1": np.array([0, 0, 1.0, 0, 0, 0]), "sat_2": np.zeros(6)})
    np.testing.assert_allclose(info["sat_1"]["accel"], [0, 3.0, 0], atol=1e-12)


def test_quaternion_stays_unit_norm_over_long_random_run():
    env = parallel_env(terminate_on_collision=False, max_distance=1e6, max_steps=600)
    rng = np.random.default_rng(0)
    env.reset(seed=0, options={"initial_state": far_state()})
    for _ in range(600):
        _, _, _, _, info = env.step({a: rng.uniform(-1, 1, 6) for a in env.agents})
    for a in info:
        assert abs(np.linalg.norm(info[a]["state"][6:10]) - 1.0) < 1e-13


def test_attitude_reference_and_observation_layout():
    env = parallel_env(terminate_on_collision=False)
    sc = env.scenario
    x0 = far_state()
    r_d = pointing_frame(x0[:, :3], reference=sc.pointing_reference)
    x0[:, 6:10] = matrix_to_quat(r_d)                      # already pointing at the object
    obs, info = env.reset(options={"initial_state": x0})
    for i, a in enumerate(env.agents):
        assert info[a]["pointing_error"] < 1e-7 and info[a]["attitude_error"] < 1e-7
        np.testing.assert_allclose(obs[a][6:10], [1, 0, 0, 0], atol=1e-7)
        np.testing.assert_allclose(obs[a][0:3], (x0[i, :3] - sc.waypoint_array()[0, i]) / 15.0, rtol=1e-6)
        np.testing.assert_allclose(obs[a][13:16], x0[i, :3] / 15.0, rtol=1e-6)
        # body z axis (the pointing axis drawn by render) is the line of sight
        np.testing.assert_allclose(quat_to_matrix(x0[i, 6:10])[:, 2], -x0[i, :3] / 40.0, atol=1e-12)
    np.testing.assert_allclose(obs["sat_1"][16:19], (x0[1, :3] - x0[0, :3]) / 15.0, rtol=1e-6)
    # a 90 deg roll about the line of sight: pointing error stays 0, attitude error is 90 deg
    roll = np.array([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
    from satenv.dynamics.attitude import quat_multiply

    x1 = x0.copy()
    x1[:, 6:10] = quat_multiply(x0[:, 6:10], roll)
    _, info = env.reset(options={"initial_state": x1})
    assert info["sat_1"]["pointing_error"] < 1e-7
    assert info["sat_1"]["attitude_error"] == pytest.approx(np.pi / 2)


def test_constraint_violations_and_collisions():
    env = parallel_env(terminate_on_collision=False)
    x = far_state()
    x[0, :3] = [0, -14.0, 0]                 # inside the keep-out sphere (15 m)
    x[1, :3] = [0, -40.0, 0]
    x[1, 3:6] = [5.5, -6.0, 0]               # two velocity axes above v_max = 5
    x[1, 10:] = [0.8, 0, -0.9]               # two angular-velocity axes above 0.7
    _, info = env.reset(options={"initial_state": x})
    assert info["sat_1"]["collision"] and info["sat_1"]["violations"] == 1
    assert not info["sat_2"]["collision"] and info["sat_2"]["violations"] == 4
    assert info["sat_2"]["cost"] == 4.0
    _, _, terms, _, info = env.step({a: np.zeros(6) for a in env.agents})
    assert not any(terms.values())
    # eq. 41: two spacecraft 5 m apart collide; the episode terminates by default
    env = parallel_env()
    x = far_state()
    x[1, :3] = [0, -40.0, 5.0]
    _, info = env.reset(options={"initial_state": x})
    assert info["sat_1"]["collision"] and info["sat_2"]["collision"]
    assert info["sat_1"]["dist_other"] == pytest.approx(5.0)
    _, rew, terms, truncs, info = env.step({a: np.zeros(6) for a in env.agents})
    assert all(terms.values()) and not any(truncs.values()) and env.agents == []
    assert rew["sat_1"] < -env.scenario.collision_penalty
    # the paper's initial positions lie exactly on the keep-out sphere: not a collision
    _, info = parallel_env().reset()
    assert info["sat_1"]["min_separation"] == 15.0 and not info["sat_1"]["collision"]


def test_batched_core_partial_reset():
    sc = resolve_scenario("pereira2022", randomize=True)
    core = ServicingCore(sc, batch=3)
    rng = np.random.default_rng(0)
    x0 = core.sample_initial_state(rng, 3)
    core.reset(x0)
    res = core.step(np.ones((3, 2, 6)))
    assert res.rewards.shape == (3, 2) and res.terminated.shape == (3,)
    assert res.info["state"].shape == (3, 2, 13) and res.info["violations"].dtype == np.int64
    info = core.reset(x0[1:2], idx=np.array([1]))
    np.testing.assert_allclose(info["state"][0], x0[1])
    assert core.t.tolist() == [1, 0, 1]
    assert core.observe().shape == (3, 2, 22) and core.global_state().shape == (3, 33)


def test_render_scene_and_frame():
    env = parallel_env(render_mode="rgb_array")
    env.reset()
    scene = env.core.render_scene(0)
    assert scene["positions"].shape == (2, 3) and scene["axes"].shape == (2, 3)
    assert {label for _, _, label in scene["spheres"]} == {"object", "keep-out"}
    assert dict((lab, r) for _, r, lab in scene["spheres"])["keep-out"] == 15.0
    env.step({a: np.zeros(6) for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.dtype == np.uint8
    env.close()
