"""pereira2022 §5.2 reproduction: claim records on a short episode (fast), the departures, and the
full run with its as-published row behind ``slow``."""

import pytest

import satenv
from satenv.baselines.nmpc import NMPC
from satenv.bench.claims import NO_VALUE
from satenv.bench.reproductions import pereira2022_servicing as serv
from satenv.rollout import rollout


def test_claims_of_a_short_episode_quote_the_paper_and_can_fail():
    env = satenv.make("servicing_v0", preset="pereira2022", max_steps=20)
    policy = NMPC(env)
    traj = rollout(env, policy, seed=0)
    claims = serv.claims_of(serv.analyse(traj, env, policy), "as published")
    assert all(c["source"] == serv.SOURCE for c in claims)
    waypoints = [c for c in claims if "distance to the waypoint" in c["claim"]]
    assert waypoints and all(c["status"] == NO_VALUE and not c["gating"] for c in waypoints)  # the band is ours
    assert all("our test" in c["rule"] and c["rule"].endswith("not met") for c in waypoints)  # 2 s: too short
    point = claims[-1]
    assert point["status"] == NO_VALUE and "our test" in point["rule"] and not point["gating"]
    assert not any(c["gating"] for c in claims)                       # as-published rows never gate


def test_departures_without_runs_say_not_measured():
    deps = {d["name"]: d for d in serv.departures({})}
    assert deps["terminal attitude cost"]["effect"] == "not measured in this result"
    assert deps["terminal attitude cost"]["fields"] == ["terminal_attitude_weight"]
    assert deps["quaternion error in the cost (eq. 39)"]["fields"] == ["quaternion_error"]
    assert {"spacecraft mass", "prediction model (translation)", "solver fallback"} <= set(deps)


def test_as_published_uses_eq39_signed_quaternion_error():
    """eq. 39 prints 1 - eta~: q_d and -q_d (the same attitude) then cost differently; ours does not."""
    import casadi as ca
    import numpy as np

    from satenv.baselines.nmpc import NMPCConfig, quaternion_cost_terms

    assert NMPCConfig(**serv.VARIANTS["as published"]).quaternion_error == "signed"
    assert NMPCConfig().quaternion_error == "sign-free"
    q = ca.DM([1.0, 0.0, 0.0, 0.0])
    for signed, expected in ((False, 0.0), (True, 2.0)):
        first = float(quaternion_cost_terms(q, -q, signed)[0])
        assert first == expected and np.allclose(np.asarray(quaternion_cost_terms(q, q, signed)), 0.0)


def test_failed_solves_are_counted_by_stop_reason_never_by_a_clock():
    assert serv.SOLVE_CAP == {"solve_time_limit": None}
    assert serv.stop_reason("failed: Maximum_Iterations_Exceeded") == "Maximum_Iterations_Exceeded"
    assert serv.stop_reason("infeasible: constraint violated by 0.0123 (Solve_Succeeded)") == \
        "infeasible: constraint violated (Solve_Succeeded)"
    assert serv.stop_reason("time limit: the solve took 12 s > 10 s (Solve_Succeeded)") == "time limit"


@pytest.mark.slow
def test_full_reproduction_reports_both_runs():
    result = serv.reproduce(diagnostics=False)
    assert set(result["runs"]) == {"ours", "as published"}
    assert result["runs"]["as published"]["terminal_attitude_weight"] == 0.0
    assert result["runs"]["as published"]["quaternion_error"] == "signed"
    gating = [c for c in result["claims"] if c["gating"]]
    assert gating and all(c["met"] for c in gating), gating
    assert "eq. 39 as printed" in result["departures"][0]["effect"]
    reasons = result["stop_reasons"]
    assert set(reasons) == {"ours", "as published"}
    assert sum(reasons["as published"].values()) == result["runs"]["as published"]["fallbacks"]
    assert not any("time limit" in r for run in reasons.values() for r in run)
