"""The ``cgmres_ipopt`` section: one C/GMRES update against ipopt on the same NMPC problem."""

from __future__ import annotations

import time

import numpy as np


def _ms_stats(seconds: list[float]) -> tuple[float, float]:
    return float(np.median(seconds) * 1e3), float(np.percentile(seconds, 95) * 1e3)


def _cgmres_loop(env, pol, steps: int, stride: int) -> dict[str, list[float]]:
    """Closed loop of ``steps`` C/GMRES updates; at every ``stride``-th one, the same problem
    (state, horizon ``T(t)``, N, cost) solved by ipopt (tol 1e-8) warm- and cold-started."""
    ocp, warm = pol.ocp, None
    times: dict[str, list[float]] = {"cgmres": [], "warm": [], "cold": [], "diff": []}
    for k in range(steps):
        x, t = env.state(), pol.time
        start = time.perf_counter()
        w = pol.update(x)
        times["cgmres"].append(time.perf_counter() - start)
        if k % stride == 0 and k > 0:
            ref = ocp.solve_ipopt(x, pol.horizon_at(t), guess=warm, tol=1e-8)
            cold = ocp.solve_ipopt(x, pol.horizon_at(t), tol=1e-8)
            warm = ref["U"]
            times["warm"].append(ref["time_s"])
            times["cold"].append(cold["time_s"])
            times["diff"].append(float(np.abs(w - ref["w0"]).max() * env.scenario.u_max))
        act = w.reshape(ocp.m, 3)
        env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
    return times


def cgmres_vs_ipopt(preset: str, steps: int = 1000, stride: int = 10) -> dict:
    """Median / p95 ms of one C/GMRES update and of ipopt solves of the same NMPC problem on
    ``formation_v0(preset=preset)``, their ratios and the largest first-input gap [m/s^2]."""
    import satenv
    from satenv.baselines.cgmres import CGMRES

    env = satenv.make("formation_v0", preset=preset)
    pol = CGMRES(env)
    env.reset(seed=0)
    pol.reset(seed=0)
    pol.ocp.solve_ipopt(np.zeros(pol.ocp.nx), 1.0, tol=1e-8)  # build the NLP outside the timings
    times = _cgmres_loop(env, pol, steps, stride)
    (cg, cg95), (ipw, ipw95), (ipc, ipc95) = (_ms_stats(times[k]) for k in ("cgmres", "warm", "cold"))
    return {"scenario": preset, "steps": steps, "ipopt_solves": len(times["warm"]),
            "unknowns": pol.ocp.dim, "horizon_steps": pol.ocp.N, "kmax": pol.options["kmax"],
            "cgmres_update_ms_median": cg, "cgmres_update_ms_p95": cg95,
            "ipopt_warm_ms_median": ipw, "ipopt_warm_ms_p95": ipw95,
            "ipopt_cold_ms_median": ipc, "ipopt_cold_ms_p95": ipc95,
            "speedup_vs_ipopt_warm": ipw / cg, "speedup_vs_ipopt_cold": ipc / cg,
            "max_first_input_diff_mps2": max(times["diff"]), "fallbacks": pol.info["fallbacks"]}
