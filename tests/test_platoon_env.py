"""satenv.envs.platoon_v0: PettingZoo API, seeding, spaces, infos, rewards, terminations."""

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import parallel_to_aec

import satenv
from satenv.dynamics import Orbit, simulate
from satenv.envs.base import INFO_KEYS
from satenv.envs.platoon_v0 import POS_SCALE, VEL_SCALE, env, parallel_env
from satenv.scenarios.platoon import PRESETS, sample_initial_state

pytestmark = pytest.mark.filterwarnings("ignore:ignoring unknown reset option")

GRID = [
    {},
    {"topology": "BDL"},
    {"topology": "TPLF", "dynamics": "nonlinear"},
    {"topology": "PLF", "dynamics": "j2", "inclination": 0.9},
    {"randomize": True},
    {"topology": [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
     "initial_state": [[30, -35, 40, 0, 0, 0], [15, -46, -30, 0, 0, 0], [-49, -43, -20, 0, 0, 0]]},
    {"preset": "pereira2022"},
    {"preset": "pereira2022", "randomize": True, "dynamics": "nonlinear"},
    {"min_error_constraint": True, "terminate_on_collision": False},
]


@pytest.mark.parametrize("kwargs", GRID, ids=lambda k: ",".join(f"{a}={b}" for a, b in k.items())[:60] or "default")
def test_parallel_api(kwargs):
    parallel_api_test(parallel_env(**kwargs), num_cycles=40)


@pytest.mark.parametrize("kwargs", [g for g in GRID if g.get("randomize") or g == {}])
def test_seed(kwargs):
    parallel_seed_test(lambda: parallel_env(**kwargs))


@pytest.mark.parametrize("kwargs", [{}, {"preset": "pereira2022", "randomize": True}])
def test_aec_api(kwargs):
    api_test(parallel_to_aec(parallel_env(**kwargs)), num_cycles=20)
    api_test(env(**kwargs), num_cycles=5)


def test_entry_point_and_agents():
    e = satenv.platoon_v0(topology="BDL")
    assert e.possible_agents == [f"follower_{i}" for i in range(1, 5)]
    assert e.scenario.graph.name == "BDL" and e.topology.name == "BDL"
    assert e.metadata["name"] == "platoon_v0"
    assert e.observation_space("follower_1") is e.observation_space("follower_1")
    assert e.observation_space("follower_1").shape == (15 + 7 * 3,)
    assert e.action_space("follower_2").dtype == np.float32


def _zero_actions(e):
    return {a: np.zeros(3, np.float32) for a in e.agents}


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"follower_1": [np.nan, 0, 0]}, "finite"),
        ({"follower_1": [0, 0]}, r"shape \(3,\)"),
        ({"follower_1": "fast"}, "numeric"),
    ],
)
def test_bad_actions_are_rejected(bad, match):
    e = parallel_env()
    e.reset(seed=0)
    acts = _zero_actions(e)
    acts.update(bad)
    with pytest.raises(ValueError, match=match):
        e.step(acts)


def test_missing_or_unknown_agent_rejected():
    e = parallel_env()
    e.reset(seed=0)
    acts = _zero_actions(e)
    del acts["follower_3"]
    with pytest.raises(ValueError, match=r"missing \['follower_3'\]"):
        e.step(acts)
    acts = _zero_actions(e)
    acts["follower_9"] = np.zeros(3)
    with pytest.raises(ValueError, match="follower_9"):
        e.step(acts)
    with pytest.raises(ValueError, match="dict"):
        e.step([0, 0, 0])


def test_bad_kwargs_rejected():
    with pytest.raises(ValueError, match="unknown keyword"):
        parallel_env(topolgy="BDL")
    with pytest.raises(ValueError, match="unknown preset"):
        parallel_env(preset="pereira2021")
    with pytest.raises(ValueError, match="hear the leader|0 or 1|square"):
        parallel_env(topology=[[0, 2, 0, 0]] * 4)
    with pytest.raises(ValueError, match="dynamics"):
        parallel_env(dynamics="rk45")
    with pytest.raises(ValueError, match="initial_state"):
        parallel_env(initial_state=np.zeros((4, 5)))
    with pytest.raises(ValueError, match="u_max"):
        parallel_env(u_max=-1)


def test_reset_initial_state_option_and_errors():
    e = parallel_env()
    x0 = PRESETS["pereira2023"].initial_array() + 1.0
    _, infos = e.reset(seed=0, options={"initial_state": x0})
    np.testing.assert_array_equal(e.state(), x0.ravel())
    np.testing.assert_array_equal(infos["follower_2"]["state"], x0[1])
    with pytest.raises(ValueError, match="shape"):
        e.reset(options={"initial_state": np.zeros((3, 6))})
    with pytest.raises(ValueError, match="finite"):
        e.reset(options={"initial_state": np.full((4, 6), np.nan)})


