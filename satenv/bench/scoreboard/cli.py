"""The command line: ``python -m satenv.bench.scoreboard`` / ``satenv-scoreboard``.

:func:`main` first sets one BLAS thread per process (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1 unless already set; fair, stable solve timings),
before numpy is imported by the board, so it holds for this process and every worker.
Importing this module changes no environment variable.
"""

from __future__ import annotations

import argparse
import os
import sys

from satenv.bench._env import single_thread_blas
from satenv.bench.scoreboard.registry import (
    FULL,
    POLICIES,
    QUICK,
    SCENARIOS,
    discover_trained_policies,
)
from satenv.bench.scoreboard.specs import SHIELD_SUFFIX, ScoreboardError, Unavailable
from satenv.training.config import parse_bool  # the trainers' boolean style: --flag true|false

__all__ = ["build_parser", "main", "with_shield"]


def _status(spec) -> str:
    try:
        spec.check_available()
        return "available"
    except Unavailable as why:
        return f"not available ({why})"


def _fits(spec) -> str:
    """Where a policy applies, for the listing."""
    if spec.baseline is not None:
        from satenv import baselines
        return baselines.get(spec.baseline).supported()
    return ",".join(spec.env_ids or ("any env",))


def list_registry() -> str:
    """The ``--list`` text: every scenario and policy, whether it can run here, where it fits."""
    lines = ["scenarios:"]
    for name, spec in SCENARIOS.items():
        lines.append(f"  {name:<32} {_status(spec):<12}  {spec.env_id:<13} {spec.description}")
    lines.append("policies:")
    for name, spec in {**POLICIES, **discover_trained_policies()}.items():
        fits = _fits(spec)
        ranked = f" (ranked on {','.join(spec.scenarios)})" if spec.scenarios else ""
        lines.append(f"  {name:<32} {_status(spec):<12}  fits {fits}{ranked}  {spec.description}")
    lines.append(f"any policy name + '{SHIELD_SUFFIX}': the policy behind the safety filter (--shield: every one)")
    lines.append(f"quick: {QUICK}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m satenv.bench.scoreboard",
                                description="Rank every policy on every scenario (satenv scoreboard).",
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help=f"the small embedded board: {QUICK['scenarios']} x {QUICK['policies']} x seeds "
                        f"{QUICK['seeds']} (a few minutes on 2 cores)")
    p.add_argument("--scenarios", help="comma-separated scenario names or globs (default: all available)")
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
    p.add_argument("--out-dir", "--out", dest="out",
                   help="output directory (default: results/scoreboard, results/scoreboard/quick with "
                        "--quick); --out is the same option")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    p.add_argument("--overwrite", action="store_true", help="discard the episodes already in --out")
    p.add_argument("--workers", type=int, default=1, help="parallel worker processes")
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
    p.add_argument("--list", action="store_true", help="list scenarios and policies, then exit")
    return p


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
    args = build_parser().parse_args(args_list)
    if args.list:
        print(list_registry())
        return 0
    from satenv.bench.scoreboard.board import (
        run_scoreboard,  # (imports numpy: after the BLAS setting)
    )
    from satenv.bench.scoreboard.runner import EPISODES_FILE

    out = args.out or ("results/scoreboard/quick" if args.quick else "results/scoreboard")
    try:
        if os.path.lexists(out) and not os.path.isdir(out):
            raise ScoreboardError(f"--out {out}: exists and is not a directory; the board is written "
                                  "to a folder (give a new or an earlier --out folder)")
        policies = with_shield(args.policies, args.quick) if args.shield else args.policies
        board = run_scoreboard(out, scenarios=args.scenarios, policies=policies, seeds=args.seeds,
                               checkpoints=args.policy, quick=args.quick, workers=args.workers,
                               backend=args.backend, ray_address=args.ray_address, resume=args.resume,
                               overwrite=args.overwrite, plots=args.plots,
                               progress=args.progress, argv=args_list)
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
