"""Speed of the 1-hop DMPC and of the pereira2023 Table II reproduction.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_dmpc --out bench_dmpc.json``

Reports (targets of issue 3: median solve per agent <= 1 ms, reproduction <= 10 s):

* ``qp_ms``: one agent's local QP (update + DAQP solve, 90 variables, 90 velocity rows), median
  over every solve of the three Table II episodes; the same for OSQP (eps 1e-9) on PLF;
* ``decision_ms_per_agent``: one DMPC decision (all Jacobi iterations of all agents) divided
  by the number of agents, median over the episodes;
* ``unconstrained_decision_ms``: one decision of the unconstrained variant (closed-form local
  solutions);
* ``reproduction_s``: wall time of ``benchmarks.repro_pereira2023.reproduce()`` in-process
  (median of ``--repeats``) and of the full command ``python -m benchmarks.reproduce
  pereira2023`` in a fresh interpreter (imports included, no plots).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np


def _episode_stats(topology: str, **options) -> dict:
    from benchmarks.repro_pereira2023 import run_topology

    _, env, policy = run_topology(topology, **options)
    n = env.scenario.n_followers
    return {"qp_ms": np.asarray(policy.info["qp_ms"]),
            "decision_ms": np.asarray(policy.info["solve_ms"]),
            "n_agents": n}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_dmpc", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="write the JSON here")
    parser.add_argument("--repeats", type=int, default=3, help="repetitions of the reproduction")
    args = parser.parse_args(argv)

    from baselines.dmpc import OneHopDMPC
    from benchmarks.repro_pereira2023 import reproduce
    from satenv.scenarios.platoon import PRESETS

    # warm-up (imports, first DAQP setups)
    reproduce()
    qp, dec_per_agent = [], []
    for topo in ("PLF", "BDL", "TPLF"):
        st = _episode_stats(topo)
        qp.append(st["qp_ms"])
        dec_per_agent.append(st["decision_ms"] / st["n_agents"])
    qp_all, dec_all = np.concatenate(qp), np.concatenate(dec_per_agent)
    osqp = _episode_stats("PLF", solver="osqp")

    sc = PRESETS["pereira2023"]
    unc = OneHopDMPC(sc, constrained=False, seed=0)
    x = sc.initial_array()
    times = []
    for _ in range(200):
        t0 = time.perf_counter()
        unc.solve(x)
        times.append(1e3 * (time.perf_counter() - t0))

    walls = []
    for _ in range(max(1, args.repeats)):
        t0 = time.perf_counter()
        res = reproduce()
        walls.append(time.perf_counter() - t0)
    env = dict(os.environ, OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "benchmarks.reproduce", "pereira2023"],
                          capture_output=True, text=True, env=env)
    cli_wall = time.perf_counter() - t0

    result = {
        "machine": {"python": platform.python_version(), "processor": platform.processor(),
                    "cpus": os.cpu_count(),
                    "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS")},
        "qp_ms": {"solver": "daqp", "median": float(np.median(qp_all)),
                  "p90": float(np.percentile(qp_all, 90)), "count": int(qp_all.size)},
        "qp_ms_osqp": {"solver": "osqp eps=1e-9", "median": float(np.median(osqp["qp_ms"])),
                       "p90": float(np.percentile(osqp["qp_ms"], 90))},
        "decision_ms_per_agent": {"median": float(np.median(dec_all)),
                                  "p90": float(np.percentile(dec_all, 90)),
                                  "max": float(np.max(dec_all))},
        "unconstrained_decision_ms": float(np.median(times)),
        "reproduction_s": {"in_process_median": float(np.median(walls)),
                           "in_process_all": walls, "cli_fresh_process": cli_wall,
                           "cli_exit_code": proc.returncode},
        "reproduction_pass": bool(res["pass"]),
        "targets": {"median_solve_per_agent_ms": 1.0, "reproduction_s": 10.0},
    }
    result["meets_targets"] = bool(
        result["qp_ms"]["median"] <= 1.0 and result["decision_ms_per_agent"]["median"] <= 1.0
        and cli_wall <= 10.0)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
