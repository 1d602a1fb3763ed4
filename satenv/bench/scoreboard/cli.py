"""The command line: ``satenv board`` (also ``python -m satenv.bench.scoreboard``).

:func:`main` first sets one BLAS thread per process (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1 unless already set; fair, stable solve timings),
before numpy is imported by the board, so it holds for this process and every worker.
Importing this module changes no environment variable.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from satenv.bench._env import single_thread_blas
from satenv.bench.scoreboard.registry import (
    FULL,
    POLICIES,
    QUICK,
    TASKS,
    discover_trained_policies,
)
from satenv.bench.scoreboard.specs import SHIELD_SUFFIX, ScoreboardError, Unavailable
from satenv.cliargs import int_at_least, new_parser, out_folder, parse_bool

__all__ = ["build_parser", "main", "with_shield"]

PUBLISHED_EPISODES = Path(__file__).resolve().parents[3] / "studies" / "published" / "episodes.jsonl"
"""The published board's episodes (in a repository checkout): their ``wall_s`` time a new plan."""
SWARM_MARK = "swarm"
"""A task whose name holds this word is a team-size variant (tens to hundreds of spacecraft,
minutes per episode): a default ``--policy`` run leaves them out."""


def _status(spec) -> str:
    try:
        spec.check_available()
        return "available"
    except Unavailable as why:
        return f"not available ({why})"


def _fits(spec) -> str:
    """Where a policy applies, for the listing (without importing its optional solver)."""
    if spec.baseline is not None:
        from satenv import baselines
        try:
            return baselines.get(spec.baseline).supported()
        except ImportError as why:
            return f"(its module needs an extra: {why})"
    return ",".join(spec.env_ids or ("any env",))


def list_registry() -> str:
    """The ``--list`` text: every scenario and policy, whether it can run here, where it fits."""
    lines = ["tasks (--scenarios):"]
    for name, spec in TASKS.items():
        lines.append(f"  {name:<32} {_status(spec):<12}  {spec.env_id:<13} {spec.description}")
    lines.append("policies:")
    for name, spec in {**POLICIES, **discover_trained_policies()}.items():
        fits = _fits(spec)
        ranked = f" (ranked on {','.join(spec.tasks)})" if spec.tasks else ""
        lines.append(f"  {name:<32} {_status(spec):<12}  fits {fits}{ranked}  {spec.description}")
    lines.append(f"any policy name + '{SHIELD_SUFFIX}': the policy behind the safety filter (--shield: every one)")
    lines.append(f"quick: {QUICK}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = new_parser("satenv board", "Rank every policy on every task (the satenv scoreboard). The board states "
                   "its plan (episodes, tasks, expected time) before the first episode.")
    p.add_argument("--quick", action="store_true",
                   help=f"the small embedded board: {QUICK['scenarios']} x {QUICK['policies']} x seeds "
                        f"{QUICK['seeds']} (about 2 minutes on 2 cores)")
    p.add_argument("--scenarios", help="comma-separated task names or globs (default: all available; with "
                                       f"--policy alone: all but the '{SWARM_MARK}' tasks)")
    p.add_argument("--policies", help="comma-separated policy names or globs (default: all available)")
    p.add_argument("--seeds", help=f"seeds: '0-9', '0,3,7' (default: the test seeds {FULL['seeds']} with fewer for "
                                   f"{sorted(FULL['scenario_seeds'])} and one for a deterministic task; "
                                   f"quick: {QUICK['seeds']})")
    p.add_argument("--policy", action="append", default=[], metavar="PATH",
                   help="also run a trained policy folder (satenv.training.load(PATH)), named after its run "
                        "folder (runs/a/final -> user:a); repeatable. Safe for folders from anyone: "
                        "only JSON and torch weights are read, nothing is unpickled; old SB3 "
                        "model.zip folders are refused (satenv.training.policy.convert_sb3 converts one "
                        "you trust)")
    p.add_argument("--out-dir", "--out", dest="out", type=lambda text: str(out_folder(text)), metavar="DIR",
                   help="output directory (default: results/scoreboard, results/scoreboard/quick with "
                        "--quick); --out is the same option")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    p.add_argument("--overwrite", action="store_true", help="discard the episodes already in --out")
    p.add_argument("--workers", type=int_at_least(1), default=1, help="parallel worker processes")
    p.add_argument("--backend", choices=("process", "ray"), default="process",
                   help="where episodes run: local processes or Ray")
    p.add_argument("--address", "--ray-address", dest="ray_address", default=None,
                   help="address of an existing Ray cluster (default: start a local one); "
                        "--ray-address is the same option")
    p.add_argument("--plots", type=parse_bool, default=True, metavar="{true,false}",
                   help="draw the PNG plots and trajectories (default: true)")
    p.add_argument("--progress", type=parse_bool, default=True, metavar="{true,false}",
                   help="show the progress bar (default: true)")
    for old in ("plots", "progress"):   # the former style, still accepted
        p.add_argument(f"--no-{old}", dest=old, action="store_false", help=argparse.SUPPRESS)
    p.add_argument("--shield", action="store_true",
                   help="rank every selected policy also behind the safety filter (satenv.safety), as "
                        "<name>+shield beside it; a policy name ending in +shield selects one alone")
    p.add_argument("--list", action="store_true", help="list tasks and policies, then exit")
    return p


