"""Benchmark the servicing NMPC: median solve time per spacecraft and NLP solver agreement.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_nmpc [--steps 300] [--fatrop-steps 10] [--out FILE.json]``

Runs ``baselines.nmpc.NMPC`` closed loop on ``servicing_v0(preset="pereira2022")`` for
``--steps`` decision steps with ipopt and reports, per spacecraft, the NLP wall time (median,
p90, max), ipopt iterations and statuses, and the one-off build time. Then, on the first
``--fatrop-steps`` states of that run, solves the same NLPs (same parameters, same initial guess)
with fatrop and compares the first input with ipopt's (``max |u_fatrop - u_ipopt|``) and the
statuses, to decide whether fatrop "holds the same solutions" (DESIGN.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._io import write_json


def _stats(ms: np.ndarray) -> dict[str, float]:
    return {"median": float(np.median(ms)), "p90": float(np.percentile(ms, 90)),
            "max": float(ms.max()), "n": int(ms.size)}


def bench_ipopt(steps: int) -> tuple[dict[str, Any], list[np.ndarray]]:
    from baselines.nmpc import NMPC
    from satenv.envs.servicing_v0 import parallel_env

    env = parallel_env(preset="pereira2022")
    t0 = time.perf_counter()
    policy = NMPC(env)
    build = time.perf_counter() - t0
    obs, _ = env.reset(seed=0)
    policy.reset()
    states = []
    for _ in range(steps):
        states.append(env.state().copy())
        obs, *_ = env.step(policy.act(obs))
        if not env.agents:
            break
    m = len(env.possible_agents)
    ms = np.asarray(policy.info["agent_solve_ms"]).reshape(-1, m)
    it = np.asarray(policy.info["iterations"]).reshape(-1, m)
    out = {"build_s": build, "steps": len(states),
           "per_agent_solve_ms": {a: _stats(ms[:, i]) for i, a in enumerate(env.possible_agents)},
           "all_solves_ms": _stats(ms.ravel()),
           "iterations_median": float(np.median(it)), "statuses": dict(policy.info["statuses"]),
           "fallbacks": int(policy.info["fallbacks"]),
           "act_ms": _stats(np.asarray(policy.info["solve_ms"]))}
    return out, states


def compare_fatrop(states: list[np.ndarray]) -> dict[str, Any]:
    """Solve each recorded state's first agent NLP with both solvers from the same guess."""
    from baselines.nmpc import NMPC
    from satenv.envs.servicing_v0 import parallel_env, unpack_global_state

    env = parallel_env(preset="pereira2022")
    res: dict[str, Any] = {"diff_u0_max": [], "ipopt": [], "fatrop": [], "fatrop_ms": [], "ipopt_ms": []}
    try:
        solvers = {"ipopt": NMPC(env), "fatrop": NMPC(env, solver="fatrop")}
    except RuntimeError as exc:          # fatrop plugin missing or refusing the structure
        return {"error": str(exc)}
    for s in states:
        x, goals, _ = unpack_global_state(s, 2)
        u0 = {}
        for name, pol in solvers.items():
            pol.reset()
            others = [np.tile(x[1, :3], (pol.N, 1))]
            u, _ = pol._solve_agent(0, x[0], np.tile(goals[0], (pol.N, 1)), others)
            status = list(pol.info["statuses"])[-1]
            res[name].append(status)
            res[f"{name}_ms"].append(pol.info["agent_solve_ms"][-1])
            u0[name] = u
        res["diff_u0_max"].append(float(np.max(np.abs(u0["fatrop"] - u0["ipopt"]))))
    res["same_solutions"] = bool(max(res["diff_u0_max"]) < 1e-3 and all(
        st in ("Solve_Succeeded", "Solved_To_Acceptable_Level", "success") for st in res["fatrop"]))
    res["fatrop_ms_median"] = float(np.median(res["fatrop_ms"]))
    res["ipopt_ms_median"] = float(np.median(res["ipopt_ms"]))
    return res


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_nmpc", description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--fatrop-steps", type=int, default=10)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    ipopt, states = bench_ipopt(args.steps)
    result = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                          "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                          "loadavg_1min": os.getloadavg()[0]},
              "ipopt": ipopt}
    if args.fatrop_steps > 0:
        result["fatrop_vs_ipopt"] = compare_fatrop(states[: args.fatrop_steps])
    for a, st in ipopt["per_agent_solve_ms"].items():
        print(f"ipopt {a}: median {st['median']:.1f} ms, p90 {st['p90']:.1f} ms, max {st['max']:.1f} ms "
              f"over {st['n']} solves")
    print(f"ipopt iterations median {ipopt['iterations_median']}, statuses {ipopt['statuses']}, "
          f"build {ipopt['build_s']:.2f} s")
    cmp = result.get("fatrop_vs_ipopt")
    if cmp:
        if "error" in cmp:
            print("fatrop:", cmp["error"])
        else:
            print(f"fatrop statuses {cmp['fatrop']}; max |u0 diff| {max(cmp['diff_u0_max']):.3g}; "
                  f"median {cmp['fatrop_ms_median']:.1f} ms vs ipopt {cmp['ipopt_ms_median']:.1f} ms; "
                  f"same solutions: {cmp['same_solutions']}")
    if args.out is not None:
        write_json(args.out, result)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
