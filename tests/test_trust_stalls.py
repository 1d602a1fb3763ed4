"""The per-solve time limit of the shared solver guard (issue 29 item 5).

A stall is injected into each baseline's solver (its hook of ``tests/test_baseline_registry.py``
wrapped in a ``sleep`` longer than a small ``solve_time_limit``): every stalled solve must be a
flagged failure (``info["fallbacks"]`` / ``info["solver_failures"]``, status ``time limit``),
the actions finite and in ``[-1, 1]``, the episode going on. Without the stall the same
controllers run clean.
"""

import dataclasses
import time

import numpy as np
import pytest
from test_baseline_registry import _check_episode_goes_on

import satenv
from satenv import baselines
from satenv.baselines import BaselineError
from satenv.baselines.base import MAX_SOLVE_TIME, guarded_solve, new_info

STALL = 0.2
LIMIT = 0.08   # a loaded 2-core machine took over 0.02 s for a real first DMPC solve


def _slow(fn):
    def stalled(*args, **kwargs):
        time.sleep(STALL)
        return fn(*args, **kwargs)
    return stalled


def test_guard_flags_a_solve_over_the_time_limit():
    info = new_info()
    slow = _slow(lambda: (np.zeros(2), True, "solved"))
    assert guarded_solve(info, slow, shape=(2,), time_limit=LIMIT) is None
    assert info["fallbacks"] == 1 and info["solver_status"].startswith("time limit")
    assert "solved" in info["solver_status"]
    assert guarded_solve(info, slow, shape=(2,), time_limit=None) is not None   # no limit
    assert guarded_solve(info, slow, shape=(2,), time_limit=1.0) is not None    # within it
    assert info["fallbacks"] == 1


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "1", True, MAX_SOLVE_TIME * 2])
@pytest.mark.parametrize("name", ["dmpc", "apf", "cgmres", "nmpc", "tube_rdmpc"])
def test_time_limit_option_is_validated(name, bad):
    env = {"dmpc": satenv.platoon_v0, "apf": satenv.cluster_v0, "cgmres": satenv.formation_v0,
           "nmpc": satenv.servicing_v0, "tube_rdmpc": satenv.cluster_v0}[name]()
    with pytest.raises(BaselineError, match="solve_time_limit"):
        baselines.make(name, env, solve_time_limit=bad)


def test_every_solver_config_has_a_default_limit():
    for cls in (baselines.DMPCConfig, baselines.APFConfig, baselines.CGMRESConfig, baselines.NMPCConfig,
                baselines.TubeRDMPCConfig):
        limit = cls().solve_time_limit
        assert limit is not None and 0 < limit <= MAX_SOLVE_TIME


def test_dmpc_stall_is_a_flagged_fallback(monkeypatch):
    from satenv.baselines.dmpc import QPSolver

    env = satenv.platoon_v0(topology="BDL", max_steps=5)
    pol = baselines.DMPC(env, seed=0, solve_time_limit=LIMIT, max_iterations=2)
    obs, _ = env.reset(seed=0)
    obs = _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] == 0
    monkeypatch.setattr(QPSolver, "solve_raw", _slow(QPSolver.solve_raw))
    _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] > 0 and pol.info["solver_status"].startswith("time limit")


def test_apf_stall_is_a_flagged_fallback(monkeypatch):
    env = satenv.cluster_v0(max_steps=3)
    pol = baselines.APF(env, solve_time_limit=LIMIT)
    obs, _ = env.reset(seed=0)
    pol.reset()
    monkeypatch.setattr(pol, "_law", _slow(pol._law))
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 and pol.info["solver_status"].startswith("time limit")


def test_cgmres_stall_is_a_flagged_fallback(monkeypatch):
    import satenv.baselines.cgmres as mod

    env = satenv.formation_v0(max_steps=6)
    pol = baselines.CGMRES(env, solve_time_limit=LIMIT)
    obs, _ = env.reset(seed=0)
    pol.reset()
    obs = _check_episode_goes_on(env, pol, obs, 1)
    monkeypatch.setattr(mod, "gmres", _slow(mod.gmres))
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 and pol.info["solver_status"].startswith("time limit")


def test_nmpc_stall_is_a_flagged_fallback(monkeypatch):
    pytest.importorskip("casadi")
    env = satenv.servicing_v0(max_steps=4)
    pol = baselines.NMPC(env, horizon=5, solve_time_limit=1.0)
    obs, _ = env.reset(seed=0)
    pol.reset()
    obs = _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] == 0
    pol.cfg = dataclasses.replace(pol.cfg, solve_time_limit=LIMIT)
    monkeypatch.setattr(pol, "_nlp", _slow(pol._nlp))
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 * pol.m and pol.info["solver_status"].startswith("time limit")


def test_nmpc_ipopt_stops_itself_at_the_limit():
    """ipopt's own ``max_wall_time`` is the limit: a limit far below one solve makes ipopt stop
    (a failed status, flagged) instead of running on."""
    pytest.importorskip("casadi")
    env = satenv.servicing_v0(max_steps=3)
    pol = baselines.NMPC(env, horizon=5, solve_time_limit=1e-6)
    obs, _ = env.reset(seed=0)
    pol.reset()
    _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] == pol.m
    assert "WallTime" in pol.info["solver_status"] or "time limit" in pol.info["solver_status"]


def test_tube_rdmpc_stall_is_a_flagged_fallback(monkeypatch):
    pytest.importorskip("casadi")
    env = satenv.cluster_v0(max_steps=4)
    pol = baselines.TubeRDMPC(env, solve_time_limit=LIMIT)
    obs, _ = env.reset(seed=0)
    pol.reset()
    real = pol.nlp.solver_for
    monkeypatch.setattr(pol.nlp, "solver_for",
                        lambda k, copy=0, relaxed=False: _slow(real(k, copy, relaxed)))
    _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] == pol.m and pol.info["solver_status"].startswith("time limit")
