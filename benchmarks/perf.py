"""Speed benchmark: agent-steps per second of satenv's batched dynamics.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.perf --out perf.json``

Measures ``RelativeModel.step`` for ``"cw"`` and ``"j2"`` at several batch sizes (4 agents per env
copy) and, as the machine's limit, the time to stream the same state and action bytes through
memory (a numpy copy); writes the figures and the ratios satenv/limit as JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time

import numpy as np

from satenv.dynamics import R_EARTH, Orbit, RelativeModel

AGENTS = 4


def _rate(fn, agent_steps: int, min_time: float = 0.2) -> float:
    """Best-of-3 agent-steps per second of ``fn`` (each call = ``agent_steps`` agent-steps)."""
    fn()
    best = 0.0
    for _ in range(3):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < min_time or calls < 3:
            fn()
            calls += 1
        best = max(best, calls * agent_steps / elapsed)
    return best


def batched_dynamics(model: str, batch: int, dt: float = 0.1) -> dict:
    """Agent-steps/s of one batched step of ``batch`` env copies x 4 agents, and of a memory copy."""
    orbit = Orbit.circular(R_EARTH + 500e3, i=math.radians(51.6))
    prop = RelativeModel(model, orbit, dt)
    rng = np.random.default_rng(0)
    state = {"x": rng.normal(size=(batch, AGENTS, 6)) * 100.0,
             "chief": np.broadcast_to(orbit.rv, (batch, 6)).copy()}
    u = rng.normal(size=(batch, AGENTS, 3)) * 1e-3

    def step() -> None:
        state["x"], state["chief"] = prop.step(state["x"], u, state["chief"])

    src = np.concatenate([state["x"].ravel(), u.ravel(), state["chief"].ravel()])
    dst = np.empty_like(src)
    sat = _rate(step, batch * AGENTS)
    limit = _rate(lambda: np.copyto(dst, src), batch * AGENTS)
    return {"model": model, "batch": batch, "agents": batch * AGENTS,
            "agent_steps_per_s": sat, "memory_limit_agent_steps_per_s": limit,
            "ratio_to_limit": sat / limit}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="perf.json", help="output JSON file")
    parser.add_argument("--batches", default="1,16,256,1024,4096", help="comma-separated batch sizes")
    args = parser.parse_args(argv)
    try:
        batches = [int(b) for b in args.batches.split(",")]
    except ValueError:
        parser.error(f"--batches must be comma-separated integers, got {args.batches!r}")
    rows = []
    for model in ("cw", "j2"):
        for batch in batches:
            row = batched_dynamics(model, batch)
            rows.append(row)
            print(f"{model:>4} batch {batch:>5}: {row['agent_steps_per_s']:.3g} agent-steps/s "
                  f"({100 * row['ratio_to_limit']:.1f} % of memory copy)")
    result = {"machine": {"platform": platform.platform(), "python": platform.python_version(),
                          "processor": platform.processor()},
              "batched": rows}
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
