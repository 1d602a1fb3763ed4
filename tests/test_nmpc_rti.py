"""satenv.baselines.NMPC with solver="rti": one condensed QP per decision about the shifted plan."""

import numpy as np
import pytest

pytest.importorskip("casadi")
pytest.importorskip("daqp")

from satenv.baselines.base import BaselineError  # noqa: E402
from satenv.baselines.nmpc import NMPC, NMPCConfig  # noqa: E402
from satenv.envs.servicing_v0 import parallel_env, unpack_global_state  # noqa: E402

HORIZON = 10   # a short horizon keeps the default suite fast; the §5.2 N = 30 runs in the perf module


def fly(pol, env, steps):
    obs, _ = env.reset(seed=0)
    pol.reset(seed=0)
    for _ in range(steps):
        act = pol.act(obs)
        assert all(np.all(np.abs(a) <= 1.0) and np.isfinite(a).all() for a in act.values())
        obs, *_ = env.step(act)
    return obs


def test_rti_solves_one_qp_per_warm_decision_and_keeps_the_constraints():
    env = parallel_env()
    pol = NMPC(env, solver="rti", horizon=HORIZON)
    fly(pol, env, 6)
    info = pol.info
    assert info["nlp_solves"] == pol.m                     # the first decision: cold, ipopt
    assert info["rti_steps"] == 5 * pol.m and info["rti_fallbacks"] == 0 and info["fallbacks"] == 0
    for plan in pol._plans:                                  # the QP's plan: inputs, bounds, keep-out
        assert np.all(np.abs(plan["u"]) <= pol.u_max * (1 + 1e-6))
        assert np.all(np.abs(plan["x"][1:, 3:6]) <= pol.v_lim * (1 + 1e-6))
        assert np.all(np.linalg.norm(plan["x"][1:, :3], axis=1) >= pol.keepout - 1e-6)


def test_rti_step_at_the_nlp_optimum_stays_there():
    """At the NLP's KKT point the Gauss-Newton QP's step is zero: the linearisation, the condensing
    and the rows are those of the NLP (a wrong Jacobian or sign would move the point)."""
    env = parallel_env()
    ref = NMPC(env, solver="ipopt", horizon=HORIZON, tol=1e-10, max_iter=500)
    rti = NMPC(env, solver="rti", horizon=HORIZON)
    fly(ref, env, 3)
    x, goals, t = unpack_global_state(env.state(), ref.m)
    ref._step = rti._step = int(round(t / env.scenario.dt))
    others = [np.tile(x[1, :3], (HORIZON, 1))]
    u0, _ = ref._solve_agent(0, x[0], np.tile(goals[0], (HORIZON, 1)), others)
    assert ref.info["solver_status"] == "Solve_Succeeded"
    rti._plans[0] = {**ref._plans[0], "duals": None}
    rti._last_goal[0] = goals[0].copy()
    u_rti, _ = rti._solve_agent(0, x[0], np.tile(goals[0], (HORIZON, 1)), others)
    assert rti.info["rti_steps"] == 1
    np.testing.assert_allclose(u_rti, u0, atol=1e-4 * float(np.max(ref.u_max)))


def test_a_failed_qp_falls_back_to_ipopt_and_is_flagged(monkeypatch):
    env = parallel_env()
    pol = NMPC(env, solver="rti", horizon=HORIZON)
    obs = fly(pol, env, 1)
    monkeypatch.setattr(pol._qp, "solve", lambda *a, **k: (None, False, "forced failure"))
    act = pol.act(obs)
    assert all(np.isfinite(a).all() for a in act.values())
    info = pol.info
    assert info["rti_fallbacks"] == pol.m and info["solver_failures"] >= pol.m
    assert info["nlp_solves"] == 2 * pol.m and info["fallbacks"] == 0    # ipopt took over


