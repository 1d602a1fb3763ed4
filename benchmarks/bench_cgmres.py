"""Speed: one C/GMRES update vs an ipopt solve of the same NMPC problem (kannan2022 scenarios).

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_cgmres --out cgmres_bench.json``

Runs the closed loop of ``baselines.cgmres.CGMRES`` on ``satenv.formation_v0`` and, at every
``stride``-th sample, solves the same discretised problem (same state, same horizon ``T(t)``, same
N, same cost with the dummy inputs) with CasADi + ipopt (tol 1e-8), warm-started from the previous
ipopt solution and cold-started from the ``T = 0`` guess. Reported: median / p95 wall time of the
C/GMRES update (``CGMRES.update``: one continuation step, ``kmax`` GMRES iterations) and of both
ipopt solves, their ratio, and the largest difference of the first inputs (m/s^2).
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._io import write_json

SCENARIOS = ("kannan2022-position", "kannan2022-collision")


def bench_scenario(preset: str, steps: int = 1000, stride: int = 10, **cgmres_options) -> dict[str, Any]:
    """Closed loop of ``steps`` samples; ipopt at every ``stride``-th one."""
    from baselines.cgmres import CGMRES
    from satenv.envs.formation_v0 import parallel_env

    env = parallel_env(preset=preset)
    pol = CGMRES(env, **cgmres_options)
    env.reset(seed=0)
    pol.reset(seed=0)
    ocp = pol.ocp
    ocp.solve_ipopt(np.zeros(ocp.nx), 1.0, tol=1e-8)  # build the NLP outside the timings
    t_cg, t_warm, t_cold, diff = [], [], [], []
    warm = None
    u_max = env.scenario.u_max
    for k in range(steps):
        x, t = env.state(), pol.time
        start = time.perf_counter()
        w = pol.update(x)
        t_cg.append(time.perf_counter() - start)
        if k % stride == 0 and k > 0:
            horizon = pol.horizon_at(t)
            ref = ocp.solve_ipopt(x, horizon, guess=warm, tol=1e-8)
            cold = ocp.solve_ipopt(x, horizon, tol=1e-8)
            warm = ref["U"]
            t_warm.append(ref["time_s"])
            t_cold.append(cold["time_s"])
            diff.append(float(np.abs(w - ref["w0"]).max() * u_max))
        act = w.reshape(ocp.m, 3)
        env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
    ms = lambda a: (float(np.median(a) * 1e3), float(np.percentile(a, 95) * 1e3))  # noqa: E731
    cg, ipw, ipc = ms(t_cg), ms(t_warm), ms(t_cold)
    return {
        "scenario": preset, "steps": steps, "ipopt_solves": len(t_warm),
        "unknowns": ocp.dim, "horizon_steps": ocp.N, "kmax": pol.options["kmax"],
        "cgmres_update_ms_median": cg[0], "cgmres_update_ms_p95": cg[1],
        "ipopt_warm_ms_median": ipw[0], "ipopt_warm_ms_p95": ipw[1],
        "ipopt_cold_ms_median": ipc[0], "ipopt_cold_ms_p95": ipc[1],
        "speedup_vs_ipopt_warm": ipw[0] / cg[0], "speedup_vs_ipopt_cold": ipc[0] / cg[0],
        "max_first_input_diff_mps2": max(diff), "fallbacks": pol.info["fallbacks"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_cgmres", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="write the JSON here")
    parser.add_argument("--steps", type=int, default=1000, help="closed-loop samples per scenario (default 1000)")
    parser.add_argument("--stride", type=int, default=10, help="ipopt every STRIDE samples (default 10)")
    args = parser.parse_args(argv)
    rows = [bench_scenario(p, args.steps, args.stride) for p in SCENARIOS]
    result = {"benchmark": "cgmres_vs_ipopt", "machine": platform.platform(),
              "python": platform.python_version(), "rows": rows}
    for r in rows:
        print(f"{r['scenario']:22} C/GMRES update {r['cgmres_update_ms_median']:.2f} ms (p95 "
              f"{r['cgmres_update_ms_p95']:.2f}) | ipopt warm {r['ipopt_warm_ms_median']:.1f} ms, cold "
              f"{r['ipopt_cold_ms_median']:.1f} ms | x{r['speedup_vs_ipopt_warm']:.0f} / "
              f"x{r['speedup_vs_ipopt_cold']:.0f} | max |du0| {r['max_first_input_diff_mps2']:.2f} m/s^2 "
              f"| {r['unknowns']} unknowns")
    if args.out is not None:
        write_json(args.out, result)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
