"""Cost of the finiteness guard in the PettingZoo step of platoon_v0 (not a pytest module).

    python tests/measure_guard.py

Times (a) 300 paired blocks of 300 steps with the guard's check on and off (alternating, order
swapped every pair; the median of the paired ratios cancels the machine's load drift) and (b) the
check alone on one step's arrays, as a share of the step time.
"""

import time
import timeit

import numpy as np

import satenv

env = satenv.platoon_v0()
acts = {a: np.zeros(3, np.float32) for a in env.possible_agents}
guard = env._finite_step


def run(n: int = 300) -> float:
    env.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(n):
        env.step(acts)
        if not env.agents:
            env.reset(seed=0)
    return (time.perf_counter() - t0) / n


on, off = [], []
for k in range(300):
    for enabled in ((True, False) if k % 2 else (False, True)):
        env._finite_step = guard if enabled else (lambda *a: True)
        (on if enabled else off).append(run())
env._finite_step = guard
on, off = np.array(on), np.array(off)
print(f"step with the check: median {np.median(on) * 1e6:.1f} us (fastest {on.min() * 1e6:.1f}); "
      f"without: median {np.median(off) * 1e6:.1f} us (fastest {off.min() * 1e6:.1f})")
print(f"A/B overhead: median of paired ratios {100 * (np.median(on / off) - 1):.2f} %")
env.reset(seed=0)
obs, res = env.core.observe(), env.core.step(np.zeros((1, env.core.n_agents, 3)))
alone = min(timeit.repeat(lambda: guard(obs, res.info["state"], sum(res.rewards[0].tolist())), number=20000, repeat=9)) / 20000
print(f"the check alone: {alone * 1e6:.2f} us = {100 * alone / np.median(off):.2f} % of the median step, "
      f"{100 * alone / off.min():.2f} % of the fastest")
