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

LABEL_TARGETS: dict[str, float] = {"servicing-pereira2022": 100.0, "cluster-li2022": 200.0}
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


FAST_MODES: dict[str, dict[str, Any]] = {"nmpc": {"solver": "rti"}, "tube_rdmpc": {"solver": "rti"},
                                         "replanning_tube_rdmpc": {"solver": "rti"}}
"""The one-QP-per-decision options of each expert / baseline (``solver="rti"``), against ipopt."""
REFERENCE_MODE: dict[str, Any] = {"solver": "ipopt"}
CLOSED_LOOP_CASES: tuple[tuple[str, str, str, int], ...] = (
    # (controller, task, seed split, seeds)
    ("nmpc", "servicing-pereira2022", "test", 1),
    ("nmpc", "servicing-pereira2022-random", "train", 3),
    ("tube_rdmpc", "cluster-case1", "test", 1),
    ("replanning_tube_rdmpc", "cluster-case1-random", "train", 3),
)
"""The reproduction's problems the fast modes are checked on: the paper task (its one scenario)
and the first training seeds of the system's training task (the states DAgger labels)."""
CLOSED_LOOP_TOLERANCE = 0.02
"""The fast mode's closed-loop cost (RMSE, final error, delta-v) within 2 % of ipopt's, and the
same successes."""
DECISION_TARGETS_MS = {"nmpc": 5.0, "tube_rdmpc": 2.0}
"""ms per agent decision of the fast modes (``<=``), medians along the closed loop."""


def closed_loop_episode(controller: str, task: str, seed: int, options: dict[str, Any],
                        max_steps: int | None = None) -> dict[str, Any]:
    """One episode of ``controller`` (a :func:`satenv.baselines.experts.make` name) with ``options`` on
    ``task`` from ``seed``: the board's metrics (:func:`satenv.metrics.summary`) plus the median
    ms per agent solve and the solver counters of the policy's ``info``."""
    import numpy as np

    from satenv import metrics, tasks
    from satenv.baselines.experts import make
    from satenv.rollout import rollout

    env = tasks.get(task).make_env()
    policy = make(controller, env, **options)
    traj = rollout(env, policy, seed=seed, max_steps=max_steps)
    row = {k: v for k, v in metrics.summary(traj).items() if k != "terminated"}
    info = policy.info
    solves = info.get("agent_solve_ms", info.get("solve_ms", []))
    row["solve_ms_median"] = float(np.median(solves)) if len(solves) else None
    row["act_ms_per_agent_median"] = float(np.median(traj.compute_time)) * 1e3 / len(env.possible_agents)
    for key in ("rti_steps", "qp_steps", "rti_fallbacks", "nlp_solves", "relaxed", "solver_failures"):
        if key in info:
            row[key] = int(info[key])
    env.close()
    return row


def closed_loop_vs_ipopt(cases=CLOSED_LOOP_CASES, max_steps: int | None = None, cache: dict | None = None,
                         log=print) -> dict[str, Any]:
    """Every case of :data:`CLOSED_LOOP_CASES` flown with ipopt and with the fast mode: each
    episode's metrics, and per case whether the fast mode keeps the successes and its RMSE,
    final error and delta-v within :data:`CLOSED_LOOP_TOLERANCE` of ipopt's (means over seeds).
    ``cache`` (a dict, e.g. loaded from JSON) holds finished episodes by key and is filled in."""
    from satenv import tasks

    cache = {} if cache is None else cache
    out: dict[str, Any] = {}
    for controller, task, split, n in cases:
        rows: dict[str, list] = {"ipopt": [], "fast": []}
        for seed in tasks.get(task).seeds(split, n):
            for mode, options in (("ipopt", REFERENCE_MODE), ("fast", FAST_MODES[controller])):
                key = f"{controller}|{task}|{seed}|{mode}|{max_steps}"
                if key not in cache:
                    cache[key] = closed_loop_episode(controller, task, seed, options, max_steps)
                    log(f"closed loop {key}: {cache[key]}")
                rows[mode].append(cache[key])
        out[f"{controller}@{task}"] = _compare(rows)
    return out


def _compare(rows: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    import numpy as np

    res: dict[str, Any] = {"episodes": rows, "successes": {m: int(sum(r["success"] for r in rows[m])) for m in rows}}
    within = res["successes"]["fast"] >= res["successes"]["ipopt"]
    for metric in ("rmse", "final_error_m", "delta_v"):
        ref, fast = (float(np.mean([r[metric] for r in rows[m]])) for m in ("ipopt", "fast"))
        res[f"{metric}_ratio"] = fast / ref if ref > 0 else (1.0 if fast == 0 else float("inf"))
        within = within and res[f"{metric}_ratio"] <= 1.0 + CLOSED_LOOP_TOLERANCE
    res["within_tolerance"] = bool(within)
    return res
