"""The ``learning_loop`` section: agent-steps/s of each trainer with its updates, on each training task.

For each training task (:data:`TASKS`: the TPLF platoon's and the cluster's), the lean batched PPO
(:mod:`satenv.training.rl.ppo`) and SB3 PPO (:func:`satenv.bench.perf.learning.end_to_end`) train
with the same network and batch (:data:`SAME`: 64 copies, 32 decisions each per iteration, minibatches
of 4096 agent-steps, 2 epochs, a 64-64 tanh MLP, one torch thread), interleaved (lean, SB3, lean,
SB3; the best of each kept). Each row splits the wall time into ``env`` (the batched env's steps and
resets), ``learner`` (GAE and the gradient updates) and, for the lean learner, ``forward`` (the
policy during collection); ``vs_sb3`` is the lean rate over SB3's from the same run, and the env
stepped alone (zero actions) gives the ceiling. Both learners run once untimed first (torch's
one-time costs). The machine's load is recorded at the start and the end: the two cores are shared.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any

from .learning import _row, end_to_end

TASKS = ("platoon-pereira2023", "cluster-li2022")
"""The systems whose training task (``satenv.tasks.training_task``) the section trains on."""
SAME: dict[str, Any] = {"num_envs": 64, "n_steps": 32, "minibatch_size": 4096, "n_epochs": 2, "net_arch": (64, 64),
                        "torch_threads": 1}
"""The lean learner's settings; SB3 PPO gets the same (:func:`sb3_config`: its fast configuration,
``satenv.bench.perf.learning.FAST_CONFIGS["sb3_ppo"]``)."""
LEAN_VS_SB3_TARGET = 4.0
"""Lean PPO at least 4x SB3 PPO's agent-steps/s, updates included, same network and batch."""
ENV_SHARE_TARGET = 0.30
"""The env at least 30 % of a lean iteration on the platoon."""


def sb3_config(same: dict[str, Any]) -> dict[str, Any]:
    """SB3 PPO's config fields (``satenv.training.config.TrainConfig``) for the lean settings ``same``."""
    return {"num_envs": same["num_envs"], "n_steps": same["n_steps"], "batch_size": same["minibatch_size"],
            "n_epochs": same["n_epochs"], "net_arch": tuple(same["net_arch"]), "torch_threads": same["torch_threads"]}


def lean_row(task: str, agent_steps: int, config: dict[str, Any] | None = None) -> dict[str, Any]:
    """About ``agent_steps`` agent-steps of the lean PPO on ``task`` (whole iterations) with
    ``config`` (:class:`satenv.training.rl.ppo.LeanConfig` fields; default :data:`SAME`): the rate
    and the env / learner / forward shares of the wall time."""
    import torch

    from satenv import tasks
    from satenv.training.rl.ppo import LeanConfig, Run, collect, horizon_gamma, plan, update
    from satenv.vector import SatVectorEnv

    config = SAME if config is None else config
    cfg = LeanConfig(task=task, **config)
    torch.set_num_threads(cfg.torch_threads)
    vec = SatVectorEnv(tasks.get(task).make_env(), cfg.num_envs, autoreset=False)
    run = Run(cfg, vec, horizon_gamma(vec.max_steps, cfg.gamma_k))
    per_iter, _ = plan(cfg, vec.n_agents)
    iterations = max(1, math.ceil(agent_steps / per_iter))
    timers = {"env": 0.0, "forward": 0.0, "update": 0.0}
    t0 = time.perf_counter()
    for _ in range(iterations):
        update(run, collect(run, timers), timers)
    wall = time.perf_counter() - t0
    acc = {"env": timers["env"], "learner": timers["update"], "forward": timers["forward"]}
    return _row(iterations * per_iter, wall, acc,
                {k: list(v) if isinstance(v, tuple) else v for k, v in config.items()})


