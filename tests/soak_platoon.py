"""Soak the PettingZoo ``platoon_v0`` env: many steps, no NaN, flat memory (not a pytest module).

    nice python tests/soak_platoon.py [--steps 1000000] [--seed 0] [--out soak.json]

Steps one env with uniform random actions (resets included) and checks every observation and
reward for finiteness itself (besides the env's own guard). Memory is sampled every
``--every`` steps: the resident set (``/proc/self/statm``; peak: ``resource.getrusage``) and the
Python heap with ``--tracemalloc`` (started after a warm-up so only growth during the soak counts;
it slows the step several times, so it is off by default). Exit status 1 when a non-finite value
appears or the memory (heap if traced, else resident set) grows by more than ``--max-growth``
bytes between the first and the last sample.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import tracemalloc

import numpy as np

import satenv


def rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--every", type=int, default=100_000, help="memory sample period (steps)")
    ap.add_argument("--max-growth", type=int, default=1 << 20, help="allowed memory growth (bytes)")
    ap.add_argument("--tracemalloc", action="store_true", help="trace the Python heap (slow)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    env = satenv.platoon_v0()
    rng = np.random.default_rng(args.seed)
    agents = env.possible_agents
    obs, _ = env.reset(seed=args.seed)
    block = rng.uniform(-1, 1, (4096, len(agents), 3)).astype(np.float32)
    for k in range(2000):                                # warm-up (caches, lazy imports)
        obs, *_ = env.step(dict(zip(agents, block[k % 4096], strict=True)))
        if not env.agents:
            env.reset()
    if args.tracemalloc:
        tracemalloc.start()
    samples, nonfinite, episodes = [], 0, 0
    t0 = time.perf_counter()
    for k in range(args.steps):
        if k % 4096 == 0:
            block = rng.uniform(-1, 1, block.shape).astype(np.float32)
        obs, rew, *_ = env.step(dict(zip(agents, block[k % 4096], strict=True)))
        if not (np.isfinite(np.stack(list(obs.values()))).all() and np.isfinite(list(rew.values())).all()):
            nonfinite += 1
        if not env.agents:
            episodes += 1
            env.reset()
        if k % args.every == 0 or k == args.steps - 1:
            heap = tracemalloc.get_traced_memory()[0] if args.tracemalloc else 0
            samples.append({"step": k, "rss": rss_bytes(), "heap": heap,
                            "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss})
            print(f"step {k:>9}: rss {samples[-1]['rss'] / 2**20:.1f} MiB, heap {heap / 1024:.1f} KiB, "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
    seconds = time.perf_counter() - t0
    key = "heap" if args.tracemalloc else "rss"
    growth = samples[-1][key] - samples[0][key]
    result = {"steps": args.steps, "episodes": episodes, "nonfinite_steps": nonfinite, "seconds": seconds,
              "us_per_step": 1e6 * seconds / args.steps, f"{key}_growth_bytes_checked": growth,
              "rss_growth_bytes": samples[-1]["rss"] - samples[0]["rss"], "samples": samples,
              "ok": nonfinite == 0 and growth <= args.max_growth}
    print(f"{args.steps} steps ({episodes} episodes) in {seconds:.0f} s: {nonfinite} non-finite steps, "
          f"{key} growth {growth} B, rss growth {result['rss_growth_bytes'] / 2**20:.2f} MiB -> "
          f"{'OK' if result['ok'] else 'FAIL'}")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=1)
    return result


if __name__ == "__main__":
    sys.exit(0 if main(sys.argv[1:])["ok"] else 1)
