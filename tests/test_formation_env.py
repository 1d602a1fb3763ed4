"""satenv.envs.formation_v0 (kannan2022 presets): PettingZoo API, seeding, dynamics, infos, connectivity."""

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import parallel_to_aec

from satenv.dynamics import cw_stm
from satenv.envs.base import INFO_KEYS, SatenvError
from satenv.envs.formation_v0 import FormationCore, env, parallel_env
from satenv.scenarios.formation import (
    PRESETS,
    FormationScenario,
    proximity_components,
    resolve_scenario,
    sample_initial_state,
)

pytestmark = pytest.mark.filterwarnings("ignore:ignoring unknown reset option")

PRESET_NAMES = ["kannan2022-position", "kannan2022-collision"]
GRID = [
    {"preset": "kannan2022-position"},
    {"preset": "kannan2022-collision"},
    {"preset": "kannan2022-position", "randomize": True},
    {"preset": "kannan2022-collision", "randomize": True, "dynamics": "nonlinear", "dt": 0.5},
    {"preset": "kannan2022-position", "thrust_mode": "norm", "terminate_on_disconnect": True},
]


@pytest.mark.parametrize("kwargs", GRID, ids=lambda k: ",".join(f"{a}={b}" for a, b in k.items()))
def test_parallel_api(kwargs):
    parallel_api_test(parallel_env(**kwargs), num_cycles=40)


@pytest.mark.parametrize("kwargs", [g for g in GRID if g.get("randomize")] + [{"preset": p} for p in PRESET_NAMES])
def test_seed(kwargs):
    parallel_seed_test(lambda: parallel_env(**kwargs), num_cycles=30)


@pytest.mark.parametrize("preset", PRESET_NAMES)
def test_aec_api_checks_observation_spaces(preset):
    api_test(parallel_to_aec(parallel_env(preset=preset)), num_cycles=30)
    api_test(env(preset=preset, randomize=True), num_cycles=10)


def test_presets_match_the_paper():
    pos = PRESETS["kannan2022-position"]
    assert pos.n_agents == 3 and pos.mean_motion == 0.0011 and pos.u_max == 50.0 and pos.thrust_mode == "box"
    np.testing.assert_array_equal(pos.initial_array(), np.zeros((3, 6)))
    np.testing.assert_array_equal(pos.target_positions(), [[100, 100, 100], [100, 200, 100], [100, 300, 100]])
    col = PRESETS["kannan2022-collision"]
    assert col.goals[0] is None and col.goals[2] is None and col.leader == 1
    np.testing.assert_array_equal(col.target_positions(), [[100, 110, 100], [100, 100, 100], [100, 90, 100]])
    # cost (34): followers' x, z relative to sat_2, y spacing 10 m; weight K on the y terms
    x = np.zeros((3, 6))
    x[:, :3] = [[5, 20, 7], [1, 2, 3], [0, 0, 0]]
    e = col.formation_error(x)
    np.testing.assert_allclose(e, [[4, 8, 4], [-99, -98, -97], [-1, 8, -3]])
    w = col.with_overrides(offset_weight=3.0).error_weights()
    np.testing.assert_array_equal(w[:, 1], [3.0, 1.0, 3.0])


def test_env_dynamics_are_exact_cw_with_n0():
    e = parallel_env(preset="kannan2022-position")
    x0 = np.array([[10.0, -5, 3, 0.1, -0.2, 0.05], [0, 20, 0, 0, 0, 0], [50, 0, -10, 0.3, 0, 0]])
    e.reset(options={"initial_state": x0})
    for _ in range(5):
        _, _, _, _, infos = e.step({a: np.zeros(3) for a in e.agents})
    expected = x0 @ cw_stm(0.0011, 5 * e.scenario.dt).T
    np.testing.assert_allclose(e.state().reshape(3, 6), expected, rtol=1e-10, atol=1e-10)
    # a full-thrust step: the applied acceleration is a * u_max per axis (box)
    e.reset()
    _, _, _, _, infos = e.step({a: np.array([1.0, -0.5, 0.2]) for a in e.agents})
    np.testing.assert_allclose(infos["sat_1"]["accel"], [50.0, -25.0, 10.0])
    assert infos["sat_1"]["delta_v"] == pytest.approx(np.linalg.norm([50, -25, 10]) * e.scenario.dt)


def test_infos_rewards_and_observations():
    e = parallel_env(preset="kannan2022-collision")
    x0 = np.zeros((3, 6))
    x0[:, :3] = [[0, 30, 0], [0, 10, 0], [0, -5, 0]]
    obs, infos = e.reset(options={"initial_state": x0})
    assert set(INFO_KEYS) <= set(infos["sat_1"]) and {"connected", "degree", "formation_error"} <= set(infos["sat_1"])
    np.testing.assert_allclose(infos["sat_1"]["tracking_error"][:3], [-100, -80, -100])
    np.testing.assert_allclose(infos["sat_1"]["formation_error"], [0, 10, 0])   # y1 - y2 - 10
    np.testing.assert_allclose(infos["sat_3"]["formation_error"], [0, -5, 0])   # -(y2 - y3 - 10)
    assert infos["sat_2"]["min_separation"] == pytest.approx(15.0)
    np.testing.assert_allclose(obs["sat_1"][:3], np.array([0, 10, 0]) / 100.0, atol=1e-7)
    np.testing.assert_allclose(obs["sat_1"][6:9], np.array([0, -20, 0]) / 100.0, atol=1e-7)  # sat_2 - sat_1
    assert obs["sat_1"][-1] == 1.0 and obs["sat_1"].shape == (19,)
    _, rew, _, _, infos = e.step({a: np.zeros(3) for a in e.agents})
    sc = e.scenario
    for i, a in enumerate(e.agents):
        err = infos[a]["formation_error"] / sc.length_scale
        expected = -0.5 * np.sum(sc.error_weights()[i] * err**2)
        assert rew[a] == pytest.approx(expected)


