"""Every scripted baseline after the env's true state went non-finite: the flagged zero action
(``satenv.baselines.base.guard_nonfinite``), never a NaN thrust and never a solve on NaN data."""

from __future__ import annotations

import numpy as np
import pytest

import satenv
from satenv import baselines
from satenv.baselines.base import NONFINITE_ACTION, NONFINITE_STATE

CASES = [("apf", "cluster_v0"), ("dmpc", "platoon_v0"), ("nmpc", "servicing_v0"),
         ("tube_rdmpc", "cluster_v0"), ("cgmres", "formation_v0")]


@pytest.mark.parametrize(("name", "env_id"), CASES)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -1e308 * 10])
def test_a_nonfinite_true_state_gives_the_flagged_zero_action(name, env_id, bad):
    env = satenv.make(env_id)
    obs, _ = env.reset(seed=0)
    policy = baselines.make(name, env)
    policy.reset(seed=0)
    env.core.x[0, -1, 0] = bad          # the last agent's position (the env's true state)
    actions = policy.act(obs)
    assert set(actions) == set(obs)
    assert all(np.array_equal(u, np.zeros(env.action_space(a).shape)) for a, u in actions.items())
    assert policy.info["fallbacks"] == len(obs) and policy.info["solver_status"] == NONFINITE_STATE


def test_a_nonfinite_computed_action_is_replaced_and_flagged():
    env = satenv.make("cluster_v0")
    obs, _ = env.reset(seed=0)
    policy = baselines.make("apf", env)
    policy.reset(seed=0)
    inner = type(policy).act.__wrapped__

    def broken(self, observations):
        out = inner(self, observations)
        out[next(iter(out))] = np.full_like(out[next(iter(out))], np.nan)
        return out

    guarded = baselines.base.guard_nonfinite(broken)
    actions = guarded(policy, obs)
    assert all(np.isfinite(u).all() for u in actions.values())
    assert policy.info["fallbacks"] == 1 and policy.info["solver_status"] == NONFINITE_ACTION
