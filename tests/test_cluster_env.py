"""cluster_v0: PettingZoo API, seeding, presets, physics, inner-loop hook, safety flags."""

import math

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import parallel_to_aec

from satenv.allocation import hungarian_assignment
from satenv.dynamics import cw_matrices, sinusoid_disturbance
from satenv.envs.base import SatenvError
from satenv.envs.cluster_v0 import N_FIXED_OBS, POS_SCALE, env, own_action_jacobian, parallel_env
from satenv.scenarios.cluster import PRESETS, ClusterScenario, resolve_scenario

pytestmark = pytest.mark.filterwarnings("ignore:ignoring unknown reset option", "ignore:Agent.s m")


def zero_actions(e):
    return {a: np.zeros(3) for a in e.agents}


@pytest.mark.parametrize("kwargs", [{}, {"preset": "li2022-case2"},
                                    {"disturbance": "random", "randomize": True, "random_position_spread": 30.0},
                                    {"dynamics": "cw", "n_neighbours": 2}])
def test_pettingzoo_api(kwargs):
    parallel_api_test(parallel_env(**kwargs), num_cycles=8)


def test_seeding_and_aec_api():
    parallel_seed_test(lambda: parallel_env(disturbance="random", randomize=True, random_position_spread=30.0))
    api_test(parallel_to_aec(parallel_env()), num_cycles=4)
    api_test(env(preset="li2022-case2", max_steps=3), num_cycles=4)


def test_presets_match_li2022():
    c1, c2 = PRESETS["li2022-case1"], PRESETS["li2022-case2"]
    assert c1.n_agents == c2.n_agents == 10
    np.testing.assert_allclose(c1.initial_array()[0], [946.1, 1025.3, 666.3, 0, 0, 0])     # Table 2
    np.testing.assert_allclose(c2.initial_array()[9, :3], [1119.9, 1385.1, 1572.2])         # Table 3
    np.testing.assert_allclose(c1.targets_array()[9], [94.2, -235.2, -247.2])               # Table 4
    assert c1.u_max == pytest.approx(1.0 / 50.0) and c1.thrust_mode == "norm"
    assert c1.dt == 5.0 and c1.substeps == 20 and c1.dynamics == "j2_drag"
    assert c1.disturbance_amplitude == pytest.approx(0.002)
    assert c1.disturbance_bound == pytest.approx(0.002 * 1.68014, rel=1e-4)
    assert (c1.pair_distance, c1.obstacle_distance, c1.target_distance) == (200.0, 400.0, 100.0)
    np.testing.assert_allclose(c1.obstacle_at(100.0), [560.0, 40.0, 40.0])
    # the targets are 300 m from the target spacecraft and >= 2 r_s apart (Assumption 2)
    tg = c1.targets_array()
    np.testing.assert_allclose(np.linalg.norm(tg - c1.target_spacecraft, axis=1), 300.0, atol=0.2)
    d = np.linalg.norm(tg[:, None] - tg[None], axis=-1)[np.triu_indices(10, 1)]
    assert d.min() > c1.pair_distance
    assert math.isclose(c1.orbit.a, 6378137.0 + 500e3) and math.isclose(c1.orbit.i, math.radians(45))


