"""Formation random starts drawn around the target formation, for the easier rungs of a task ladder."""

from __future__ import annotations

import numpy as np
import pytest

from satenv import tasks
from satenv.errors import SatenvError
from satenv.scenarios.formation import proximity_components, resolve_scenario, sample_initial_state


def _nominal_draw(scenario, rng: np.random.Generator) -> np.ndarray:
    """The formation draw before ``random_start`` existed (around the nominal initial positions)."""
    x0 = scenario.initial_array()
    m = scenario.n_agents
    s, v = scenario.random_position_spread, scenario.random_velocity_spread
    iu = np.triu_indices(m, 1)
    while True:
        x = x0.copy()
        x[:, :3] += rng.uniform(-s, s, size=(m, 3))
        x[:, 3:] += rng.uniform(-v, v, size=(m, 3))
        dist = np.linalg.norm(x[:, None, :3] - x[None, :, :3], axis=-1)
        if np.min(dist[iu]) < max(scenario.random_min_gap, scenario.collision_distance):
            continue
        if proximity_components(x[:, :3], scenario.connection_range).all():
            return x


@pytest.mark.parametrize("preset", ["kannan2022-position", "kannan2022-collision"])
def test_default_draw_is_unchanged(preset: str) -> None:
    sc = resolve_scenario(preset, randomize=True)
    assert sc.random_start == "initial"
    for seed in range(20):
        got = sample_initial_state(sc, np.random.default_rng(seed))
        assert np.array_equal(got, _nominal_draw(sc, np.random.default_rng(seed)))


@pytest.mark.parametrize("preset", ["kannan2022-position", "kannan2022-collision"])
def test_target_draw_is_around_the_target_formation(preset: str) -> None:
    s, v = 5.0, 0.1
    sc = resolve_scenario(preset, randomize=True, random_start="target", random_position_spread=s,
                          random_velocity_spread=v)
    target = sc.target_positions()
    for seed in range(50):
        x = sample_initial_state(sc, np.random.default_rng(seed))
        assert np.all(np.abs(x[:, :3] - target) <= s)
        assert np.all(np.abs(x[:, 3:]) <= v)
        assert proximity_components(x[:, :3], sc.connection_range).all()


def test_env_reset_uses_the_target_draw() -> None:
    env = tasks.get("formation-kannan2022-position-random").make_env(random_start="target")
    target = env.scenario.target_positions()
    _, info = env.reset(seed=700000)
    pos = np.stack([np.asarray(info[a]["state"])[:3] for a in env.possible_agents])
    assert np.all(np.abs(pos - target) <= env.scenario.random_position_spread + 1e-9)


@pytest.mark.parametrize("bad", ["origin", "", None, 1])
def test_bad_random_start_is_a_clear_error(bad: object) -> None:
    with pytest.raises(SatenvError, match="random_start"):
        resolve_scenario("kannan2022-position", random_start=bad)
