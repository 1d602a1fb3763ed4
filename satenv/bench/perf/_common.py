"""Timing helpers shared by the sections of :mod:`satenv.bench.perf` (imports no section)."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from satenv.dynamics import R_EARTH, Orbit

AGENTS = 4
"""Agents per copy of the platoon measurements (``platoon_v0``'s default preset)."""


def _rate(fn: Callable[[], Any], agent_steps: int, min_time: float = 0.2, repeats: int = 3) -> float:
    """Best-of-``repeats`` agent-steps per second of ``fn`` (each call = ``agent_steps`` agent-steps)."""
    fn()
    best = 0.0
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < min_time or calls < 3:
            fn()
            calls += 1
        best = max(best, calls * agent_steps / elapsed)
    return best


def _orbit() -> Orbit:
    return Orbit.circular(R_EARTH + 500e3, i=math.radians(51.6))


class PettingZooLoop:
    """Times a PettingZoo parallel env stepped with uniform random actions (resets included)."""

    def __init__(self, env, low: float, high: float, seed: int = 0) -> None:
        self.env, self.low, self.high = env, low, high
        self.rng = np.random.default_rng(seed)
        self.agents = list(env.possible_agents)
        self.dim = env.action_space(self.agents[0]).shape[0]
        env.reset(seed=seed)
        self.best = 0.0
        self._chunk()

    def _chunk(self) -> int:
        env, n = self.env, 0
        for _ in range(50):
            if not env.agents:
                env.reset()
            live = list(env.agents)
            acts = self.rng.uniform(self.low, self.high, size=(len(live), self.dim)).astype(np.float32)
            env.step({a: acts[i] for i, a in enumerate(live)})
            n += len(live)
        return n

    def measure(self, min_time: float) -> float:
        """One timing repeat; keeps the best agent-steps/s seen."""
        steps, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < min_time:
            steps += self._chunk()
        self.best = max(self.best, steps / elapsed)
        return self.best

    def result(self) -> dict:
        return {"agents": len(self.agents), "agent_steps_per_s": self.best,
                "us_per_env_step": 1e6 * len(self.agents) / self.best}


def act_times(env, policy, decisions: int, seed: int = 0) -> list[float]:
    """Wall time [s] of each ``policy.act`` over the first ``decisions`` of one episode from
    ``reset(seed)`` (fewer if it ends)."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    times = []
    for _ in range(decisions):
        t0 = time.perf_counter()
        act = policy.act(obs)
        times.append(time.perf_counter() - t0)
        obs, *_ = env.step(act)
        if not env.agents:
            break
    return times


def _best_call_s(fn: Callable[[], Any], number: int = 2000, repeats: int = 7) -> float:
    import timeit

    return min(timeit.repeat(fn, number=number, repeat=repeats)) / number


def _machine() -> dict:
    from satenv.bench.scoreboard.report import machine

    return {**machine(), "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
            "load_average_at_start": _loadavg()}


def _loadavg() -> list[float] | None:
    """1/5/15-minute load averages (a shared machine slows every figure down alike)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None
