"""The ``solvers`` and ``fast_solvers`` sections: per-decision solve times of the scripted MPC
baselines, and the fast solver paths against the ipopt reference on recorded problems."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ._common import act_times

SOLVERS = [  # (policy, scenario, decisions to time)
    ("dmpc", "platoon-PLF-cw", 180),
    ("tube_rdmpc", "cluster-case1", 6),
    ("nmpc", "servicing-pereira2022", 20),
    ("cgmres", "formation-kannan2022-position", 100),
]


def solver_times(max_decisions_scale: float = 1.0, max_seconds: float = 60.0,
                 policies: tuple[str, ...] | None = None) -> dict:
    """Median / p95 wall time of ``act()`` (all agents) and of the solver's own ``solve_ms`` /
    ``qp_ms`` entries, over the first decisions of one episode (seed 0)."""
    from satenv.bench.scoreboard.registry import POLICIES, TASKS
    from satenv.bench.scoreboard.specs import Unavailable

    out: dict[str, Any] = {}
    for pol_name, scen_name, decisions in SOLVERS:
        if policies is not None and pol_name not in policies:
            continue
        key = f"{pol_name}@{scen_name}"
        try:
            env = TASKS[scen_name].make()
            policy = POLICIES[pol_name].make(env)
        except Unavailable as why:
            out[key] = {"skipped": str(why)}
            continue
        obs, _ = env.reset(seed=0)
        policy.reset(seed=0)
        times, start = [], time.perf_counter()
        for _ in range(max(1, int(decisions * max_decisions_scale))):
            t0 = time.perf_counter()
            act = policy.act(obs)
            times.append(1e3 * (time.perf_counter() - t0))
            obs, _, _, _, _ = env.step(act)
            if not env.agents or time.perf_counter() - start > max_seconds:
                break
        info = dict(getattr(policy, "info", {}) or {})
        n = env.core.n_agents if hasattr(env, "core") else len(env.possible_agents)
        row = {"decisions": len(times), "agents": n,
               "act_ms_median": float(np.median(times)), "act_ms_p95": float(np.percentile(times, 95)),
               "act_ms_per_agent_median": float(np.median(times)) / n,
               "fallbacks": int(info.get("fallbacks", 0))}
        for k in ("solve_ms", "qp_ms", "agent_solve_ms"):
            v = np.asarray(info.get(k, []), dtype=float).ravel()
            if v.size:
                row[f"{k}_median"] = float(np.median(v))
                row[f"{k}_p95"] = float(np.percentile(v, 95))
                row[f"{k}_count"] = int(v.size)
        out[key] = row
        env.close()
    return out


FAST_SOLVER_TARGETS_MS = {"tube_rdmpc@cluster-case1": 5.0, "nmpc@servicing-pereira2022": 10.0}
"""The fast solver path's targets: ms per agent decision."""


def _record(scen_name: str, make: Callable, hook: str, decisions: int) -> tuple[Any, list[tuple]]:
    """Run ``make(env)`` (the ipopt reference) for ``decisions`` and record the arguments of every
    call of its solve method ``hook`` (``"nlp.solve"`` or ``"_run_nlp"``)."""
    from satenv.bench.scoreboard.registry import TASKS

    env = TASKS[scen_name].make()
    ref = make(env)
    owner_path, name = hook.rsplit(".", 1) if "." in hook else ("", hook)
    owner = ref if not owner_path else getattr(ref, owner_path)
    inner, calls = getattr(owner, name), []

    def recording(*args, **kwargs):  # copies: the controller reuses its warm-start rows
        calls.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in (*args, *kwargs.values())))
        return inner(*args, **kwargs)

    setattr(owner, name, recording)
    obs, _ = env.reset(seed=0)
    ref.reset(seed=0)
    for _ in range(decisions):
        obs, *_ = env.step(ref.act(obs))
        if not env.agents:
            break
    setattr(owner, name, inner)
    return ref, calls