def test_observation_layout_and_infos():
    e = parallel_env()
    obs, infos = e.reset(seed=0)
    sc = e.scenario
    x = sc.initial_array()
    topo = sc.graph
    err = topo.neighbourhood_error(x) - topo.gains[:, None] * np.asarray(sc.desired_error)
    scale = np.array([POS_SCALE] * 3 + [VEL_SCALE] * 3)
    for i, a in enumerate(e.agents):
        assert set(INFO_KEYS) <= set(infos[a])
        np.testing.assert_allclose(infos[a]["tracking_error"], err[i])
        o = obs[a]
        assert o.dtype == np.float32 and e.observation_space(a).contains(o)
        np.testing.assert_allclose(o[:6], err[i] / scale, rtol=1e-6)
        np.testing.assert_allclose(o[6:12], x[i] / scale, rtol=1e-6)
        assert o[12] == 1.0 and o[13] == pytest.approx(topo.gains[i] / 4) and o[14] == 1.0
    # PLF: follower_3 hears follower_2 only -> slots (1, 2, 4): masks 0, 1, 0
    slots = obs["follower_3"][15:].reshape(3, 7)
    np.testing.assert_array_equal(slots[:, 0], [0, 1, 0])
    np.testing.assert_allclose(slots[1, 1:], (x[1] - x[2]) / scale, rtol=1e-6)
    assert np.all(slots[[0, 2], 1:] == 0)
    assert infos["follower_1"]["min_separation"] == pytest.approx(
        min(np.linalg.norm(x[0, :3]), *(np.linalg.norm(x[0, :3] - x[j, :3]) for j in (1, 2, 3))))


def _reference_observation(core, x, t):
    """The observation layout of the module docstring, entry by entry (one copy, loops)."""
    n, sc, topo = core.n_agents, core.scenario, core.topology
    scale = np.array([POS_SCALE] * 3 + [VEL_SCALE] * 3)
    err = topo.neighbourhood_error(x) - sc.desired_neighbourhood_error()
    obs = np.zeros((n, 15 + 7 * (n - 1)))
    for f in range(n):
        obs[f, 0:6] = err[f] / scale
        obs[f, 6:12] = x[f] / scale
        obs[f, 12:15] = topo.pinning[f], topo.gains[f] / n, 1 - t / sc.max_steps
        for k, j in enumerate(j for j in range(n) if j != f):
            if topo.adjacency[f, j]:
                obs[f, 15 + 7 * k] = 1.0
                obs[f, 16 + 7 * k:22 + 7 * k] = (x[j] - x[f]) / scale
    return obs


@pytest.mark.parametrize("topology", ["PLF", "BDL", "TPLF", [[0, 1, 1], [1, 0, 0], [0, 1, 0]]])
def test_batched_observation_and_separation_match_the_layout(topology):
    from satenv.envs.platoon_v0 import PlatoonCore
    from satenv.scenarios.platoon import resolve_scenario

    n = 3 if isinstance(topology, list) else 4
    sc = resolve_scenario("pereira2023", topology=topology, randomize=True,
                          **({"initial_state": np.zeros((3, 6))} if n == 3 else {}))
    core = PlatoonCore(sc, batch=5)
    rng = np.random.default_rng(3)
    core.reset(rng.normal(0, 40, (5, n, 6)))
    info = core.step(rng.uniform(-6, 6, (5, n, 3))).info
    core.t[2] = 7
    obs = core.observe()
    assert obs.dtype == np.float32 and obs.shape == (5, n, core.obs_dim)
    for b in range(5):
        np.testing.assert_allclose(obs[b], _reference_observation(core, core.x[b], core.t[b]),
                                   rtol=1e-6, atol=1e-6)
        pos = np.vstack([np.zeros(3), core.x[b, :, :3]])
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.diag(np.full(n + 1, np.inf))
        np.testing.assert_allclose(info["min_separation"][b], d[1:].min(axis=1), rtol=1e-12)
        np.testing.assert_array_equal(info["collision"][b], (d[1:] < 6.0).any(axis=1))


def test_step_infos_survive_a_later_partial_reset():
    from satenv.envs.platoon_v0 import PlatoonCore

    core = PlatoonCore(PRESETS["pereira2023"], batch=3)
    core.reset(np.tile(PRESETS["pereira2023"].initial_array(), (3, 1, 1)))
    info = core.step(np.ones((3, 4, 3)))
    kept = {k: v.copy() for k, v in info.info.items()}
    core.reset(np.zeros((1, 4, 6)) + 50.0, np.array([1]))
    for k, v in info.info.items():
        np.testing.assert_array_equal(v, kept[k], err_msg=k)


