"""One episode and the episode log.

Every episode is a :class:`Job`, keyed ``(task, policy, seed)`` (the log's fields ``scenario``,
``policy``, ``seed``: :data:`~satenv.bench.scoreboard.report.KEY`): the env is reset with ``seed``
and the policy with ``reset(seed)``; its record (:func:`satenv.scoring.episode_record` plus
``env`` and ``wall_s``) goes as one JSON line to ``OUT/episodes.jsonl``, appended and flushed
(``fsync``) as soon as the episode finishes. Reading the log back keeps every good line (older
records through :func:`satenv.scoring.upgrade_record`); a torn or corrupt line is moved to
``episodes.jsonl.corrupt`` with a warning.
"""

from __future__ import annotations

import json
import os
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from satenv.bench.scoreboard.report import KEY, jsonable
from satenv.bench.scoreboard.specs import PolicySpec, TaskSpec
from satenv.scoring import episode_record, upgrade_record

__all__ = ["EPISODES_FILE", "EpisodeLog", "Job", "ScoreboardWarning", "error_record", "read_episodes",
           "run_episode"]

EPISODES_FILE = "episodes.jsonl"
CORRUPT_SUFFIX = ".corrupt"


class ScoreboardWarning(UserWarning):
    """Something the board recovered from (e.g. a corrupt log line moved aside)."""


@dataclass(frozen=True)
class Job:
    """One episode to run: ``rollout(task.make(), policy.make(env), seed=seed)``."""

    task: TaskSpec
    policy: PolicySpec
    seed: int
    trajectory_path: str | None = None  # save the Trajectory (.npz) here (example episodes)

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.task.name, self.policy.name, self.seed)


def _base_record(job: Job) -> dict[str, Any]:
    return {"scenario": job.task.name, "policy": job.policy.name, "seed": int(job.seed),
            "scenario_fp": job.task.fingerprint(), "policy_fp": job.policy.fingerprint()}


def error_record(job: Job, error: str, wall_s: float = 0.0) -> dict[str, Any]:
    """The record of an episode that failed outside the episode itself (e.g. its worker died)."""
    return jsonable({**_base_record(job), "error": error, "success": False, "wall_s": wall_s})


def _play(job: Job, env, record: dict[str, Any]) -> None:
    from satenv.rollout import rollout

    record["env"] = env.metadata.get("name", type(env).__name__)
    traj = rollout(env, job.policy.make(env), seed=int(job.seed))
    record.update(episode_record(traj, job.seed, len(env.possible_agents)))
    record["error"] = None
    if job.trajectory_path is not None:
        Path(job.trajectory_path).parent.mkdir(parents=True, exist_ok=True)
        traj.save(job.trajectory_path)


def run_episode(job: Job) -> dict[str, Any]:
    """Run one episode and return its JSON record (an exception in it is recorded, not raised)."""
    start = time.perf_counter()
    record = _base_record(job)
    env = None
    try:
        env = job.task.make()
        _play(job, env, record)
    except Exception as exc:  # a crashing controller is a result of the board, not a crash of it
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc(limit=6)
        record["success"] = False
    finally:
        if env is not None:
            env.close()
    record["wall_s"] = time.perf_counter() - start
    return jsonable(record)


# ----------------------------------------------------------------------------------------------
# The episode log: one JSON line per finished episode.
# ----------------------------------------------------------------------------------------------
def _parse(line: bytes, key: tuple[str, ...] = KEY) -> dict[str, Any] | None:
    """The record on one log line, or ``None`` if the line is not a whole record with ``key``."""
    try:
        rec = json.loads(line)
        tuple(rec[k] for k in key)
    except (ValueError, KeyError, TypeError):
        return None
    return rec if isinstance(rec, dict) else None


def _split_log(data: bytes, key: tuple[str, ...] = KEY) -> tuple[list[bytes], list[tuple[int, bytes]]]:
    """Good lines and ``(line number, bad line)``; a last line without newline is torn (bad)."""
    good, bad = [], []
    lines = data.split(b"\n")
    for lineno, line in enumerate(lines, 1):
        if not line.strip():
            continue
        torn = lineno == len(lines)           # after the last newline: never finished
        (bad.append((lineno, line)) if torn or _parse(line, key) is None else good.append(line))
    return good, bad


def _quarantine(path: Path, good: list[bytes], bad: list[tuple[int, bytes]]) -> None:
    """Append the bad lines to ``<log>.corrupt`` and atomically rewrite the log with the good."""
    corrupt = path.with_name(path.name + CORRUPT_SUFFIX)
    with open(corrupt, "ab") as fh:
        fh.write(b"".join(line + b"\n" for _, line in bad))
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(b"".join(line + b"\n" for line in good))
    os.replace(tmp, path)
    warnings.warn(f"{path}: {len(bad)} torn or corrupt line(s) (line "
                  f"{', '.join(str(n) for n, _ in bad)}) moved to {corrupt}; their episodes will run "
                  "again", ScoreboardWarning, stacklevel=3)


MAX_LOG_BYTES = 2**30
"""Cap on an episode log read back: 1 GiB (the published board's is under 1 MiB)."""


def read_episodes(path: str | Path, repair: bool = False, key: tuple[str, ...] = KEY) -> list[dict[str, Any]]:
    """Records of ``episodes.jsonl`` (first occurrence per ``key``, the board's ``KEY`` by default;
    another log of this format passes its own); torn or corrupt lines are skipped. The log must be a
    regular file of at most :data:`MAX_LOG_BYTES` (a link is refused: :func:`satenv.training.trust.read_member`).

    With ``repair`` those lines are moved to ``episodes.jsonl.corrupt`` (with a warning) and the
    log keeps every good line, so that appending to it continues a clean file.
    """
    from satenv.training.trust import read_member

    path = Path(path)
    if not os.path.lexists(path):
        return []
    good, bad = _split_log(bytes(read_member(path.parent, path.name, MAX_LOG_BYTES)), key)
    if bad and repair:
        _quarantine(path, good, bad)
    records, seen = [], set()
    for rec in (upgrade_record(_parse(line, key)) for line in good):
        k = tuple(rec[name] for name in key)
        if k not in seen:
            seen.add(k)
            records.append(rec)
    return records


class EpisodeLog:
    """Append-only JSONL writer: every record is one ``write`` of a full line, then ``fsync``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def append(self, record: dict[str, Any]) -> None:
        line = (json.dumps(record, sort_keys=True, allow_nan=False) + "\n").encode()
        os.write(self._fd, line)
        os.fsync(self._fd)

    def close(self) -> None:
        os.close(self._fd)
