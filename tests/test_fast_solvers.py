"""The fast solver paths (``solver="ipopt-jit"``, tube ``warm_duals``, NMPC
``hessian="gauss-newton"``) against the ipopt reference on recorded problems.

Decision problems (initial state, neighbours' predictions, waypoints: the NLP parameters and the
warm start) are recorded from the li2022 case-1 cluster under the tube-RDMPC and from the
pereira2022 §5.2 servicing scenario under the NMPC, each solved by the interpreted ipopt build
(the reference) and by the compiled one. Agreement: objective within 1e-6 relative, first control
within 1e-6 (tube: of the unit-ball-scaled input; NMPC: in N, of inputs up to 3 N). The horizons are
shortened (N = 3) so the gcc compile stays a few seconds in the default suite;
``satenv.bench.perf`` times the full horizons against the same reference. Last, the parallel
expert labeller (``satenv.training.labeller.ExpertPool``) against labelling in one process.
"""

import numpy as np
import pytest

pytest.importorskip("casadi")

from satenv.baselines.nmpc import NMPC, NMPCConfig  # noqa: E402
from satenv.baselines.tube_rdmpc import TubeRDMPC  # noqa: E402
from satenv.envs.cluster_v0 import parallel_env as cluster_env  # noqa: E402
from satenv.envs.servicing_v0 import parallel_env as servicing_env  # noqa: E402

REL_OBJECTIVE_TOL = 1e-6
FIRST_CONTROL_TOL = 1e-6


def record_tube_problems(decisions: int = 2, horizon: float = 15.0) -> tuple[list[dict], dict]:
    env = cluster_env(preset="li2022-case1", terminate_on_collision=False)
    ref = TubeRDMPC(env, solver="ipopt", horizon=horizon)
    problems: list[dict] = []
    solve = ref.nlp.solve

    def recording(info, params, w0, relaxed, duals=None, copy=0):
        problems.append({"params": params.copy(), "w0": w0.copy(), "relaxed": relaxed})
        return solve(info, params, w0, relaxed, duals, copy)

    ref.nlp.solve = recording
    obs, _ = env.reset(seed=0)
    ref.reset(seed=0)
    for _ in range(decisions):
        obs, *_ = env.step(ref.act(obs))
    return problems, {"ref": ref, "fast": TubeRDMPC(env, solver="ipopt-jit", horizon=horizon)}


def tube_solution(pol: TubeRDMPC, problem: dict, duals: dict | None = None) -> tuple[float, np.ndarray, bool]:
    """Objective, point and success of one recorded problem; ``duals`` (``lam_x``, ``lam_g``) are
    the multipliers to start from, replaced by the solve's own."""
    nlp = pol.nlp
    lbx, ubx = nlp.bounds(problem["relaxed"])
    w0 = np.clip(problem["w0"], lbx, np.where(np.isfinite(ubx), ubx, problem["w0"]))
    k = nlp.slots(problem["params"])
    solver, (lbg, ubg) = nlp.solver_for(k), nlp.row_bounds(k)
    if duals and duals["lam_g"].size != lbg.size:
        duals.clear()
    start = {"lam_x0": duals["lam_x"], "lam_g0": duals["lam_g"]} if duals else {}
    sol = solver(x0=w0, p=problem["params"], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **start)
    if duals is not None:
        duals.update(lam_x=np.asarray(sol["lam_x"]).ravel(), lam_g=np.asarray(sol["lam_g"]).ravel())
    return float(sol["f"]), np.asarray(sol["x"]).ravel(), bool(solver.stats()["success"])


def test_compiled_tube_rdmpc_finds_the_ipopt_optimum_on_recorded_li2022_problems():
    problems, pols = record_tube_problems()
    assert len(problems) >= 20
    for problem in problems:
        f_ref, w_ref, ok_ref = tube_solution(pols["ref"], problem)
        f_fast, w_fast, ok_fast = tube_solution(pols["fast"], problem)
        assert ok_fast == ok_ref
        assert abs(f_fast - f_ref) <= REL_OBJECTIVE_TOL * max(1.0, abs(f_ref))
        assert np.abs(w_fast[:3] - w_ref[:3]).max() <= FIRST_CONTROL_TOL


