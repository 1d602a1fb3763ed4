"""``python -m satenv.bench.learning``: run the grid, write ``results.json``, render the docs page.

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.bench.learning run \\
        --systems platoon-pereira2023,platoon-pereira2022 --seeds 0-2 --workers 2
    python -m satenv.bench.learning results      # studies/reference_results/log.jsonl -> results.json
    python -m satenv.bench.learning render       # results.json -> docs/reference_results.md + figures

``run`` is resumable: the same command skips every run already in the log (kill -9 safe).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from satenv import tasks
from satenv.bench.learning.grid import DEFAULT_ALGORITHMS, FILTER_SYSTEMS, LearningError, grid
from satenv.errors import SatenvError

__all__ = ["LOG", "RESULTS", "main"]

STUDY = Path(__file__).resolve().parents[3] / "studies" / "reference_results"
LOG = STUDY / "log.jsonl"
"""The evaluation log (committed: the raw data of ``results.json``)."""
RESULTS = STUDY / "results.json"
SYSTEM_ORDER = ("platoon-pereira2023", "platoon-pereira2022", "formation-kannan2022-position",
                "formation-kannan2022-collision", "cluster-li2022", "servicing-pereira2022")
"""Cheap systems first."""


def _names(text: str, allowed, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        raise LearningError(f"--{what} must name some of {list(allowed)}, got {text!r}")
    return names


def _runs(ns: argparse.Namespace, log_path: Path) -> list:
    """The runs ``run`` asks for (every argument checked: a :class:`LearningError` or a
    :class:`~satenv.errors.SatenvError` naming the bad one)."""
    from satenv.bench.learning.grid import ALGORITHMS

    if ns.workers < 1:
        raise LearningError(f"--workers must be an int >= 1, got {ns.workers}")
    try:
        seeds = tasks.parse_seeds(ns.seeds)
    except SatenvError as exc:
        raise LearningError(f"--seeds: {exc}") from exc
    return grid(_names(ns.systems, tasks.SYSTEMS, "systems"), _names(ns.algorithms, ALGORITHMS, "algorithms"),
                seeds, _names(ns.filter_systems, tasks.SYSTEMS, "filter-systems") if ns.filter_systems else (),
                log_path=str(log_path.resolve()), budget=ns.budget)


def cmd_run(ns: argparse.Namespace) -> int:
    from satenv.bench.learning.grid import KEY
    from satenv.bench.learning.runner import done_runs, logged_keys, lost_record, read_log, run_one
    from satenv.bench.scoreboard.backends import stream
    from satenv.bench.scoreboard.runner import EpisodeLog

    log_path = Path(ns.log)
    try:
        runs = _runs(ns, log_path)
    except LearningError as exc:   # bad input: one line, no traceback (the scoreboard's convention)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    log_path.parent.mkdir(parents=True, exist_ok=True)
    read_log(log_path, repair=True)
    done = done_runs(runs, log_path)
    todo = [r for r in runs if r not in done]
    print(f"{len(runs)} runs, {len(done)} already in {log_path}, {len(todo)} to run", flush=True)
    if ns.dry_run:
        for r in todo:
            print(" ", r.label())
        return 0
    for result in stream(todo, ns.backend, ns.workers, ns.address, run=run_one, lost=lost_record):
        keys = logged_keys(log_path)
        log = EpisodeLog(log_path)
        try:   # what the worker could not write itself (a Ray worker elsewhere, a dead worker)
            for rec in result["records"]:
                key = tuple(rec[k] for k in KEY)
                if rec.get("lost") or (rec.get("error") is None and key not in keys):
                    log.append(rec)
        finally:
            log.close()
        for rec in result["records"]:
            if rec.get("error"):
                print(f"error in {rec['system']}/{rec['algorithm']}/seed{rec['seed']}: {rec['error']}", flush=True)
    return 0


def cmd_results(ns: argparse.Namespace) -> int:
    from satenv.bench.learning.results import write_results

    out = write_results(Path(ns.log), Path(ns.out))
    print(f"wrote {out}")
    return 0


def cmd_render(ns: argparse.Namespace) -> int:
    from satenv.bench.learning.render import write_page

    page = write_page(Path(ns.results))
    print(f"wrote {page}")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m satenv.bench.learning", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="train and evaluate the grid (resumable)")
    r.add_argument("--log", default=str(LOG))
    r.add_argument("--systems", default=",".join(SYSTEM_ORDER))
    r.add_argument("--algorithms", default=",".join(DEFAULT_ALGORITHMS))
    r.add_argument("--seeds", default="0-2", help="training seeds, e.g. 0-2")
    r.add_argument("--filter-systems", default=",".join(FILTER_SYSTEMS),
                   help="systems with the filter-in-training PPO row ('' for none)")
    r.add_argument("--budget", type=int, default=0, help="RL agent-steps for every system (0: the grid's)")
    r.add_argument("--backend", choices=("local", "ray"), default="local")
    r.add_argument("--workers", type=int, default=1)
    r.add_argument("--address", default=None, help="Ray cluster address (--backend ray)")
    r.add_argument("--dry-run", action="store_true")
    r.set_defaults(func=cmd_run)
    s = sub.add_parser("results", help="log -> results.json")
    s.add_argument("--log", default=str(LOG))
    s.add_argument("--out", default=str(RESULTS))
    s.set_defaults(func=cmd_results)
    d = sub.add_parser("render", help="results.json -> docs page and figures")
    d.add_argument("--results", default=str(RESULTS))
    d.set_defaults(func=cmd_render)
    return p


def main(argv: list[str] | None = None) -> int:
    ns = parser().parse_args(argv)
    return ns.func(ns)


if __name__ == "__main__":
    sys.exit(main())
