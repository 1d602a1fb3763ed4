"""The ``experts`` section: DAgger expert labels per second, one process against a pool of two.

Each system's expert (:data:`satenv.tasks.SYSTEMS`: the NMPC on servicing, the re-planning
tube-RDMPC on the cluster) flies round-0 episodes of its training task (the expert's own actions,
random starts) cut to ``decisions`` steps, through :class:`satenv.training.labeller.ExpertPool` with one
worker and with two; a label is one agent's action at one decision. The pools are warmed up first
(envs, experts and their solvers built in every worker), so the rates are the steady state of a
run that keeps its pool. Both rates come from the same run; the machine's load at the time is
recorded beside them (every other process shares the two cores).
"""

from __future__ import annotations

import os
import time
from typing import Any

LABEL_TARGETS: dict[str, float] = {"servicing-pereira2022": 100.0, "cluster-li2022": 50.0}
"""DAgger expert labels per second on two cores (``>=``)."""

DECISIONS = {"servicing-pereira2022": 40, "cluster-li2022": 12}
"""Decisions per labelled episode (the episodes' first decisions: the servicing ones include the
first waypoint's cold arcs, the hardest NLPs)."""


def _rate(pool, jobs) -> tuple[float, int, float]:
    start = time.perf_counter()
    out = pool.label(jobs)
    wall = time.perf_counter() - start
    labels = sum(len(rows["act"]) for rows, _ in out)
    return labels / wall, labels, wall


def labels_per_second(system: str, episodes: int = 4, decisions: int | None = None,
                      workers: tuple[int, ...] = (1, 2)) -> dict[str, Any]:
    """Labels/s of ``system``'s expert over ``episodes`` episodes of ``decisions`` steps, per pool size."""
    from satenv import tasks
    from satenv.training.labeller import ExpertPool, LabelJob

    sys_ = tasks.system(system)
    steps = decisions or DECISIONS.get(system, 20)
    jobs = [LabelJob(sys_.training_task, seed=1000 + e, env_kwargs={"max_steps": steps, "terminate_on_collision": False})
            for e in range(episodes)]
    warm = (LabelJob(sys_.training_task, seed=1, env_kwargs=jobs[0].env_kwargs),)
    out: dict[str, Any] = {"expert": sys_.expert, "task": sys_.training_task, "episodes": episodes,
                           "decisions_per_episode": steps, "load_average_at_start": _load()}
    for n in workers:
        with ExpertPool(sys_.expert, workers=n, warm=warm) as pool:
            rate, labels, wall = _rate(pool, jobs)
        out[f"workers_{n}"] = {"labels_per_s": rate, "labels": labels, "wall_s": wall}
    out["load_average_at_end"] = _load()
    rates = [out[f"workers_{n}"]["labels_per_s"] for n in workers]
    out["parallel_speedup"] = rates[-1] / rates[0]
    return out


def _load() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


def run(o, log) -> dict[str, Any]:
    """The section (``satenv.bench.perf`` registry entry): both systems, their targets."""
    scale = getattr(o, "scale", 1.0)
    out: dict[str, Any] = {}
    targets = []
    for system, goal in LABEL_TARGETS.items():
        row = labels_per_second(system, episodes=max(2, round(4 * min(scale, 1.0))),
                                decisions=max(3, round(DECISIONS[system] * min(scale, 1.0))))
        out[system] = row
        best = row["workers_2"]["labels_per_s"]
        targets.append({"name": f"expert labels/s on 2 workers, {system} ({row['expert']})", "value": best,
                        "target": goal, "op": ">=", "met": bool(best >= goal)})
        log(f"experts {system}: {row['workers_1']['labels_per_s']:.1f} labels/s on 1 worker, {best:.1f} on 2 "
            f"(x{row['parallel_speedup']:.2f}; load {row['load_average_at_start']})")
    out["targets"] = targets
    return out