def test_tube_rdmpc_dual_warm_start_finds_the_cold_ipopt_optimum_on_recorded_problems():
    """``warm_duals`` (multipliers of the satellite's previous solve, chained through the recorded
    decisions as in the controller) against the primal-only warm start: the same optimum in fewer
    ipopt iterations."""
    problems, pols = record_tube_problems(decisions=3)
    env = pols["ref"].env
    cold = TubeRDMPC(env, solver="ipopt", horizon=15.0, warm_duals=False)
    warm = TubeRDMPC(env, solver="ipopt", horizon=15.0, warm_duals=True)
    duals: list[dict] = [{} for _ in range(env.num_agents)]
    iterations = {"cold": 0, "warm": 0}
    for k, problem in enumerate(problems):
        f_cold, w_cold, ok_cold = tube_solution(cold, problem)
        iterations["cold"] += cold.nlp.solver_for(cold.nlp.slots(problem["params"])).stats()["iter_count"]
        f_warm, w_warm, ok_warm = tube_solution(warm, problem, duals[k % env.num_agents])
        iterations["warm"] += warm.nlp.solver_for(warm.nlp.slots(problem["params"])).stats()["iter_count"]
        assert ok_warm == ok_cold
        assert abs(f_warm - f_cold) <= REL_OBJECTIVE_TOL * max(1.0, abs(f_cold))
        assert np.abs(w_warm[:3] - w_cold[:3]).max() <= FIRST_CONTROL_TOL
    assert iterations["warm"] < iterations["cold"]


def record_nmpc_problems(decisions: int = 6, **options) -> tuple[NMPC, list[dict]]:
    """The NLP arguments (parameters, warm start, multipliers) of every NMPC solve of the first
    ``decisions`` steps of pereira2022 §5.2 under the ipopt reference."""
    env = servicing_env(preset="pereira2022")
    ref = NMPC(env, solver="ipopt", hessian="exact", **options)
    problems: list[dict] = []
    run = ref._run_nlp

    def recording(args, out):
        problems.append({k: np.array(v, dtype=float) for k, v in args.items()})
        return run(args, out)

    ref._run_nlp = recording
    obs, _ = env.reset(seed=0)
    ref.reset(seed=0)
    for _ in range(decisions):
        obs, *_ = env.step(ref.act(obs))
    ref._run_nlp = run
    return ref, problems


def test_compiled_nmpc_finds_the_ipopt_optimum_on_recorded_pereira2022_problems():
    ref, problems = record_nmpc_problems(horizon=3)
    fast = NMPC(ref.env, solver="ipopt-jit", hessian="exact", horizon=3)
    assert len(problems) == 12
    u0 = ref._u_idx[0]
    for args in problems:
        sol_ref, sol_fast = ref._nlp(**args), fast._nlp(**args)
        assert fast._nlp.stats()["success"] == ref._nlp.stats()["success"]
        f_ref, f_fast = float(sol_ref["f"]), float(sol_fast["f"])
        assert abs(f_fast - f_ref) <= REL_OBJECTIVE_TOL * max(1.0, abs(f_ref))
        x_ref, x_fast = np.asarray(sol_ref["x"]).ravel(), np.asarray(sol_fast["x"]).ravel()
        assert np.abs(x_fast[u0] - x_ref[u0]).max() <= FIRST_CONTROL_TOL


@pytest.mark.parametrize(("tol", "control_tol", "objective_tol"), [(1e-6, 1e-3, 1e-7), (1e-8, 1e-5, 1e-10)])
def test_gauss_newton_nmpc_finds_the_exact_hessian_optimum(tol, control_tol, objective_tol):
    """``hessian="gauss-newton"`` against the exact Hessian on recorded §5.2 problems (N = 30):
    the same optimum, the gap shrinking with the tolerance both are solved to."""
    ref, problems = record_nmpc_problems(decisions=4, tol=tol)
    gn = NMPC(ref.env, solver="ipopt", hessian="gauss-newton", tol=tol)
    u0 = ref._u_idx[0]
    for args in problems:
        sol_ref, sol_gn = ref._nlp(**args), gn._nlp(**args)
        assert gn._nlp.stats()["success"] and ref._nlp.stats()["success"]
        f_ref, f_gn = float(sol_ref["f"]), float(sol_gn["f"])
        assert abs(f_gn - f_ref) <= objective_tol * abs(f_ref)
        x_ref, x_gn = np.asarray(sol_ref["x"]).ravel(), np.asarray(sol_gn["x"]).ravel()
        assert np.abs(x_gn[u0] - x_ref[u0]).max() <= control_tol


