"""Running one grid run and the evaluation log (the scoreboard's log format and backends).

Each evaluation is one JSON line of ``LOG`` (key :data:`~satenv.bench.learning.grid.KEY`), written
by the worker that trained the run as soon as it is measured (one ``write`` of the whole line,
then ``fsync``: :class:`satenv.bench.scoreboard.runner.EpisodeLog`); the parent appends whatever a
worker returned that is not in the log yet (a Ray worker on another machine). Reading keeps the
first record of each key and moves torn lines aside (:func:`satenv.bench.scoreboard.runner.read_episodes`),
so a run killed at any point resumes: the runs with every record logged are skipped, the
others train again from the start (evaluations already logged are not written twice).

Each checkpoint is flown on the run's test seeds and on its validation seeds (the record's
``validation`` summary); once training ends, the checkpoint
:func:`~satenv.bench.learning.grid.select_checkpoint` picks on the validation seeds is flown on the
final test seeds (one more record, ``selected_checkpoint`` naming it).
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from satenv.bench.learning.evaluate import evaluate_policy
from satenv.bench.learning.grid import KEY, Run, select_checkpoint
from satenv.bench.scoreboard.runner import EpisodeLog, read_episodes

__all__ = ["done_runs", "logged_keys", "logged_records", "read_log", "run_one", "lost_record"]


def read_log(path: str | Path, repair: bool = False) -> list[dict[str, Any]]:
    """The good records of the log (first occurrence per key)."""
    return read_episodes(path, repair=repair, key=KEY)


def logged_records(path: str | Path) -> dict[tuple[Any, ...], dict[str, Any]]:
    """The log's evaluations (error records left out) by their key."""
    return {tuple(r[k] for k in KEY): r for r in read_log(path) if r.get("error") is None}


def logged_keys(path: str | Path) -> set[tuple[Any, ...]]:
    return set(logged_records(path))


def done_runs(runs: Iterable[Run], path: str | Path) -> set[Run]:
    """The runs whose every record (each checkpoint and the selected one) is in the log."""
    keys = logged_keys(path)
    return {r for r in runs if all(r.key(k) in keys for k in r.records)}


def _base(run: Run) -> dict[str, Any]:
    return {"system": run.system, "task": run.task.name, "rung": run.rung_index, "algorithm": run.algorithm,
            "filter": run.filter, "seed": run.seed, "budget_agent_steps": run.budget}


def lost_record(run: Run, error: str) -> dict[str, Any]:
    """The record of a run whose worker died (checkpoint -1: it does not count as logged)."""
    return {"records": [{**_base(run), "checkpoint": -1, "error": error, "lost": True}]}


def _successes(episodes: list[dict[str, Any]]) -> int:
    return sum(bool(e["success"]) for e in episodes)


def validation_summary(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """What selection reads of a checkpoint's validation episodes (kept in its record)."""
    return {"seeds": [int(e["seed"]) for e in episodes], "success": _successes(episodes),
            "unsafe": sum(bool(e["collisions"] or e["violations"]) for e in episodes)}


def run_one(run: Run) -> dict[str, Any]:
    """Train and evaluate ``run`` (:func:`satenv.bench.learning.trainers.train`); every evaluation is
    appended to ``run.log_path`` when it is measured. Returns ``{"records": [...]}``; a crash is an
    error record (checkpoint -1), not an exception."""
    from satenv.bench.learning.trainers import train

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    path = Path(run.log_path) if run.log_path else None
    log = EpisodeLog(path) if path is not None and path.parent.is_dir() else None
    logged = logged_records(path) if log is not None else {}
    records: list[dict[str, Any]] = []
    if all(run.key(k) in logged for k in run.records):   # done meanwhile (another invocation)
        if log is not None:
            log.close()
        return {"records": records}
    t_start = time.perf_counter()
    validations: list[dict[str, Any]] = []
    policies: list[Any] = []
    last: dict[str, Any] = {}

    def tested(k: int, make_policy) -> dict[str, Any]:
        """Record ``k``'s evaluation on its test seeds (:meth:`Run.seeds`)."""
        t0 = time.perf_counter()
        seeds = run.seeds(k)
        episodes = evaluate_policy(run.task.make_env, make_policy, seeds, filtered=run.filter)
        return {"eval_s": round(time.perf_counter() - t0, 2), "load_avg_1m": round(os.getloadavg()[0], 2),
                "test_seeds": list(seeds), "episodes": episodes, "error": None}

    def emit(rec: dict[str, Any]) -> None:
        records.append(rec)
        if log is not None:
            log.append(rec)

    def checkpoint(k: int, agent_steps: int, wall_s: float, make_policy) -> None:
        last.update(agent_steps=int(agent_steps), wall_s=round(wall_s, 2))
        done = logged.get(run.key(k))
        if run.selects:
            policies.append(make_policy)
            if done is not None and "validation" in done:
                validations.append(done["validation"])
            else:
                seeds = run.validation_seeds()
                validations.append(validation_summary(
                    evaluate_policy(run.task.make_env, make_policy, seeds, filtered=run.filter)))
        if done is not None:
            return
        rec = {**_base(run), "checkpoint": k, "agent_steps": int(agent_steps), "wall_s": round(wall_s, 2),
               **tested(k, make_policy)}
        if run.selects:
            rec["validation"] = validations[-1]
        emit(rec)
        print(f"{run.label()} checkpoint {k}: {agent_steps} steps, success {_successes(rec['episodes'])}/"
              f"{len(rec['episodes'])}"
              + (f" (validation {validations[-1]['success']}/{len(validations[-1]['seeds'])})" if run.selects else "")
              + f", train {wall_s:.0f}s", flush=True)

    def select() -> None:
        k = run.selected_index
        if not run.selects or run.key(k) in logged:
            return
        if len(validations) != len(run.checkpoints):
            raise RuntimeError(f"{run.label()}: {len(validations)} of {len(run.checkpoints)} checkpoints "
                               "reached the selection")
        j = select_checkpoint(validations)
        rec = {**_base(run), "checkpoint": k, "selected_checkpoint": j, **last, **tested(k, policies[j])}
        emit(rec)
        print(f"{run.label()} selected checkpoint {j} (validation {validations[j]['success']}/"
              f"{len(validations[j]['seeds'])}): success {_successes(rec['episodes'])}/{len(rec['episodes'])}",
              flush=True)

    try:
        train(run, checkpoint, select)
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
