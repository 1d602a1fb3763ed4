"""satenv.baselines.experts and satenv.training.recipes: stateless experts and the held-out target checks
(the resumable DAgger run: tests/test_imitation.py)."""

from __future__ import annotations

import numpy as np
import pytest

import satenv
from satenv.baselines.experts import JointPlatoonMPC
from satenv.training.recipes.heldout import matched_ratios, targets


@pytest.fixture(scope="module")
def env():
    return satenv.make("platoon_v0", preset="pereira2022", randomize=True)


def _state(env, seed):
    env.reset(seed=seed)
    return np.asarray(env.state(), dtype=float).reshape(2, 6)


@pytest.mark.parametrize("coupling", ["sequential", "joint"])
def test_the_expert_depends_on_the_state_only(env, coupling):
    ex = JointPlatoonMPC(env, coupling=coupling)
    x, other = _state(env, 600_000), _state(env, 600_001)
    first = ex.plan(x)
    ex.plan(other)                      # another decision in between changes nothing (DAQP's
    np.testing.assert_allclose(ex.plan(x), first, rtol=0, atol=1e-9)   # warm active set: round-off)
    assert np.all(np.abs(first) <= env.scenario.u_max + 1e-12) and ex.info["fallbacks"] == 0


def test_sequential_follower_1_does_not_depend_on_follower_2(env):
    """Follower 1 does not observe follower 2 (PLF): its label must not depend on it."""
    ex = JointPlatoonMPC(env, coupling="sequential")
    x = np.array([[0.5, -10.3, 0.2, 0.01, 0.0, -0.02], [0.3, -19.5, -0.4, 0.0, 0.02, 0.0]])
    moved = x.copy()
    moved[1, :3] += [0.3, -0.4, 0.2]
    a, b = ex.plan(x), ex.plan(moved)
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-9)
    assert np.abs(a[1] - b[1]).max() > 1e-3


def test_expert_options_are_checked(env):
    with pytest.raises(ValueError, match="coupling"):
        JointPlatoonMPC(env, coupling="both")
    with pytest.raises(ValueError, match="u_scale"):
        JointPlatoonMPC(env, u_scale=0.0)


def _ep(seed, rmse, dv, *, collided=False, terminated=False):
    return {"seed": seed, "rmse": rmse, "delta_v": dv, "collisions": int(collided), "terminated": terminated}


def test_ratios_use_matched_completed_episodes_only():
    mine = [_ep(1, 10, 5), _ep(2, 1, 1, collided=True), _ep(3, 30, 15)]
    ref = [_ep(1, 10, 10), _ep(2, 100, 100), _ep(3, 10, 10, terminated=True)]
    r = matched_ratios(mine, ref)
    assert r == {"matched_seeds": 1, "rmse_ratio": 1.0, "delta_v_ratio": 0.5}
    assert matched_ratios(mine, [_ep(9, 1, 1)]) == {"matched_seeds": 0}


def test_targets_fail_on_each_rule():
    agg = {"success_rate": 0.96, "collision_episodes": 0, "violation_episodes": 0, "compute_ms_per_agent": 0.5}
    ratios = {"rmse_ratio": 1.2, "delta_v_ratio": 1.49}
    assert all(targets(agg, {"success_rate": 1.0}, ratios).values())
    assert not targets(agg, {"success_rate": 1.0}, {**ratios, "delta_v_ratio": 1.51})["delta_v"]
    assert not targets({**agg, "success_rate": 0.94}, {"success_rate": 1.0}, ratios)["success"]
    assert not targets({**agg, "violation_episodes": 1}, {"success_rate": 1.0}, ratios)["no_violations"]
    assert not targets(agg, {"success_rate": 1.0}, {})["rmse"]