def test_solver_option_is_validated():
    env = cluster_env(preset="li2022-case1")
    with pytest.raises(ValueError, match="solver"):
        TubeRDMPC(env, solver="snopt")
    with pytest.raises(ValueError, match="solver"):
        NMPC(servicing_env(preset="pereira2022"), solver="ipopt_jit")
    env = servicing_env(preset="pereira2022")
    assert NMPC(env, solver="fatrop", horizon=3).hessian == "exact"
    assert NMPC(env, horizon=3).hessian == "gauss-newton"
    assert NMPC(env, config=NMPCConfig(horizon=3), solver="fatrop").hessian == "exact"
    with pytest.raises(ValueError, match="hessian"):
        NMPC(servicing_env(preset="pereira2022"), solver="fatrop", hessian="gauss-newton")
    with pytest.raises(ValueError, match="hessian"):
        NMPC(servicing_env(preset="pereira2022"), hessian="newton")


# --------------------------------------------------------------------------- parallel expert labels
def test_expert_pool_rejects_a_bad_worker_count():
    from satenv.training.labeller import ExpertPool

    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="workers"):
            ExpertPool("joint_platoon_mpc", workers=bad)


@pytest.mark.slow
def test_expert_pool_labels_are_those_of_one_process():
    """Two workers label three short platoon episodes (one flown by the expert with action noise):
    the rows and stats of each equal those of ``label_episode`` in this process."""
    from satenv.training import labeller
    from satenv.training.labeller import ExpertPool, LabelJob

    kw = {"max_steps": 4}
    jobs = [LabelJob("platoon-pereira2022-random", seed=s, noise=n, rng=s, env_kwargs=kw)
            for s, n in ((3, 0.0), (4, 0.1), (5, 0.0))]
    with ExpertPool("joint_platoon_mpc", workers=2, warm=(jobs[0],)) as pool:
        out = pool.label(jobs)
        with pytest.raises(TypeError, match="LabelJob"):
            pool.label([{"task": "x"}])
    labeller._WORKER.clear()
    labeller._WORKER["expert"] = ("joint_platoon_mpc", {})
    try:
        for job, (rows, stats) in zip(jobs, out, strict=True):
            ref_rows, ref_stats = labeller.label_episode(job)
            assert stats == ref_stats and rows.keys() == ref_rows.keys()
            for key in rows:
                np.testing.assert_array_equal(rows[key], ref_rows[key], err_msg=key)
            assert len(rows["act"]) == 4 * len(labeller._WORKER[(job.task, '{"max_steps": 4}')][0].possible_agents)
    finally:
        labeller._WORKER.clear()


def test_dense_qp_least_distance_form_finds_daqps_optimum_and_warm_starts_to_it():
    """:class:`DenseQP` (the QP brought to least-distance form here) against DAQP on the QP as it is,
    with an equality bound; then a perturbed QP from the first one's active set, moved by a shift,
    against the same QP solved cold."""
    daqp = pytest.importorskip("daqp")
    from satenv.baselines._qp import DenseQP

    rng = np.random.default_rng(3)
    n, m = 12, 20
    q = rng.normal(size=(n, n))
    h = q @ q.T + n * np.eye(n)
    f, a = rng.normal(size=n), rng.normal(size=(m, n))
    lo, hi = -np.abs(rng.normal(size=m)) - 0.2, np.abs(rng.normal(size=m)) + 0.2
    lb, ub = -np.full(n, 0.3), np.full(n, 0.3)
    lb[4] = ub[4] = 0.1
    sense = np.zeros(n + m, dtype=np.intc)
    sense[4] = 5
    ref, _, flag, _ = daqp.solve(h, f, a, np.r_[ub, hi], np.r_[lb, lo], sense)
    qp = DenseQP()
    x, ok, status = qp.solve(h, f, a, lo, hi, lb, ub, owner="a")
    assert flag == 1 and ok, status
    np.testing.assert_allclose(x, ref, atol=1e-9)
    assert x[4] == pytest.approx(0.1)
    f2 = f + 0.05 * rng.normal(size=n)
    shift = np.r_[np.arange(1, n + m), -1]
    warm, ok, _ = qp.solve(h, f2, a, lo, hi, lb, ub, owner="a", shift=shift)
    cold, ok_cold, _ = DenseQP().solve(h, f2, a, lo, hi, lb, ub)
    assert ok and ok_cold
    np.testing.assert_allclose(warm, cold, atol=1e-9)
    assert qp.solve(-h, f, a, lo, hi, lb, ub)[:2] == (None, False)          # not positive definite
