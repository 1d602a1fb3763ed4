"""Running one grid run and the evaluation log (the scoreboard's log format and backends).

Each evaluation is one JSON line of ``LOG`` (key :data:`~satenv.bench.learning.grid.KEY`), written
by the worker that trained the run as soon as it is measured (one ``write`` of the whole line,
then ``fsync``: :class:`satenv.bench.scoreboard.runner.EpisodeLog`); the parent appends whatever a
worker returned that is not in the log yet (a Ray worker on another machine). Reading keeps the
first record of each key and moves torn lines aside (:func:`satenv.bench.scoreboard.runner.read_episodes`),
so a run killed at any point resumes: the runs with every checkpoint logged are skipped, the
others train again from the start (evaluations already logged are not written twice).
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from satenv.bench.learning.evaluate import evaluate_policy
from satenv.bench.learning.grid import KEY, Run
from satenv.bench.scoreboard.runner import EpisodeLog, read_episodes

__all__ = ["done_runs", "logged_keys", "read_log", "run_one", "lost_record"]


def read_log(path: str | Path, repair: bool = False) -> list[dict[str, Any]]:
    """The good records of the log (first occurrence per key)."""
    return read_episodes(path, repair=repair, key=KEY)


def logged_keys(path: str | Path) -> set[tuple[Any, ...]]:
    return {tuple(r[k] for k in KEY) for r in read_log(path) if r.get("error") is None}


def done_runs(runs: Iterable[Run], path: str | Path) -> set[Run]:
    """The runs whose every checkpoint is in the log."""
    keys = logged_keys(path)
    return {r for r in runs if all(r.key(k) in keys for k in range(len(r.checkpoints)))}


def _base(run: Run) -> dict[str, Any]:
    return {"system": run.system, "task": run.task.name, "rung": run.rung_index, "algorithm": run.algorithm,
            "filter": run.filter, "seed": run.seed, "budget_agent_steps": run.budget}


def lost_record(run: Run, error: str) -> dict[str, Any]:
    """The record of a run whose worker died (checkpoint -1: it does not count as logged)."""
    return {"records": [{**_base(run), "checkpoint": -1, "error": error, "lost": True}]}


def run_one(run: Run) -> dict[str, Any]:
    """Train and evaluate ``run`` (:func:`satenv.bench.learning.trainers.train`); every evaluation is
    appended to ``run.log_path`` when it is measured. Returns ``{"records": [...]}``; a crash is an
    error record (checkpoint -1), not an exception."""
    from satenv.bench.learning.trainers import train

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    path = Path(run.log_path) if run.log_path else None
    log = EpisodeLog(path) if path is not None and path.parent.is_dir() else None
    skip = logged_keys(path) if log is not None else set()
    records: list[dict[str, Any]] = []
    if all(run.key(k) in skip for k in range(len(run.checkpoints))):   # done meanwhile (another invocation)
        if log is not None:
            log.close()
        return {"records": records}
    t_start = time.perf_counter()

    def checkpoint(k: int, agent_steps: int, wall_s: float, make_policy) -> None:
        if run.key(k) in skip:
            return
        t0 = time.perf_counter()
        seeds = run.seeds(k)
        episodes = evaluate_policy(run.task.make_env, make_policy, seeds, filtered=run.filter)
        rec = {**_base(run), "checkpoint": k, "agent_steps": int(agent_steps), "wall_s": round(wall_s, 2),
               "eval_s": round(time.perf_counter() - t0, 2), "load_avg_1m": round(os.getloadavg()[0], 2),
               "test_seeds": list(seeds), "episodes": episodes,
               "error": None}
        records.append(rec)
        if log is not None:
            log.append(rec)
        print(f"{run.label()} checkpoint {k}: {agent_steps} steps, success "
              f"{sum(bool(e['success']) for e in episodes)}/{len(episodes)}, train {wall_s:.0f}s", flush=True)

    try:
        train(run, checkpoint)
    except Exception as exc:   # a run that crashes is a result of the grid, not a crash of it
        records.append({**_base(run), "checkpoint": -1, "error": f"{type(exc).__name__}: {exc}",
                        "traceback": traceback.format_exc(limit=8),
                        "wall_s": round(time.perf_counter() - t_start, 2)})
        if log is not None:
            log.append(records[-1])
    finally:
        if log is not None:
            log.close()
    return {"records": records}