def env_alone(task: str, num_envs: int, min_time: float = 0.5) -> float:
    """Agent-steps/s of the task's batched env stepped alone with zero actions (resets included)."""
    import numpy as np

    from satenv import tasks
    from satenv.vector import SatVectorEnv

    vec = SatVectorEnv(tasks.get(task).make_env(), num_envs, seed=0)
    vec.reset()
    zero = np.zeros(vec.action_shape)
    n, t0 = 0, time.perf_counter()
    while (wall := time.perf_counter() - t0) < min_time or n < 3:
        vec.step(zero)
        n += 1
    return n * num_envs * vec.n_agents / wall


def learning_loop(agent_steps: int = 65536, repeats: int = 2, systems: tuple[str, ...] = TASKS,
                  same: dict[str, Any] = SAME, log: Any = print) -> dict[str, Any]:
    """The section: per training task, lean PPO and SB3 PPO rows (best of ``repeats``
    interleaved runs of about ``agent_steps`` each, both with the settings ``same``), ``vs_sb3``
    and the targets."""
    from satenv import tasks

    sb3 = sb3_config(same)
    lean_config = {k: list(v) if isinstance(v, tuple) else v for k, v in same.items()}
    out: dict[str, Any] = {"same_config": {"lean_ppo": lean_config,
                                           "sb3_ppo": {**sb3, "net_arch": list(sb3["net_arch"])}},
                           "load_average_at_start": _load(), "tasks": {}, "targets": [],
                           "benchmarl_mappo": {"skipped": "its runner trains on an env id's defaults, not on "
                                                          "a task; measured by the learning section"}}
    first = tasks.training_task(systems[0]).name
    lean_row(first, 1, same)                             # warm-up: torch's one-time costs
    end_to_end("sb3_ppo", first, 64, sb3)
    for system in systems:
        task = tasks.training_task(system).name
        lean, ref = [], []
        for _ in range(repeats):
            lean.append(lean_row(task, agent_steps, same))
            ref.append(end_to_end("sb3_ppo", task, agent_steps, sb3))
        best = {"lean_ppo": max(lean, key=_rate), "sb3_ppo": max(ref, key=_rate)}
        row: dict[str, Any] = {"system": system, **best,
                               "env_alone_agent_steps_per_s": env_alone(task, same["num_envs"])}
        if "skipped" not in best["sb3_ppo"]:
            row["vs_sb3"] = _rate(best["lean_ppo"]) / _rate(best["sb3_ppo"])
            out["targets"].append({"name": f"(g) lean PPO / SB3 PPO agent-steps/s, {task}", "value": row["vs_sb3"],
                                   "target": LEAN_VS_SB3_TARGET, "op": ">=",
                                   "met": bool(row["vs_sb3"] >= LEAN_VS_SB3_TARGET)})
        if system == "platoon-pereira2023":
            share = best["lean_ppo"]["env_share"]
            out["targets"].append({"name": f"(g) env share of a lean PPO iteration, {task}", "value": share,
                                   "target": ENV_SHARE_TARGET, "op": ">=", "met": bool(share >= ENV_SHARE_TARGET)})
        out["tasks"][task] = row
        log(f"(g) {task}: lean {_rate(best['lean_ppo']):.3g} agent-steps/s (env "
            f"{100 * best['lean_ppo']['env_share']:.0f} %), SB3 {_rate(best['sb3_ppo']):.3g} (env "
            f"{100 * best['sb3_ppo'].get('env_share', math.nan):.0f} %): x{row.get('vs_sb3', math.nan):.2f}; "
            f"env alone {row['env_alone_agent_steps_per_s']:.3g}")
    out["load_average_at_end"] = _load()
    return out


def _rate(row: dict[str, Any]) -> float:
    return row.get("agent_steps_per_s", 0.0)


def _load() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


def run(o: Any, log: Any) -> dict[str, Any]:
    """The section's entry of ``satenv.bench.perf.REGISTRY`` (``--solver-scale`` shrinks the runs)."""
    return learning_loop(agent_steps=max(64, int(65536 * o.scale)), repeats=2 if o.scale >= 1 else 1, log=log)
