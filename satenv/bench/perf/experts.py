"""The ``experts`` section: DAgger expert labels per second, and the experts' fast modes against ipopt.

Labels: each system's expert (:data:`satenv.tasks.SYSTEMS`: the NMPC on servicing, the re-planning
tube-RDMPC on the cluster) flies round-0 episodes of its training task (the expert's own actions,
random starts) cut to ``decisions`` steps, through :class:`satenv.training.labeller.ExpertPool` with
one worker and with two; a label is one agent's action at one decision (the expert's ``act``, as
DAgger calls it). The pools are warmed up first (envs, experts and their solvers built in every
worker), so the rates are the steady state of a run that keeps its pool. Each expert is measured
with its fast mode (:data:`FAST_MODES`, ``solver="rti"``: one QP per decision) and with ipopt
(:data:`REFERENCE_MODE`), in the same run; the machine's load at the time is recorded beside them
(every other process shares the two cores).

Decision times (:func:`decision_times`): ms per agent decision of both modes along the same
closed loop (the system's paper task), medians, and their ratio.

Closed loop (:func:`closed_loop_vs_ipopt`, too long for the section: ``python -m
satenv.bench.perf.experts --out FILE.json``): the fast mode against ipopt on the reproduction's
problems (:data:`CLOSED_LOOP_CASES`), the board's metrics per episode and the 2 % check.
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
                      workers: tuple[int, ...] = (1, 2), options: dict[str, Any] | None = None) -> dict[str, Any]:
    """Labels/s of ``system``'s expert (with ``options``) over ``episodes`` episodes of ``decisions``
    steps, per pool size."""
    from satenv import tasks
    from satenv.training.labeller import ExpertPool, LabelJob

    sys_ = tasks.system(system)
    steps = decisions or DECISIONS.get(system, 20)
    jobs = [LabelJob(sys_.training_task, seed=1000 + e,
                     env_kwargs={"max_steps": steps, "terminate_on_collision": False})
            for e in range(episodes)]
    warm = (LabelJob(sys_.training_task, seed=1, env_kwargs=jobs[0].env_kwargs),)
    out: dict[str, Any] = {"expert": sys_.expert, "options": dict(options or {}), "task": sys_.training_task,
                           "episodes": episodes, "decisions_per_episode": steps, "load_average_at_start": _load()}
    for n in workers:
        with ExpertPool(sys_.expert, options=options, workers=n, warm=warm) as pool:
            rate, labels, wall = _rate(pool, jobs)
        out[f"workers_{n}"] = {"labels_per_s": rate, "labels": labels, "wall_s": wall}
    out["load_average_at_end"] = _load()
    rates = [out[f"workers_{n}"]["labels_per_s"] for n in workers]
    out["parallel_speedup"] = rates[-1] / rates[0]
    return out


def decision_times(controller: str, task: str, decisions: int, seed: int = 0) -> dict[str, Any]:
    """ms per agent decision (median, and mean, of whole ``act`` calls / agents, after the first) of
    ``controller`` in its fast mode and with ipopt over the first ``decisions`` of ``task``, and
    the fast mode's median QP step alone."""
    import numpy as np

    from satenv import tasks
    from satenv.baselines.registry import make_expert as make

    from ._common import act_times

    out: dict[str, Any] = {"task": task, "decisions": decisions, "load_average_at_start": _load()}
    for mode, options in (("ipopt", REFERENCE_MODE), ("fast", FAST_MODES[controller])):
        env = tasks.get(task).make_env()
        policy = make(controller, env, **options)
        act_times(env, policy, 2, seed)                    # builds (compiles) before timing
        times = np.asarray(act_times(env, policy, decisions, seed)[1:]) * 1e3 / len(env.possible_agents)
        out[f"{mode}_ms_per_agent_decision"] = float(np.median(times))
        out[f"{mode}_ms_per_agent_decision_mean"] = float(np.mean(times))
        steps = policy.info.get("qp_ms") or ([] if mode == "ipopt" else None)
        if steps:
            out["fast_qp_ms_median"] = float(np.median(steps))
        env.close()
    out["speedup"] = out["ipopt_ms_per_agent_decision"] / out["fast_ms_per_agent_decision"]
    out["load_average_at_end"] = _load()
    return out


def _load() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