def test_rti_option_is_validated_and_shares_the_ipopt_nlp():
    with pytest.raises(BaselineError, match="solver"):
        NMPCConfig(solver="qp")
    env = parallel_env()
    assert NMPC(env, solver="rti", horizon=HORIZON)._nlp is NMPC(env, solver="ipopt", horizon=HORIZON)._nlp


def test_closed_loop_check_needs_the_same_successes_and_every_metric_within_two_percent():
    from satenv.bench.perf.experts import _compare

    def row(success, rmse, final, dv):
        return {"success": success, "rmse": rmse, "final_error_m": final, "delta_v": dv}

    ref = [row(True, 10.0, 0.1, 100.0)]
    assert _compare({"ipopt": ref, "fast": [row(True, 10.19, 0.1, 90.0)]})["within_tolerance"]
    assert not _compare({"ipopt": ref, "fast": [row(True, 10.21, 0.1, 90.0)]})["within_tolerance"]
    assert not _compare({"ipopt": ref, "fast": [row(True, 10.0, 0.103, 100.0)]})["within_tolerance"]
    assert not _compare({"ipopt": ref, "fast": [row(False, 9.0, 0.05, 90.0)]})["within_tolerance"]


def test_the_nmpc_expert_labels_with_rti_unless_told_otherwise():
    from satenv.baselines.registry import make_expert

    env = parallel_env()
    assert make_expert("nmpc", env, horizon=HORIZON).cfg.solver == "rti"
    assert make_expert("nmpc", env, horizon=HORIZON, solver="ipopt").cfg.solver == "ipopt"
    assert NMPC(env, horizon=HORIZON).cfg.solver == "ipopt"          # the baseline and the reproduction


def test_condensed_hessian_and_gradient_are_those_of_the_stacked_residuals():
    """The backward-recursion condensing equals ``2 M'M`` and ``2 M'r`` of the stacked residual
    Jacobian ``M`` (stage ``k``: ``Jx_k Phi_k + Ju_k E_k``, the terminal ``J_N Phi_N``)."""
    env = parallel_env()
    pol = NMPC(env, solver="rti", horizon=HORIZON)
    fly(pol, env, 3)
    x, goals, _ = unpack_global_state(env.state(), pol.m)
    goal_path = np.tile(goals[0], (HORIZON, 1))
    others = [np.tile(x[1, :3], (HORIZON, 1))]
    w0, _ = pol._initial_guess(0, x[0], goal_path[0])
    xg, ug = w0[pol._x_idx], w0[pol._u_idx]
    hess, grad, *_, phi_m, phi = pol._rti_qp(x[0], xg, ug, goal_path, others)
    stage, terminal = pol._rti
    out = stage(xg[:-1].T, ug.T, goal_path.T)[0].T
    part = [out[:, a:b] for a, b in zip(pol._rti_sizes[:-1], pol._rti_sizes[1:], strict=True)]
    jrx = part[4].reshape(HORIZON, 13, 19).transpose(0, 2, 1)
    jru = part[5].reshape(HORIZON, 6, 19).transpose(0, 2, 1)
    rows, res = [], []
    for k in range(HORIZON):
        m_k = jrx[k] @ phi_m[k]
        m_k[:, 6 * k:6 * k + 6] += jru[k]
        rows.append(m_k)
        res.append(part[3][k] + jrx[k] @ phi[k])
    term = terminal(xg[-1])[0].ravel()
    n_t = term.size // 14
    j_n = term[n_t:].reshape(13, n_t).T
    rows.append(j_n @ phi_m[HORIZON])
    res.append(term[:n_t] + j_n @ phi[HORIZON])
    m_all, r_all = np.vstack(rows), np.concatenate(res)
    np.testing.assert_allclose(hess, 2.0 * m_all.T @ m_all, rtol=1e-10, atol=1e-10 * np.abs(hess).max())
    np.testing.assert_allclose(grad, 2.0 * m_all.T @ r_all, rtol=1e-10, atol=1e-10 * np.abs(grad).max())