def test_step_matches_dynamics_and_reward_formula():
    for model in ("cw", "nonlinear"):
        e = parallel_env(dynamics=model)
        e.reset(seed=0)
        sc = e.scenario
        a = {ag: np.array([0.5, -0.25, 0.1], np.float32) for ag in e.agents}
        _, rew, term, trunc, infos = e.step(a)
        u = np.tile(np.array([0.5, -0.25, 0.1], np.float32).astype(float) * sc.u_max, (1, 4, 1))
        orbit = Orbit.circular(sc.orbit_radius, mu=sc.mu)
        expect = simulate(model, sc.initial_array(), orbit=orbit, dt=sc.dt, steps=1, u=u)[1]
        np.testing.assert_allclose(e.state().reshape(4, 6), expect, atol=1e-9)
        for i, ag in enumerate(e.agents):
            err = infos[ag]["tracking_error"]
            stage = err @ (np.asarray(sc.state_weight) * err) + u[0, i] @ (np.asarray(sc.input_weight) * u[0, i])
            assert rew[ag] == pytest.approx(-sc.alpha[i] * stage / sc.reward_scale)
            np.testing.assert_allclose(infos[ag]["accel"], u[0, i])
            assert infos[ag]["delta_v"] == pytest.approx(np.linalg.norm(u[0, i]) * sc.dt)
            assert not term[ag] and not trunc[ag]


def test_truncation_at_max_steps():
    e = parallel_env(max_steps=3)
    e.reset(seed=0)
    for _ in range(3):
        _, _, term, trunc, _ = e.step(_zero_actions(e))
    assert all(trunc.values()) and not any(term.values()) and e.agents == []


def test_collision_terminates_unless_disabled():
    x0 = PRESETS["pereira2023"].initial_array()
    x0[1, :3] = x0[0, :3] + [1.0, 0, 0]  # 1 m apart, radii 3 m
    assert not parallel_env().scenario.terminate_on_collision  # the paper preset never stops
    e = parallel_env(terminate_on_collision=True)
    _, infos = e.reset(options={"initial_state": x0})
    assert infos["follower_1"]["collision"] and infos["follower_2"]["collision"]
    _, rew, term, _, infos = e.step(_zero_actions(e))
    assert all(term.values()) and e.agents == []
    assert rew["follower_1"] < -e.scenario.collision_penalty + 1e-9
    assert infos["follower_1"]["cost"] >= 1.0
    e2 = parallel_env(terminate_on_collision=False)
    e2.reset(options={"initial_state": x0})
    _, _, term, _, infos = e2.step(_zero_actions(e2))
    assert not any(term.values()) and infos["follower_2"]["collision"]


def test_leaving_the_region_terminates():
    x0 = PRESETS["pereira2023"].initial_array()
    x0[3] = [0, -499.9, 0, 0, -10.0, 0]
    e = parallel_env()
    e.reset(options={"initial_state": x0})
    _, _, term, _, _ = e.step(_zero_actions(e))
    assert all(term.values())


def test_violations_counted():
    # velocity bound (40): |E_v| > (g+d) v_max for follower 1 (PLF, g+d = 1)
    x0 = PRESETS["pereira2023"].initial_array()
    x0[0, 3] = 25.0
    e = parallel_env()
    _, infos = e.reset(options={"initial_state": x0})
    # follower 2: E_2,v = 2 v_2 - v_1 = -25, within (g+d) v_max = 40
    assert infos["follower_1"]["violations"] == 1 and infos["follower_2"]["violations"] == 0
    x0[1, 3] = 35.0  # now E_2,v = 70 - 25 = 45 > 40
    _, infos = e.reset(options={"initial_state": x0})
    assert infos["follower_2"]["violations"] == 1 and infos["follower_3"]["violations"] == 0
    # pereira2022: follower 1 outside the LOS cone (y > -y_rho)
    e = parallel_env(preset="pereira2022")
    x0 = PRESETS["pereira2022"].initial_array()
    x0[0, :3] = [0.0, 20.0, 0.0]
    _, infos = e.reset(options={"initial_state": x0})
    assert infos["follower_1"]["violations"] >= 1


def test_randomized_initial_states():
    sc = PRESETS["pereira2023"]
    rng = np.random.default_rng(0)
    xs = [sample_initial_state(sc, rng) for _ in range(20)]
    for x in xs:
        pos = np.vstack([np.zeros(3), x[:, :3]])
        d = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(5) * 1e9
        assert d.min() >= 2 * sc.follower_radius + sc.random_min_gap
        assert np.all(np.abs(x[:, :3] - sc.initial_array()[:, :3]) <= sc.random_position_spread)
    e = parallel_env(randomize=True)
    e.reset(seed=1)
    s1 = e.state()
    e.reset(seed=2)
    assert not np.allclose(s1, e.state())
    e.reset(seed=1)
    np.testing.assert_array_equal(s1, e.state())


def test_render_rgb_array():
    e = parallel_env(render_mode="rgb_array")
    e.reset(seed=0)
    e.step(_zero_actions(e))
    frame = e.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    e.close()