def fast_vs_ipopt(decisions_scale: float = 1.0, policies: tuple[str, ...] | None = None) -> dict:
    """ms per agent decision of the fast path and of the ipopt reference on the same recorded
    decision problems (tube-RDMPC li2022 case 1, N = 10; NMPC pereira2022 §5.2, N = 30), medians,
    the compile time and the largest first-control gap.

    Tube-RDMPC: the reference is ipopt with the primal warm start only (``warm_duals=False``); the
    fast path is ``solver="ipopt-jit"`` with ``warm_duals`` (each satellite's multipliers chained
    through the recorded decisions, as in the controller); ``warm_duals_ms_...`` is the
    interpreted ipopt with ``warm_duals`` alone. NMPC: the default ``hessian="gauss-newton"``
    against ``hessian="exact"``, and both one's median NLP time along the closed loop
    (:func:`nmpc_closed_loop`)."""
    from satenv.baselines.nmpc import NMPC
    from satenv.baselines.tube_rdmpc import TubeRDMPC

    out: dict[str, Any] = {}
    for key, cls, hook, decisions in (("tube_rdmpc@cluster-case1", TubeRDMPC, "nlp.solve", 3),
                                      ("nmpc@servicing-pereira2022", NMPC, "_run_nlp", 10)):
        if policies is not None and key.split("@")[0] not in policies:
            continue
        tube = cls is TubeRDMPC
        ref_options = {"warm_duals": False} if tube else {"hessian": "exact"}
        ref, calls = _record(key.split("@")[1], lambda env, c=cls, o=ref_options: c(env, solver="ipopt", **o),
                             hook, max(1, int(decisions * decisions_scale)))
        start = time.perf_counter()
        pols = {"ipopt": ref, "fast": cls(ref.env, solver="ipopt-jit") if tube else cls(ref.env)}
        slots = [ref.nlp.slots(args[1]) for args in calls] if tube else []
        if tube:   # build (compile) the NLPs of the recorded problems' slot counts before timing
            pols["fast"].nlp.prepare(slots)
        compile_s = time.perf_counter() - start
        if tube:
            pols["warm_duals"] = cls(ref.env, solver="ipopt")
            for pol in (ref, pols["warm_duals"]):
                pol.nlp.prepare(slots)
        times: dict[str, list[float]] = {label: [] for label in pols}
        duals = {label: [{} for _ in range(ref.m)] for label in pols}
        gap = 0.0
        for k, args in enumerate(calls):
            first = []
            for label, pol in pols.items():
                if tube:
                    warm = duals[label][k % ref.m] if pol.cfg.warm_duals else None
                    t0 = time.perf_counter()
                    w = pol.nlp.solve({}, *args[1:4], warm)
                    times[label].append(time.perf_counter() - t0)
                    first.append(None if w is None else w[:3] * pol.u_nom)
                else:
                    res: dict[str, Any] = {}
                    t0 = time.perf_counter()
                    w, _, _ = pol._run_nlp(args[0], res)
                    times[label].append(time.perf_counter() - t0)
                    first.append(w[pol._u_idx[0]])
            if all(f is not None for f in first):
                gap = max(gap, max(float(np.abs(first[0] - f).max()) for f in first[1:]))
        ms = {label: float(np.median(t) * 1e3) for label, t in times.items()}
        out[key] = {"problems": len(calls), "ipopt_ms_per_agent_decision_median": ms["ipopt"],
                    "fast_ms_per_agent_decision_median": ms["fast"], "speedup": ms["ipopt"] / ms["fast"],
                    "fast_solver": "ipopt-jit + warm_duals" if tube else "ipopt + gauss-newton",
                    "compile_s": compile_s,
                    "max_first_control_diff": gap, "target_ms": FAST_SOLVER_TARGETS_MS[key]}
        if tube:
            out[key]["warm_duals_ms_per_agent_decision_median"] = ms["warm_duals"]
            out[key]["closed_loop_ms_per_agent_decision"] = tube_closed_loop(ref.env)
        else:
            out[key]["closed_loop_ms_per_agent_decision"] = nmpc_closed_loop(
                ref.env, max(10, int(300 * decisions_scale)))
    return out


NMPC_VARIANTS: dict[str, dict[str, Any]] = {
    "exact": {"hessian": "exact"},
    "gauss_newton": {"hessian": "gauss-newton"},
    "gauss_newton_jit": {"hessian": "gauss-newton", "solver": "ipopt-jit"},
    "gauss_newton_jit_adaptive_mu": {"hessian": "gauss-newton", "solver": "ipopt-jit",
                                     "solver_options": {"ipopt.mu_strategy": "adaptive"}},
}
"""The NMPC configurations timed along the closed loop (public options only): the exact Hessian
(the reference), the default Gauss-Newton one, compiled, and compiled with ipopt's adaptive barrier
update (fewer iterations on the recorded problems: 7.4 against 8.4)."""


def nmpc_closed_loop(env, decisions: int = 300) -> dict[str, float]:
    """Median ms per NLP solve of the NMPC along its own closed loop (the first ``decisions``
    steps of §5.2 from seed 0: the first waypoint phase is 400), per :data:`NMPC_VARIANTS` entry,
    and each one's mean ipopt iterations (``<name>_iterations``)."""
    from satenv.baselines.nmpc import NMPC

    out = {}
    for name, options in NMPC_VARIANTS.items():
        pol = NMPC(env, **options)
        act_times(env, pol, 1)                  # builds (compiles) before the timed episode
        act_times(env, pol, decisions)
        out[name] = float(np.median(pol.info["agent_solve_ms"]))
        out[f"{name}_iterations"] = float(np.mean(pol.info["iterations"]))
    return out


def tube_closed_loop(env, decisions: int = 6, workers: tuple[int, ...] = (1, 2)) -> dict[str, float]:
    """Wall time of whole ``TubeRDMPC.act`` calls (ipopt with ``warm_duals``) divided by the number
    of satellites, median over ``decisions`` from the same start, for each thread count (the
    decisions are identical; ``tests/test_tube_rdmpc.py``), and for ``solver="ipopt-jit"`` on one
    thread (``ipopt_jit_workers_1``; timed on a second pass, after the compiles)."""
    from satenv.baselines.tube_rdmpc import TubeRDMPC

    def per_agent(pol: TubeRDMPC) -> float:
        return float(np.median(act_times(env, pol, decisions))) * 1e3 / len(env.possible_agents)

    out = {f"workers_{n}": per_agent(TubeRDMPC(env, workers=n)) for n in workers}
    jit = TubeRDMPC(env, solver="ipopt-jit")
    act_times(env, jit, decisions)              # compiles the solvers these decisions use
    out["ipopt_jit_workers_1"] = per_agent(jit)
    return out