def without_swarms() -> str:
    """``--scenarios`` of a default ``--policy`` run: every task but the swarms, each as a one-name
    glob (``[p]latoon-PLF-cw``) so that the selection keeps a default run's rules (a task that
    cannot run here or that no policy fits is skipped with a note, not an error)."""
    return ",".join(f"[{n[0]}]{n[1:]}" for n in TASKS if SWARM_MARK not in n)


def _measured_rate(path: Path = PUBLISHED_EPISODES) -> dict[tuple[str, str], float]:
    """Mean wall seconds of an episode per (task, policy) of the published board (empty without it)."""
    from satenv.bench.scoreboard.runner import read_episodes

    if not path.is_file():
        return {}
    walls: dict[tuple[str, str], list[float]] = {}
    for rec in read_episodes(path):
        if isinstance(rec.get("wall_s"), (int, float)):
            walls.setdefault((rec.get("scenario"), rec.get("policy")), []).append(float(rec["wall_s"]))
    return {k: sum(v) / len(v) for k, v in walls.items()}


def plan_line(keys: list[tuple[str, str, int]], done, workers: int,
              rate: dict[tuple[str, str], float]) -> str:
    """``planning N episodes on M tasks ...``: the plan's size and the expected time of the episodes
    not ``done`` (keys of the log) at the published board's measured rate (a pair it did not run:
    the mean of its task's episodes)."""
    todo = [k for k in keys if k not in done]
    done = len(keys) - len(todo)
    per_task: dict[str, list[float]] = {}
    for (task, _), wall in rate.items():
        per_task.setdefault(task, []).append(wall)
    known = [rate.get((t, p)) or (sum(per_task[t]) / len(per_task[t]) if t in per_task else None)
             for t, p, _ in todo]
    timed = [w for w in known if w is not None]
    tasks = {k[0] for k in keys}
    text = (f"planning {len(keys)} episodes on {len(tasks)} tasks x {len({k[1] for k in keys})} policies"
            + (f" ({done} already in the log)" if done else ""))
    if timed:
        minutes = sum(timed) / workers / 60
        text += (f", about {f'{minutes:.0f} min' if minutes >= 1 else 'a minute or less'} on {workers} worker(s) "
                 f"at the published board's measured rate"
                 + (f" (+{len(todo) - len(timed)} episodes of tasks it has not timed)"
                    if len(timed) < len(todo) else ""))
    swarms = sorted(t for t in tasks if SWARM_MARK in t)
    if swarms:
        text += f"; the swarm tasks {', '.join(swarms)} take minutes per episode"
    return text


def with_shield(policies: str | None, quick: bool) -> str:
    """``--shield``: each requested policy pattern and its ``+shield`` twin (default: every policy,
    or the quick board's)."""
    names = policies.split(",") if policies else (list(QUICK["policies"]) if quick else ["*"])
    names = [n.strip() for n in names if n.strip()]
    return ",".join(names + [n + SHIELD_SUFFIX for n in names if not n.endswith(SHIELD_SUFFIX)])


def _report(board, plots: bool) -> int:
    from satenv.bench.scoreboard.runner import EPISODES_FILE

    print(board.markdown)
    print(f"wrote {board.out}/scoreboard.md, scoreboard.json, scoreboard.csv, episodes.csv"
          + (", plots/" if plots else ""))
    errors = sum(1 for r in board.records if r.get("error"))
    if errors:
        print(f"warning: {errors} episode(s) raised an error (see the 'error' field in "
              f"{board.out}/{EPISODES_FILE})", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    single_thread_blas()
    args_list = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(args_list)
    if args.list:
        print(list_registry())
        return 0
    from satenv.bench.scoreboard.board import (
        run_scoreboard,  # (imports numpy: after the BLAS setting)
    )
    from satenv.bench.scoreboard.runner import EPISODES_FILE

    out = str(args.out or ("results/scoreboard/quick" if args.quick else "results/scoreboard"))
    scenarios = args.scenarios
    if args.policy and scenarios is None and not args.quick:
        scenarios = without_swarms()
        print(f"note: --policy without --scenarios: the '{SWARM_MARK}' tasks are left out "
              "(--scenarios '*' runs them too)", file=sys.stderr)
    rate = _measured_rate()
    total = [0, 0]

    def on_plan(plan, done) -> None:
        total[:] = [len(plan.keys), len(done)]
        print(plan_line(plan.keys, done, args.workers, rate) + f"; writing to {out}", file=sys.stderr, flush=True)

    def on_record(_record) -> None:
        total[1] += 1
        if total[1] == total[0]:
            print(f"all {total[0]} episodes done: writing the tables"
                  + (" and drawing the plots (a few minutes on a full board; --plots false skips them)"
                     if args.plots else ""), file=sys.stderr, flush=True)

    try:
        policies = with_shield(args.policies, args.quick) if args.shield else args.policies
        board = run_scoreboard(out, scenarios=scenarios, policies=policies, seeds=args.seeds,
                               checkpoints=args.policy, quick=args.quick, workers=args.workers,
                               backend=args.backend, ray_address=args.ray_address, resume=args.resume,
                               overwrite=args.overwrite, plots=args.plots,
                               progress=args.progress, argv=args_list, on_plan=on_plan, on_record=on_record)
    except ScoreboardError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # --out unwritable (permissions, a file on the way, ...)
        print(f"error: --out {out}: cannot write there ({exc.strerror or exc})", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished episodes are in {out}/{EPISODES_FILE}; "
              "rerun with --resume to continue", file=sys.stderr)
        return 130
    return _report(board, args.plots)
