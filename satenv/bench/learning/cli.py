"""``satenv results``: the reference-results grid: run it, write ``results.json``, render the docs page.

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 satenv results run \\
        --systems platoon-pereira2023,platoon-pereira2022 --seeds 0-2 --workers 2
    satenv results results      # results/reference_results/log.jsonl -> results.json
    satenv results render       # results.json -> results/reference_results/reference_results.md + figures

``run`` is resumable: the same command skips every run already in the log (kill -9 safe). Every
command writes under ``results/reference_results/`` unless told otherwise; ``--update-published``
reads and writes the committed record instead (``studies/reference_results/``, and the docs page
``docs/reference_results.md`` with its figures).
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
"""The published evaluation log (committed: the raw data of ``results.json``)."""
RESULTS = STUDY / "results.json"
USER = Path("results") / "reference_results"
"""Where the commands read and write by default (a user folder, never a tracked file)."""
SYSTEM_ORDER = ("platoon-pereira2023", "platoon-pereira2022", "formation-kannan2022-position",
                "formation-kannan2022-collision", "cluster-li2022", "servicing-pereira2022")
"""Cheap systems first."""


def _names(text: str, allowed, what: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        raise LearningError(f"--{what} {text!r}: expected comma-separated names among {list(allowed)}")
    return names


def _runs(ns: argparse.Namespace, log_path: Path) -> list:
    """The runs ``run`` asks for (every argument checked: a :class:`LearningError` naming the bad one)."""
    from satenv.bench.learning.grid import ALGORITHMS

    try:
        seeds = tasks.parse_seeds(ns.seeds)
    except SatenvError as exc:
        raise LearningError(f"--seeds {ns.seeds!r}: {exc}") from exc
    try:
        rungs = tasks.parse_seeds(ns.rungs) if ns.rungs else None
    except SatenvError as exc:
        raise LearningError(f"--rungs {ns.rungs!r}: {exc}") from exc
    return grid(_names(ns.systems, tasks.SYSTEMS, "systems"), _names(ns.algorithms, ALGORITHMS, "algorithms"),
                seeds, _names(ns.filter_systems, tasks.SYSTEMS, "filter-systems") if ns.filter_systems else (),
                log_path=str(log_path.resolve()), budget=ns.budget, rungs=rungs)


def _estimate(todo: list, log: list[dict], workers: int = 1) -> str:
    """The expected training wall time of ``todo`` from the runs of the same system and algorithm
    already in ``log`` (their slowest seconds per agent-step times each run's budget; the
    controller's evaluation time), or why there is none."""
    measured: dict[tuple, float] = {}
    for rec in log:
        key = (rec.get("system"), rec.get("algorithm"), rec.get("filter"))
        steps, wall = rec.get("agent_steps") or 0, float(rec.get("wall_s") or 0.0) + float(rec.get("eval_s") or 0.0)
        measured[key] = max(measured.get(key, 0.0), wall / steps if steps else wall)
    known = [measured[k] * (r.budget or 1) for r in todo if (k := (r.system, r.algorithm, r.filter)) in measured]
    if not known:
        return "no run of these systems and algorithms in the log to time them by"
    unknown = len(todo) - len(known)
    return (f"about {sum(known) / 3600 / workers:.1f} h on {workers} worker(s) for the {len(known)} whose system "
            "and algorithm the logs have timed" + (f" (+{unknown} not timed yet)" if unknown else ""))


def cmd_run(ns: argparse.Namespace) -> int:
    from satenv.bench.learning.grid import KEY
    from satenv.bench.learning.runner import done_runs, logged_keys, lost_record, read_log, run_one
    from satenv.bench.scoreboard.backends import stream
    from satenv.bench.scoreboard.runner import EpisodeLog

    log_path = Path(ns.log)
    try:
        runs = _runs(ns, log_path)
    except LearningError as exc:   # bad input: one error line, nothing written
        ns.parser.error(str(exc))
    if not ns.dry_run:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    log = read_log(log_path, repair=not ns.dry_run) if log_path.is_file() else []
    done = done_runs(runs, log_path)
    todo = [r for r in runs if r not in done]
    print(f"{len(runs)} runs, {len(done)} already in {log_path}, {len(todo)} to run"
          + (f": {_estimate(todo, log + (read_log(LOG) if LOG.is_file() else []), ns.workers)}; "
             "the same command resumes after an interruption" if todo else ""),
          flush=True)
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

    if not Path(ns.log).is_file():
        ns.parser.error(f"--log {str(ns.log)!r}: expected the grid's log file (satenv results run writes it)")
    Path(ns.out).parent.mkdir(parents=True, exist_ok=True)
    out = write_results(Path(ns.log), Path(ns.out))
    print(f"wrote {out}")
    return 0


def cmd_render(ns: argparse.Namespace) -> int:
    from satenv.bench.learning.render import ASSETS, PAGE, write_page

    if not Path(ns.results).is_file():
        ns.parser.error(f"--results {str(ns.results)!r}: expected a results.json file "
                        "(satenv results results writes it)")

    if ns.update_published:
        page = write_page(Path(ns.results), PAGE, ASSETS)
    else:
        folder = Path(ns.out_dir) if ns.out_dir else USER
        folder.mkdir(parents=True, exist_ok=True)
        page = write_page(Path(ns.results), folder / PAGE.name, folder / ASSETS.relative_to(PAGE.parent))
    print(f"wrote {page}")
    return 0


def parser() -> argparse.ArgumentParser:
    from satenv.cliargs import int_at_least, new_parser, out_file, out_folder

    p = new_parser("satenv results", __doc__)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, help: str, func) -> argparse.ArgumentParser:
        c = sub.add_parser(name, help=help, description=help, allow_abbrev=False,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        c.set_defaults(func=func, parser=c)
        return c

    r = command("run", "train and evaluate the grid (resumable: the same command skips the runs in the log)", cmd_run)
    r.add_argument("--log", type=out_file, default=None,
                   help=f"the evaluation log (JSON lines; default: {USER / 'log.jsonl'})")
    published(r)
    r.add_argument("--systems", default=",".join(SYSTEM_ORDER), help="comma-separated systems (default: all)")
    r.add_argument("--algorithms", default=",".join(DEFAULT_ALGORITHMS),
                   help="comma-separated algorithms (default: %(default)s)")
    r.add_argument("--seeds", default="0-4", help="training seeds, e.g. 0-4 (default: %(default)s)")
    r.add_argument("--rungs", default="", help="ladder rungs, 1 the easiest, e.g. 1 or 1-2 (default: every rung)")
    r.add_argument("--filter-systems", default=",".join(FILTER_SYSTEMS),
                   help="systems with the filter-in-training PPO row ('' for none)")
    r.add_argument("--budget", type=int_at_least(0), default=0,
                   help="RL agent-steps for every system (0: the grid's)")
    r.add_argument("--backend", choices=("local", "ray"), default="local")
    r.add_argument("--workers", type=int_at_least(1), default=1, help="parallel runs (default: 1)")
    r.add_argument("--address", default=None, help="Ray cluster address (--backend ray)")
    r.add_argument("--dry-run", action="store_true", help="list the runs to do, with the time estimate, and stop")
    s = command("results", "log -> results.json", cmd_results)
    s.add_argument("--log", type=out_file, default=None, help=f"the evaluation log (default: {USER / 'log.jsonl'})")
    s.add_argument("--out", type=out_file, default=None, help=f"the results file (default: {USER / 'results.json'})")
    published(s)
    d = command("render", "results.json -> docs page and figures", cmd_render)
    d.add_argument("--results", type=out_file, default=None,
                   help=f"the results file (default: {USER / 'results.json'})")
    d.add_argument("--out-dir", type=out_folder, default=None,
                   help=f"where the page and its figures go (default: {USER})")
    published(d)
    return p


def published(command: argparse.ArgumentParser) -> None:
    """The ``--update-published`` flag of a sub-command."""
    command.add_argument("--update-published", action="store_true",
                         help="read and write the committed record (studies/reference_results/, and for render "
                              "docs/reference_results.md with its figures) instead of results/reference_results/")


PATH_FLAGS = {"log": ("--log", LOG, "log.jsonl"), "out": ("--out", RESULTS, "results.json"),
              "results": ("--results", RESULTS, "results.json")}
"""Each path flag: its name, its published default and its file name under :data:`USER`."""


def resolve_paths(ns: argparse.Namespace) -> None:
    """Fill the path flags left out: the committed record with ``--update-published``, else :data:`USER`
    (a path given with ``--update-published`` is one error: the flag names where it writes)."""
    from satenv.cliargs import published_or_user

    for key, (flag, published_path, name) in PATH_FLAGS.items():
        if hasattr(ns, key):
            setattr(ns, key, published_or_user(ns.parser, flag, getattr(ns, key), ns.update_published,
                                               published_path, USER / name))
    if hasattr(ns, "out_dir"):
        published_or_user(ns.parser, "--out-dir", ns.out_dir, ns.update_published, "docs/reference_results.md", USER)


def main(argv: list[str] | None = None) -> int:
    ns = parser().parse_args(argv)
    resolve_paths(ns)
    return ns.func(ns)


if __name__ == "__main__":
    sys.exit(main())