def test_bad_arguments_raise_clear_errors():
    with pytest.raises(SatenvError, match="unknown keyword"):
        parallel_env(thrust=2.0)
    with pytest.raises(SatenvError, match="unknown preset"):
        parallel_env(preset="li2023")
    with pytest.raises(SatenvError, match="physics_dt must divide dt"):
        parallel_env(physics_dt=0.3)
    with pytest.raises(SatenvError, match="disturbance"):
        parallel_env(disturbance="gaussian")
    with pytest.raises(ValueError, match="at least one target per satellite"):
        resolve_scenario(targets=[[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="unknown cluster scenario parameter"):
        PRESETS["li2022-case1"].with_overrides(n_sats=3)
    with pytest.raises(ValueError, match="inclination"):
        ClusterScenario(name="x", initial_positions=[[0.0, 0.0, 0.0]], inclination=45.0)


def test_reset_allocation_infos_and_observations():
    e = parallel_env()
    obs, infos = e.reset(seed=0)
    sc = e.scenario
    x0 = sc.initial_array()
    expected = hungarian_assignment(x0[:, :3], sc.targets_array())
    np.testing.assert_array_equal(e.assignment, expected)
    assert [infos[a]["target_index"] for a in e.agents] == expected.tolist()
    np.testing.assert_allclose(infos["sat_1"]["tracking_error"][:3], x0[0, :3] - sc.targets_array()[expected[0]])
    assert e.observation_space("sat_1").shape == (N_FIXED_OBS + 7 * 4,)
    o = obs["sat_1"]
    np.testing.assert_allclose(o[0:3], (x0[0, :3] - e.targets()[0]) / POS_SCALE, rtol=1e-6)
    np.testing.assert_allclose(o[9:12], (np.array(sc.obstacle_position) - x0[0, :3]) / POS_SCALE, rtol=1e-6)
    # neighbour slots: graph neighbours, nearest first
    adj = e.graph()
    d = np.linalg.norm(x0[:, None, :3] - x0[None, :, :3], axis=-1)
    nearest = min(np.nonzero(adj[0])[0], key=lambda j: d[0, j])
    assert o[N_FIXED_OBS] == 1.0
    np.testing.assert_allclose(o[N_FIXED_OBS + 1:N_FIXED_OBS + 4], (x0[nearest, :3] - x0[0, :3]) / POS_SCALE,
                               rtol=1e-6)
    assert e.state().shape == (6 * 10 + 6,)
    fixed = parallel_env(allocation="fixed")
    fixed.reset()
    np.testing.assert_array_equal(fixed.assignment, np.arange(10))


def test_physics_matches_cw_with_the_sinusoid_disturbance():
    """With dynamics="cw" the env is the exact CW ZOH model driven by u + w every physics step."""
    e = parallel_env(dynamics="cw", max_steps=3)
    e.reset(seed=0)
    sc = e.scenario
    a, b = cw_matrices(sc.orbit.n, sc.physics_dt)
    x = sc.initial_array()
    action = {ag: np.array([0.3, -0.2, 0.1]) for ag in e.agents}
    u = np.array([0.3, -0.2, 0.1]) * sc.u_max
    for k in range(3):
        _, _, _, _, infos = e.step(action)
        for s in range(sc.substeps):
            t = k * sc.dt + s * sc.physics_dt
            w = sinusoid_disturbance(t, sc.disturbance_amplitude)
            x = x @ a.T + (u + w) @ b.T
        np.testing.assert_allclose(e.state()[:60].reshape(10, 6), x, rtol=1e-9, atol=1e-9)
    info = infos["sat_1"]
    np.testing.assert_allclose(info["accel"], u, rtol=1e-12)
    assert info["delta_v"] == pytest.approx(np.linalg.norm(u) * sc.dt)
    assert info["thrust_peak"] == pytest.approx(np.linalg.norm(u))


def test_own_action_jacobian_matches_the_env_step():
    """A change of one satellite's action moves its own next observation by the jacobian times the
    acceleration change (CW truth: exact up to round-off), and nothing else in the layout."""
    obs1 = {}
    for da in (0.0, 0.3):
        e = parallel_env(dynamics="cw", max_steps=3, randomize=True)
        e.reset(seed=3)
        action = {ag: np.array([0.2, -0.1, 0.05]) for ag in e.agents}
        action["sat_1"] = action["sat_1"] + np.array([da, -da, 0.5 * da])
        obs1[da] = e.step(action)[0]["sat_1"].astype(float)
    sc = e.scenario
    du = np.array([0.3, -0.3, 0.15]) * sc.u_max
    jac = own_action_jacobian(obs1[0.0], cw_matrices(sc.orbit.n, sc.dt)[1])
    np.testing.assert_allclose(obs1[0.3] - obs1[0.0], jac @ du, rtol=0, atol=1e-6)
    assert np.abs(jac[N_FIXED_OBS - 1]).max() == 0.0                  # the clock does not move
    b = cw_matrices(sc.orbit.n, sc.dt)[1]
    for bad_obs, bad_b, kind in ((np.zeros(20), b, ValueError), (obs1[0.0], np.zeros((3, 6)), ValueError),
                                 (np.full(47, np.nan), b, ValueError), (obs1[0.0], np.full((6, 3), np.inf), ValueError),
                                 (obs1[0.0] + 0j, b, TypeError), (np.ma.masked_all(47), b, TypeError),
                                 (np.float64(1.0), b, ValueError)):
        with pytest.raises(kind, match="own_action_jacobian"):
            own_action_jacobian(bad_obs, bad_b)


def test_thrust_is_saturated_on_the_norm_ball():
    e = parallel_env(dynamics="cw", max_steps=2)
    e.reset(seed=0)
    _, _, _, _, infos = e.step({a: np.ones(3) for a in e.agents})
    np.testing.assert_allclose(np.linalg.norm(infos["sat_3"]["accel"]), e.scenario.u_max)


def test_inner_loop_hook_is_called_every_physics_step_and_removed_at_reset():
    class Hook:
        def __init__(self):
            self.calls = []

        def correction(self, t, x, chief, u_cmd):
            self.calls.append((float(t[0]), x.shape, chief.shape, u_cmd.copy()))
            return np.full(u_cmd.shape, 1e-3)

    e = parallel_env(dynamics="cw", disturbance="none", max_steps=2)
    e.reset(seed=0)
    hook = Hook()
    e.set_inner_loop(hook)
    _, _, _, _, infos = e.step({a: np.array([0.5, 0.0, 0.0]) for a in e.agents})
    assert len(hook.calls) == e.scenario.substeps
    assert hook.calls[1][0] == pytest.approx(e.scenario.physics_dt)
    assert hook.calls[0][1] == (1, 10, 6) and hook.calls[0][2] == (1, 6)
    np.testing.assert_allclose(hook.calls[0][3][0, 0], [0.5 * e.scenario.u_max, 0.0, 0.0])
    np.testing.assert_allclose(infos["sat_1"]["accel"], [0.01 + 1e-3, 1e-3, 1e-3])
    e.reset()
    assert e.inner_loop is None
    with pytest.raises(SatenvError, match="correction"):
        e.set_inner_loop(object())


def test_safety_violations_are_flagged_and_terminate():
    e = parallel_env(max_steps=5)
    x0 = e.scenario.initial_array()
    x0[1, :3] = x0[0, :3] + [150.0, 0.0, 0.0]          # 150 m < 2 r_s
    e.reset(options={"initial_state": x0})
    _, _, terms, truncs, infos = e.step(zero_actions(e))
    assert all(terms.values()) and not any(truncs.values()) and not e.agents
    assert infos["sat_1"]["collision"] and infos["sat_2"]["collision"]
    assert infos["sat_1"]["pair_distance"] < 200.0
    assert infos["sat_1"]["violations"] == 1 and infos["sat_1"]["cost"] == 1.0
    # without termination the episode goes on and keeps flagging
    e = parallel_env(max_steps=5, terminate_on_collision=False)
    x0 = e.scenario.initial_array()
    x0[0, :3] = [600.0, 0.0, 350.0]                       # 350 m from the obstacle (< 400)
    e.reset(options={"initial_state": x0})
    _, _, terms, _, infos = e.step(zero_actions(e))
    assert not any(terms.values()) and e.agents
    assert infos["sat_1"]["collision"] and infos["sat_1"]["obstacle_distance"] < 400.0


def test_reallocation_every_k_decisions():
    e = parallel_env(reallocate_every=1, dynamics="cw", disturbance="none", max_steps=3)
    x0 = e.scenario.initial_array()
    e.reset(options={"initial_state": x0})
    first = e.assignment
    # swap two satellites' states: the next allocation follows the satellites
    x = e.core.x[0]
    x[[0, 1]] = x[[1, 0]]
    _, _, _, _, infos = e.step(zero_actions(e))
    assert infos["sat_1"]["target_index"] == first[1] and infos["sat_2"]["target_index"] == first[0]


def test_render_rgb_array():
    e = parallel_env(render_mode="rgb_array", max_steps=2)
    e.reset(seed=0)
    e.step(zero_actions(e))
    frame = e.render()
    assert frame.ndim == 3 and frame.dtype == np.uint8
    e.close()