def run(o, log) -> dict[str, Any]:
    """The section (``satenv.bench.perf`` registry entry): both systems' label rates in the fast
    mode and with ipopt, the fast modes' decision times, their targets."""
    scale = min(getattr(o, "scale", 1.0), 1.0)
    out: dict[str, Any] = {}
    targets = []
    for controller, task, decisions in DECISION_CASES:
        row = decision_times(controller, task, max(3, round(decisions * scale)))
        out[f"decisions_{controller}@{task}"] = row
        targets.append({"name": f"{controller} {FAST_MODES[controller]} ms per agent decision ({task})",
                        "value": row["fast_ms_per_agent_decision"], "target": DECISION_TARGETS_MS[controller],
                        "op": "<=", "met": bool(row["fast_ms_per_agent_decision"] <= DECISION_TARGETS_MS[controller])})
        log(f"experts {controller}@{task}: {row['fast_ms_per_agent_decision']:.2f} ms per agent decision fast, "
            f"{row['ipopt_ms_per_agent_decision']:.2f} ipopt "
            f"(x{row['speedup']:.1f}; load {row['load_average_at_start']})")
    for system, goal in LABEL_TARGETS.items():
        expert = _expert(system)
        kw = {"episodes": max(2, round(4 * scale)), "decisions": max(3, round(DECISIONS[system] * scale))}
        row = labels_per_second(system, options=FAST_MODES[expert], **kw)
        ref = labels_per_second(system, options=REFERENCE_MODE, workers=(2,), **kw)
        row["ipopt_workers_2"] = ref["workers_2"]
        best = row["workers_2"]["labels_per_s"]
        row["fast_vs_ipopt"] = best / ref["workers_2"]["labels_per_s"]
        out[system] = row
        targets.append({"name": f"expert labels/s on 2 workers, {system} ({expert}, {FAST_MODES[expert]})",
                        "value": best, "target": goal, "op": ">=", "met": bool(best >= goal)})
        log(f"experts {system}: {row['workers_1']['labels_per_s']:.1f} labels/s on 1 worker, {best:.1f} on 2 "
            f"(x{row['parallel_speedup']:.2f}; ipopt {ref['workers_2']['labels_per_s']:.1f} on 2; "
            f"load {row['load_average_at_start']})")
    out["targets"] = targets
    return out


def _expert(system: str) -> str:
    from satenv import tasks

    return tasks.system(system).expert


FAST_MODES: dict[str, dict[str, Any]] = {"nmpc": {"solver": "rti"}, "tube_rdmpc": {"solver": "rti"},
                                         "replanning_tube_rdmpc": {"solver": "rti"}}
"""The one-QP-per-decision options of each expert / baseline (``solver="rti"``), against ipopt."""
REFERENCE_MODE: dict[str, Any] = {"solver": "ipopt"}
CLOSED_LOOP_CASES: tuple[tuple[str, str, str, int], ...] = (
    # (controller, task, seed split, seeds)
    ("nmpc", "servicing-pereira2022", "test", 1),
    ("nmpc", "servicing-pereira2022-random", "train", 3),
    ("tube_rdmpc", "cluster-case1", "test", 1),
    ("replanning_tube_rdmpc", "cluster-case1-random", "train", 2),
)
"""The reproduction's problems the fast modes are checked on: the paper task (its one scenario)
and the first training seeds of the system's training task (the states DAgger labels)."""
CLOSED_LOOP_TOLERANCE = 0.02
"""The fast mode's closed-loop cost (RMSE, final error, delta-v) within 2 % of ipopt's, and the
same successes."""
DECISION_TARGETS_MS = {"nmpc": 5.0, "tube_rdmpc": 2.0}
"""ms per agent decision of the fast modes (``<=``), medians along the closed loop."""
DECISION_CASES = (("nmpc", "servicing-pereira2022", 60), ("tube_rdmpc", "cluster-case1", 12))
"""(controller, task, decisions) of :func:`decision_times`."""


def closed_loop_episode(controller: str, task: str, seed: int, options: dict[str, Any],
                        max_steps: int | None = None) -> dict[str, Any]:
    """One episode of ``controller`` (a :func:`satenv.baselines.experts.make` name) with ``options`` on
    ``task`` from ``seed``: the board's metrics (:func:`satenv.metrics.summary`) plus the median
    ms per agent solve and the solver counters of the policy's ``info``."""
    import numpy as np

    from satenv import metrics, tasks
    from satenv.baselines.registry import make_expert as make
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


def main(argv: list[str] | None = None) -> int:
    """``python -m satenv.bench.perf.experts --out FILE.json``: :func:`closed_loop_vs_ipopt`."""
    import argparse
    import json
    from pathlib import Path

    parser = argparse.ArgumentParser(prog="python -m satenv.bench.perf.experts", allow_abbrev=False,
                                     description="The experts' fast modes against ipopt in closed loop.")
    parser.add_argument("--out", required=True, help="JSON file of the results (finished episodes are "
                        "kept in it and not flown again)")
    parser.add_argument("--tasks", default=None, help="comma-separated tasks of CLOSED_LOOP_CASES (default: all)")
    args = parser.parse_args(argv)
    path = Path(args.out)
    done = json.loads(path.read_text()).get("episodes", {}) if path.exists() else {}
    chosen = None if args.tasks is None else set(args.tasks.split(","))
    cases = tuple(c for c in CLOSED_LOOP_CASES if chosen is None or c[1] in chosen)

    def save(key: str, row: dict) -> None:
        done[key] = row
        path.write_text(json.dumps({"episodes": done}, indent=1, default=float))

    result = closed_loop_vs_ipopt(cases, cache=_Saving(done, save))
    path.write_text(json.dumps({"episodes": dict(done), "cases": result, "load_average_at_end": _load()},
                               indent=1, default=float))
    for key, row in result.items():
        print(key, {k: v for k, v in row.items() if k != "episodes"})
    return 0


class _Saving(dict):
    """A cache dict that saves every finished episode (a long run resumes where it stopped)."""

    def __init__(self, data: dict, save) -> None:
        super().__init__(data)
        self._save = save

    def __setitem__(self, key: str, value: dict) -> None:
        super().__setitem__(key, value)
        self._save(key, value)


if __name__ == "__main__":
    raise SystemExit(main())
