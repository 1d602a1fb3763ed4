"""satenv.baselines.TubeRDMPC with solver="rti": one sequential-convexification QP per satellite."""

import numpy as np
import pytest

pytest.importorskip("casadi")
pytest.importorskip("daqp")

from satenv.baselines.base import BaselineError  # noqa: E402
from satenv.baselines.tube_rdmpc import NLP_CONSTRAINT_TOL, TubeRDMPC, TubeRDMPCConfig  # noqa: E402
from satenv.envs.cluster_v0 import parallel_env  # noqa: E402


def fly(pol, env, steps):
    obs, _ = env.reset(seed=0)
    pol.reset(seed=0)
    for _ in range(steps):
        act = pol.act(obs)
        assert all(np.isfinite(a).all() and np.linalg.norm(a) <= 1.0 + 1e-9 for a in act.values())
        obs, *_ = env.step(act)
    return obs


def test_rti_solves_one_qp_per_warm_decision_within_the_nlp_rows():
    env = parallel_env(terminate_on_collision=False)
    pol = TubeRDMPC(env, solver="rti")
    fly(pol, env, 4)
    info = pol.info
    assert info["solves"] == 4 * pol.m and info["qp_steps"] == 3 * pol.m   # decision 1: cold, ipopt
    assert info["rti_fallbacks"] == 0 and info["relaxed"] == 0 and info["fallbacks"] == 0


def test_qp_step_at_the_nlp_optimum_stays_there():
    """At the exact NLP's optimum the linearised QP's step is zero (the rows, their Jacobian and
    the cost's Hessian and gradient are the NLP's): the point comes back unchanged."""
    env = parallel_env(terminate_on_collision=False)
    ref = TubeRDMPC(env, tol=1e-10, max_iter=500, warm_duals=False)
    fly(ref, env, 2)
    captured = {}
    solve = ref.nlp.solve

    def spy(info, params, w0, relaxed, duals=None, copy=0):
        w = solve(info, params, w0, relaxed, duals, copy)
        captured.setdefault("first", (params.copy(), None if w is None else w.copy()))
        return w

    ref.nlp.solve = spy
    ref.act({a: None for a in env.agents})
    params, w_opt = captured["first"]
    assert w_opt is not None
    rti = TubeRDMPC(env, solver="rti")
    for mu in (None, np.ones(rti.nlp.curvature.shape[0])):     # the convex rows' curvature moves no KKT point
        if mu is not None:
            rti.nlp._mu[0] = mu
        info = {}
        w = rti.nlp.qp_step(info, params, w_opt, owner=0)
        assert w is not None, info
        np.testing.assert_allclose(w[:3], w_opt[:3], atol=1e-4)    # the first input (unit ball)


def test_a_failed_qp_falls_back_to_ipopt_and_is_flagged(monkeypatch):
    env = parallel_env(terminate_on_collision=False)
    pol = TubeRDMPC(env, solver="rti")
    obs = fly(pol, env, 1)
    monkeypatch.setattr(pol.nlp._qp, "solve", lambda *a, **k: (None, False, "forced failure"))
    pol.act(obs)
    info = pol.info
    assert info["rti_fallbacks"] == pol.m and info["qp_steps"] == 0
    assert info["solver_failures"] >= pol.m and info["fallbacks"] == 0          # ipopt took over


def test_a_qp_step_from_a_start_inside_a_keepout_is_refused():
    env = parallel_env(terminate_on_collision=False)
    pol = TubeRDMPC(env, solver="rti")
    fly(pol, env, 1)
    nlp = pol.nlp
    k = nlp.slot_sizes[0]
    rows = nlp._buffered("rows", k, 0)
    params = np.zeros(nlp._fixed + k * nlp._per_slot)
    params[6:9] = [1000.0, 0, 0]                 # target far away; everything else at the origin
    info = {}
    # at the origin the target-spacecraft keep-out row is violated: the step is refused, not used
    assert nlp.qp_step(info, params, np.zeros(nlp.n_w), owner=0) is None
    assert "NLP rows" in info["solver_status"] or info["solver_failures"] >= 1
    assert rows(np.zeros(nlp.n_w), params)[0].min() < -NLP_CONSTRAINT_TOL


def test_rti_option_is_validated():
    with pytest.raises(BaselineError, match="solver"):
        TubeRDMPCConfig(solver="qp")
    assert TubeRDMPCConfig(solver="rti").solver == "rti"


def test_convex_row_curvature_is_their_hessian_and_their_planes_support_the_ball():
    """``curvature`` is the Hessian on the inputs of the thrust-ball and speed rows (central
    differences of the rows' Jacobian, exact for these quadratic rows); ``_support`` gives the
    tangent plane at the sphere's nearest point: every point of the sphere satisfies it, the
    nearest one with equality."""
    from satenv.baselines.tube_rdmpc import _support

    env = parallel_env(terminate_on_collision=False)
    pol = TubeRDMPC(env, solver="rti")
    nlp = pol.nlp
    k = nlp.slot_sizes[0]
    params = np.zeros(nlp._fixed + k * nlp._per_slot)
    params[:6] = [100.0, -50.0, 20.0, 1.0, -0.5, 0.2]
    params[6:9] = [300.0, 200.0, -100.0]
    rng = np.random.default_rng(0)
    w = np.zeros(nlp.n_w)
    w[:3 * nlp.N] = rng.uniform(-0.5, 0.5, 3 * nlp.N)
    lin = nlp._buffered("lin", k, 0)
    convex, step, cols = nlp.convex_rows(k), 1e-3, 3 * nlp.N
    fd = np.empty((convex.size, cols, cols))
    for j in range(cols):
        e = np.zeros(nlp.n_w)
        e[j] = step
        fd[:, :, j] = (lin(w + e, params)[3][convex, :cols] - lin(w - e, params)[3][convex, :cols]) / (2 * step)
    np.testing.assert_allclose(nlp.curvature, fd, atol=1e-8 * max(1.0, np.abs(fd).max()))
    y, r = rng.normal(size=3), 2.0
    g = np.array([y @ y / r**2 - 1.0])
    jac = 2.0 * y / r**2
    sphere = rng.normal(size=(200, 3))
    sphere = r * sphere / np.linalg.norm(sphere, axis=1, keepdims=True)
    assert np.all((sphere - y) @ jac <= _support(g)[0] + 1e-12)
    assert (r * y / np.linalg.norm(y) - y) @ jac == pytest.approx(_support(g)[0])
