"""The satenv scoreboard: every policy on every task over seeds, ranked on the papers' metrics.

Usage::

    python -m satenv.bench.scoreboard --quick            # the README's first command (~1-3 min)
    python -m satenv.bench.scoreboard                    # the full, published board
    python -m satenv.bench.scoreboard --scenarios 'platoon-*' --policies zero,dmpc --seeds 0-9
    python -m satenv.bench.scoreboard --policy runs/my_ppo/final --scenarios platoon-random-cw
    python -m satenv.bench.scoreboard --list             # what is registered / available
    satenv-scoreboard ...                              # the same, as a console script

The package, one job per module:

* :mod:`~satenv.bench.scoreboard.specs` — :class:`TaskSpec` (a task of :mod:`satenv.tasks`:
  ``satenv.make(env_id, **kwargs)``), :class:`PolicySpec`, and the rule :func:`policy_fits` (which
  policy runs on which env); an episode is scored by :func:`satenv.scoring.episode_record`;
* :mod:`~satenv.bench.scoreboard.registry` — the tables ``TASKS``, ``POLICIES``, ``QUICK``,
  ``FULL``, shipped trained policies and ``--policy`` folders (``runs/a/final`` -> ``user:a``);
* :mod:`~satenv.bench.scoreboard.plan` — selection (names or globs), seeds, preflight: every
  (task, policy) pair is built once (cheap or learned policies act once) before any episode
  runs, so bad input fails fast with a :class:`ScoreboardError`;
* :mod:`~satenv.bench.scoreboard.runner` — one episode (a :class:`Job`), and the JSONL log ``OUT/episodes.jsonl``:
  one line per finished episode, appended and ``fsync``-ed; ``--resume`` skips the keys already
  done, and moves a torn or corrupt line to ``episodes.jsonl.corrupt`` with a warning;
* :mod:`~satenv.bench.scoreboard.backends` — serial, a spawn process pool (``--workers K``; workers
  die with the board, a dead worker costs only its episode) or Ray (``--backend ray``): they
  only change *where* episodes run, so records equal a serial run's except the measured times
  (:data:`TIMING_FIELDS`);
* :mod:`~satenv.bench.scoreboard.report` — aggregation (the counts of :func:`satenv.scoring.aggregate`;
  mean and 95 % interval over seeds: percentile bootstrap for metrics, Wilson for the success rate),
  ranking (safety first: success rate desc, collision episodes asc, violation episodes asc, RMSE asc,
  delta-v asc) and the outputs in ``OUT`` (default ``results/scoreboard``,
  ``results/scoreboard/quick`` with ``--quick``): ``scoreboard.md``, ``scoreboard.json``,
  ``scoreboard.csv``, ``episodes.csv``, ``plots/<metric>.png``, ``plots/trajectories/*.png``;
* :mod:`~satenv.bench.scoreboard.headline` — the summary at the top of ``scoreboard.md``: per system
  of the papers (:data:`satenv.tasks.SYSTEMS`), the best scripted and the best learned policy side by
  side, ratios on matched completed episodes, and ``plots/headline.png``;
* :mod:`~satenv.bench.scoreboard.board` — :func:`run_scoreboard`, the steps above in order, and
  :func:`reaggregate` (re-write a board's files from its ``episodes.jsonl``, running nothing);
* :mod:`~satenv.bench.scoreboard.cli` — :func:`main` (sets one BLAS thread per process first).

Importing the package changes no environment variable and imports its modules lazily.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "board": ("reaggregate", "run_scoreboard"),
    "cli": ("build_parser", "main"),
    "plan": ("parse_seeds",),
    "registry": ("FULL", "POLICIES", "QUICK", "TASKS", "discover_trained_policies", "user_policy_name"),
    "report": ("KEY", "METRICS", "TIMING_FIELDS", "Board", "aggregate", "rank"),
    "runner": ("EPISODES_FILE", "Job", "ScoreboardWarning", "read_episodes", "run_episode"),
    "specs": ("PolicySpec", "ScoreboardError", "TaskSpec", "Unavailable", "policy_fits"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    if name not in _WHERE:
        raise AttributeError(f"module 'satenv.bench.scoreboard' has no attribute {name!r}")
    return getattr(importlib.import_module(f"satenv.bench.scoreboard.{_WHERE[name]}"), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