def test_connectivity_is_reported_and_can_terminate():
    x0 = np.zeros((3, 6))
    x0[:, 1] = [0.0, 100.0, 400.0]        # sat_3 is 300 m from sat_2 > delta = 150 m
    e = parallel_env()
    _, infos = e.reset(options={"initial_state": x0})
    assert [infos[a]["connected"] for a in e.agents] == [False] * 3
    assert [infos[a]["violations"] for a in e.agents] == [0, 0, 1]
    assert [infos[a]["degree"] for a in e.agents] == [1, 1, 0]
    _, rew, term, trunc, infos = e.step({a: np.zeros(3) for a in e.agents})
    assert not any(term.values()) and infos["sat_3"]["cost"] == 1.0
    assert rew["sat_3"] < rew["sat_2"] - 0.5          # the connection penalty
    e = parallel_env(terminate_on_disconnect=True)
    e.reset(options={"initial_state": x0})
    _, _, term, _, _ = e.step({a: np.zeros(3) for a in e.agents})
    assert all(term.values()) and e.agents == []
    # a chain 0-1-2 with 140 m links is connected although 0 and 2 are 280 m apart
    p = np.array([[0, 0, 0], [0, 140, 0], [0, 280, 0]], dtype=float)
    assert proximity_components(p, 150.0).all()
    assert not proximity_components(p, 139.0).all()
    batch = proximity_components(np.stack([p, p * 2]), 150.0)
    assert batch.shape == (2, 3, 3) and batch[0].all() and not batch[1].all()


def test_leaving_the_region_and_collisions_terminate():
    e = parallel_env(max_distance=200.0)
    x0 = np.zeros((3, 6))
    x0[:, 1] = [0, 100, 195]
    x0[2, 4] = 1000.0             # 10 m per 0.01 s step: beyond 200 m after one step
    e.reset(options={"initial_state": x0})
    _, _, term, trunc, _ = e.step({a: np.zeros(3) for a in e.agents})
    assert all(term.values()) and not any(trunc.values())
    e = parallel_env(collision_distance=5.0)
    x0[2, 4] = 0.0
    x0[:, 1] = [0, 10, 12]
    e.reset(options={"initial_state": x0})
    _, _, term, _, infos = e.step({a: np.zeros(3) for a in e.agents})
    assert all(term.values()) and infos["sat_3"]["collision"] and not infos["sat_1"]["collision"]


def test_truncation_at_max_steps():
    e = parallel_env(max_steps=3)
    e.reset(seed=1)
    for _ in range(3):
        _, _, term, trunc, _ = e.step({a: np.zeros(3) for a in e.agents})
    assert all(trunc.values()) and not any(term.values()) and e.agents == []


def test_randomized_initial_states_are_connected_and_seeded():
    sc = resolve_scenario("kannan2022-position", randomize=True, random_position_spread=60.0)
    draws = [sample_initial_state(sc, np.random.default_rng(s)) for s in range(20)]
    for x in draws:
        assert proximity_components(x[:, :3], sc.connection_range).all()
    e = parallel_env(randomize=True)
    a = e.reset(seed=4)[1]["sat_1"]["state"]
    b = e.reset(seed=4)[1]["sat_1"]["state"]
    c = e.reset(seed=5)[1]["sat_1"]["state"]
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_batched_core_partial_reset():
    core = FormationCore(PRESETS["kannan2022-position"], batch=4)
    rng = np.random.default_rng(0)
    core.reset(core.sample_initial_state(rng, 4))
    core.step(np.full((4, 3, 3), 10.0))
    info = core.reset(np.zeros((2, 3, 6)), idx=np.array([1, 3]))
    assert info["state"].shape == (2, 3, 6) and info["connected"].shape == (2, 3)
    assert np.all(core.x[[1, 3]] == 0) and np.all(core.x[[0, 2], :, 3] != 0)
    assert list(core.t) == [1, 0, 1, 0]
    assert core.observe().shape == (4, 3, 19)


def test_bad_arguments_are_rejected_with_clear_errors():
    with pytest.raises(SatenvError, match="unknown keyword"):
        parallel_env(horizon=3)
    with pytest.raises(SatenvError, match="unknown preset"):
        parallel_env(preset="kannan2023")
    with pytest.raises(SatenvError, match="u_max"):
        parallel_env(u_max=-1.0)
    with pytest.raises(ValueError, match="goals must be a sequence of 3"):
        FormationScenario(name="x", initial_state=np.zeros((3, 6)), goals=((1, 2, 3),))
    with pytest.raises(ValueError, match="no goal and there is no leader"):
        FormationScenario(name="x", initial_state=np.zeros((2, 6)), goals=(None, (1, 2, 3)))
    with pytest.raises(ValueError, match="leader .* needs an absolute goal"):
        FormationScenario(name="x", initial_state=np.zeros((2, 6)), goals=(None, (1, 2, 3)), leader=0)
    with pytest.raises(ValueError, match="offsets must have shape"):
        resolve_scenario("kannan2022-collision", offsets=((0, 1, 0),))
    with pytest.raises(ValueError, match="thrust_mode"):
        resolve_scenario(thrust_mode="ball")
    with pytest.raises(ValueError, match="max_steps"):
        resolve_scenario(max_steps=0)


def test_render_rgb_array():
    e = parallel_env(render_mode="rgb_array")
    e.reset(seed=0)
    e.step({a: np.ones(3) for a in e.agents})
    frame = e.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
    e.close()
