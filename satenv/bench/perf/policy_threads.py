"""The ``policy_threads`` section: a loaded policy's decision time on a busy machine.

``satenv.training.load`` runs each forward pass on one torch thread (``satenv.training.policy.INFERENCE_THREADS``,
set around the pass and restored after it). Measured in one run, with busy-loop processes on
every core (a busy machine): the decision time (``LearnedPolicy.act`` on ``formation_v0``'s
observations) with torch's default thread count and no guard, with one thread set globally (the
peer), and with the guard while the caller keeps its default count. Target: the guard within
:data:`GUARD_VS_ONE_THREAD` of the one-thread time.

Before that, on the quiet machine: every shipped network's decision time (:func:`network_times`:
``satenv.training.load(folder, env=env, shielded=False).act`` for all agents of its evaluation env, the
safety filter excluded, one thread), per agent, beside the same env's step per agent in the same
run (the peer: ``ratio_to_step``). Target: at most :data:`NETWORK_MS_PER_AGENT_LIMIT` ms per agent.

    python -m satenv.bench.perf --sections policy_threads --out perf_policy_threads.json
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from typing import Any

GUARD_VS_ONE_THREAD = 2.0
"""The guarded decision time may be at most this multiple of the one-thread time."""
POLICY = "formation_position_dagger"
"""The shipped policy measured (an MLP on formation_v0's observations)."""
NETWORK_MS_PER_AGENT_LIMIT = 0.2
"""A shipped network's decision (every agent's action, the safety filter excluded) [ms per agent]."""


def _spin(stop: Any) -> None:
    while not stop.is_set():
        pass


def _ms_per_decision(policy: Any, obs: dict, seconds: float) -> float:
    """Best of 3 blocks of at least ``seconds`` each: ms per ``act`` call."""
    best = float("inf")
    for _ in range(3):
        n, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds or n < 20:
            policy.act(obs)
            n += 1
        best = min(best, (time.perf_counter() - start) / n * 1e3)
    return best


def _ms_per_step(env: Any, actions: dict, seconds: float) -> float:
    """Best of 3 blocks of at least ``seconds`` each: ms per ``env.step(actions)`` (resets included
    when an episode ends)."""
    best = float("inf")
    for _ in range(3):
        n, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds or n < 20:
            if not env.agents:
                env.reset()
            env.step(actions)
            n += 1
        best = min(best, (time.perf_counter() - start) / n * 1e3)
    return best


def network_times(seconds: float = 0.3, log=print) -> list[dict[str, Any]]:
    """Every shipped folder's network: ms per agent of one decision for all agents of the folder's
    evaluation env (``env.json``), its env's step per agent, their ratio (module docstring)."""
    import json

    import numpy as np

    import satenv
    from satenv import training
    rows = []
    for folder in sorted(p for p in training.POLICIES_DIR.iterdir() if (p / "env.json").is_file()):
        meta = json.loads((folder / "env.json").read_text())
        env = satenv.make(meta["env_id"], **meta["eval_env_kwargs"])
        network = training.load(folder, env=env, shielded=False)
        obs, _ = env.reset(seed=0)
        agents = len(env.possible_agents)
        ms = _ms_per_decision(network, obs, seconds) / agents
        zero = {a: np.zeros(env.action_space(a).shape, dtype=np.float32) for a in env.possible_agents}
        step = _ms_per_step(env, zero, seconds) / agents
        log(f"network {folder.name} ({agents} agents): {ms:.4f} ms per agent decision, env step "
            f"{step:.4f} ms per agent (x{ms / step:.2f})")
        rows.append({"policy": folder.name, "env_id": meta["env_id"], "agents": agents,
                     "ships_with_filter": meta.get("safety_filter") is not None, "ms_per_agent": ms,
                     "step_ms_per_agent": step, "ratio_to_step": ms / step,
                     "target_ms_per_agent": NETWORK_MS_PER_AGENT_LIMIT, "met": ms <= NETWORK_MS_PER_AGENT_LIMIT})
    return rows


def run(options: Any = None, log=print, seconds: float = 0.5) -> dict[str, Any]:
    """The shipped networks' decision times, then the three decision times on a busy machine
    (module docstring), the busy processes' count and the targets."""
    import torch

    import satenv
    from satenv import training
    from satenv.training import policy as tp

    networks = network_times(max(0.1, seconds * getattr(options, "scale", 1.0)), log)

    env = satenv.make("formation_v0", randomize=True)
    policy = training.load(training.POLICIES_DIR / POLICY, env=env)
    obs, _ = env.reset(seed=0)
    before = torch.get_num_threads()
    busy = os.cpu_count() or 1
    default = max(2, busy)     # torch's own default is the core count (this run's harness sets 1)
    stop = mp.Event()
    spinners = [mp.Process(target=_spin, args=(stop,), daemon=True) for _ in range(busy)]
    for p in spinners:
        p.start()
    try:
        torch.set_num_threads(default)
        tp.INFERENCE_THREADS = default                       # no guard: torch's default count
        unguarded = _ms_per_decision(policy, obs, seconds)
        tp.INFERENCE_THREADS = 1
        torch.set_num_threads(1)                             # the peer: one thread, set globally
        one = _ms_per_decision(policy, obs, seconds)
        torch.set_num_threads(default)                       # the guard, the caller at its default
        guarded = _ms_per_decision(policy, obs, seconds)
    finally:
        stop.set()
        for p in spinners:
            p.join(timeout=5)
        tp.INFERENCE_THREADS = 1
        torch.set_num_threads(before)
    ratio = guarded / one
    log(f"policy decision on a busy machine ({busy} busy processes, torch default {default} threads): "
        f"default {unguarded:.3f} ms, one thread {one:.3f} ms, guard {guarded:.3f} ms (x{ratio:.2f})")
    return {"policy": POLICY, "busy_processes": busy, "torch_default_threads": default,
            "ms_default_threads": unguarded, "ms_one_thread": one, "ms_guard": guarded,
            "guard_vs_one_thread": ratio, "networks": networks,
            "targets": [{"name": "policy decision after satenv.training.load on a busy machine: guard / one thread",
                         "value": ratio, "target": GUARD_VS_ONE_THREAD, "op": "<=",
                         "met": ratio <= GUARD_VS_ONE_THREAD},
                        *({"name": f"network {r['policy']}: ms per agent decision (filter excluded)",
                           "value": r["ms_per_agent"], "target": NETWORK_MS_PER_AGENT_LIMIT, "op": "<=",
                           "met": r["met"]} for r in networks)]}
