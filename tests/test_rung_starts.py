"""Random starts drawn near the targets, for the easier rungs of a task ladder."""

from __future__ import annotations

import math

import numpy as np
import pytest

import satenv
from satenv.errors import SatenvError
from satenv.scenarios import cluster
from satenv.scenarios.servicing import resolve_scenario, sample_initial_state


def _whole_sphere_draw(scenario, rng: np.random.Generator) -> np.ndarray:
    """The servicing draw before ``random_cone`` existed (uniform directions on the sphere)."""
    m = scenario.n_agents
    r0 = scenario.keepout_radius + scenario.random_min_gap
    min_sep = scenario.separation_radius + scenario.random_min_gap
    while True:
        d = rng.normal(size=(m, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        p = d * rng.uniform(r0, r0 + scenario.random_shell, size=(m, 1))
        dist = np.linalg.norm(p[:, None] - p[None], axis=-1)
        if np.any(dist[np.triu_indices(m, 1)] < min_sep):
            continue
        v = rng.uniform(-1, 1, size=(m, 3)) * scenario.random_velocity_spread
        q = rng.normal(size=(m, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        q *= np.where(q[:, :1] < 0, -1.0, 1.0)
        w = rng.uniform(-1, 1, size=(m, 3)) * scenario.random_angular_spread
        return np.concatenate([p, v, q, w], axis=1)


def test_servicing_default_draw_is_unchanged() -> None:
    sc = resolve_scenario("pereira2022", randomize=True)
    assert sc.random_cone == math.pi
    for seed in range(20):
        got = sample_initial_state(sc, np.random.default_rng(seed))
        assert np.array_equal(got, _whole_sphere_draw(sc, np.random.default_rng(seed)))


def test_servicing_cone_draws_near_the_first_waypoints() -> None:
    cone, shell = 0.2, 2.0
    sc = resolve_scenario("pereira2022", randomize=True, random_cone=cone, random_shell=shell)
    axis = np.array(sc.waypoints[0]) / np.linalg.norm(sc.waypoints[0], axis=1, keepdims=True)
    r0 = sc.keepout_radius + sc.random_min_gap
    angles = []
    for seed in range(200):
        p = sample_initial_state(sc, np.random.default_rng(seed))[:, :3]
        r = np.linalg.norm(p, axis=1)
        assert np.all((r >= r0) & (r <= r0 + shell))
        angles.append(np.arccos(np.clip(np.sum(p / r[:, None] * axis, axis=1), -1.0, 1.0)))
    angles = np.concatenate(angles)
    assert angles.max() <= cone + 1e-12
    assert angles.max() > 0.9 * cone                 # the whole cap is used, not only its centre


@pytest.mark.parametrize("cone", [0.0, -0.1, math.pi + 0.01, float("nan")])
def test_servicing_cone_out_of_range_is_rejected(cone: float) -> None:
    with pytest.raises(SatenvError, match="random_cone"):
        resolve_scenario("pereira2022", randomize=True, random_cone=cone)


def test_servicing_cone_needs_waypoint_directions() -> None:
    wps = (((0.0, 0.0, 0.0), (0.0, 0.0, 15.0)),)
    with pytest.raises(SatenvError, match="random_cone"):
        resolve_scenario("pereira2022", waypoints=wps, waypoint_times=(), random_cone=0.3)
    resolve_scenario("pereira2022", waypoints=wps, waypoint_times=())          # the whole sphere needs no direction


def _preset_draw(scenario, rng: np.random.Generator) -> np.ndarray:
    """The cluster draw before ``random_start`` existed (around the preset positions)."""
    x = scenario.initial_array()
    s = scenario.random_position_spread
    while True:
        pos = x[:, :3] + rng.uniform(-s, s, size=(scenario.n_agents, 3))
        if cluster.safety_ok(scenario, pos, 0.0, margin=10.0):
            out = x.copy()
            out[:, :3] = pos
            return out


def test_cluster_default_draw_is_unchanged() -> None:
    sc = cluster.resolve_scenario("li2022-case1", randomize=True)
    assert sc.random_start == "preset"
    for seed in range(10):
        rng, ref = np.random.default_rng(seed), np.random.default_rng(seed)
        assert np.array_equal(cluster.sample_initial_state(sc, rng), _preset_draw(sc, ref))
        assert np.array_equal(cluster.sample_targets(sc, rng), cluster.sample_targets(sc, ref))


@pytest.mark.parametrize("spread", [0.0, 20.0])
def test_cluster_slot_starts_surround_the_allocated_slots(spread: float) -> None:
    env = satenv.make("cluster_v0", preset="li2022-case1", randomize=True, random_start="slots",
                      random_position_spread=spread)
    for seed in range(5):
        _, info = env.reset(seed=seed)
        err = np.array([info[a]["tracking_error"] for a in env.possible_agents])
        assert np.all(np.abs(err[:, :3]) <= spread)            # within the spread of the slot, per axis
        assert np.all(err[:, 3:] == 0.0)                        # at rest (the slots are fixed)
        assert cluster.safety_ok(env.scenario, np.array([info[a]["state"][:3] for a in env.possible_agents]))
    vec = satenv.make_vec("cluster_v0", 3, seed=1, preset="li2022-case1", randomize=True, random_start="slots",
                          random_position_spread=spread, max_steps=2)
    _, info = vec.reset(seed=1)
    assert np.all(np.abs(info["tracking_error"][..., :3]) <= spread)
    for _ in range(2):                                          # the copies' automatic resets draw alike
        *_, truncated, info = vec.step(np.zeros((3, vec.n_agents, 3)))
    assert np.all(truncated) and np.all(np.abs(info["tracking_error"][..., :3]) <= spread)


def test_cluster_random_start_is_checked() -> None:
    with pytest.raises(SatenvError, match="random_start"):
        cluster.resolve_scenario("li2022-case1", random_start="targets")
