"""Speed of ``baselines.TubeRDMPC``: NLP solve time per satellite on the li2022 scenario.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_tube_rdmpc [--case 1] [--steps 60] [--out FILE.json]``

Runs the tube RDMPC on ``cluster_v0`` for ``--steps`` decisions and reports the median / p90 /
max of every ipopt solve (one per satellite per decision, plus the relaxed re-solves), the ipopt
iteration counts, and the controller's wall time per decision (10 solves) and the env's.
Target (issue 4): median solve per satellite <= 100 ms.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np


def measure(case: int = 1, steps: int = 60, seed: int = 0) -> dict:
    from baselines.tube_rdmpc import TubeRDMPC
    from satenv.envs.cluster_v0 import parallel_env

    env = parallel_env(preset=f"li2022-case{case}", terminate_on_collision=False)
    pol = TubeRDMPC(env)
    iters: list[int] = []
    solve = pol.nlp.solve

    def counting(params, w0, relaxed):
        out = solve(params, w0, relaxed)
        iters.append(int(pol.nlp.solver.stats().get("iter_count", -1)))
        return out

    pol.nlp.solve = counting
    obs, _ = env.reset(seed=seed)
    pol.reset(seed=seed)
    act_s, env_s = [], []
    for _ in range(steps):
        t0 = time.perf_counter()
        actions = pol.act(obs)
        t1 = time.perf_counter()
        obs, *_ = env.step(actions)
        env_s.append(time.perf_counter() - t1)
        act_s.append(t1 - t0)
    ms = np.asarray(pol.info["solve_ms"])
    return {
        "case": case, "decisions": steps, "solves": int(ms.size),
        "relaxed_solves": int(pol.info["relaxed"]), "fallbacks": int(pol.info["fallbacks"]),
        "solve_ms_median": float(np.median(ms)), "solve_ms_p90": float(np.percentile(ms, 90)),
        "solve_ms_max": float(ms.max()), "ipopt_iterations_median": float(np.median(iters)),
        "decision_ms_median": float(np.median(act_s) * 1e3),
        "env_step_ms_median": float(np.median(env_s) * 1e3),
        "target_solve_ms_median": 100.0, "meets_target": bool(np.median(ms) <= 100.0),
        "machine": {"python": platform.python_version(), "cpu_count": os.cpu_count(),
                    "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                    "loadavg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_tube_rdmpc",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=int, choices=(1, 2), default=1)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error(f"--steps must be >= 1, got {args.steps}")
    res = measure(args.case, args.steps, args.seed)
    text = json.dumps(res, indent=2)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
