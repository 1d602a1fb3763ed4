"""Reproduce a paper's table or claims: ``satenv reproduce <paper> --out FILE.json``.

Each paper lives in its own module ``satenv/bench/reproductions/<paper>.py`` (``-`` in the paper
name becomes ``_``) exposing::

    reproduce(plots: str | Path | None = None, seed: int = 0) -> dict   # {"paper", "claims", "departures", "pass", ...}
    format_table(result: dict) -> str                                  # printed beside the paper

A module may also define ``add_arguments(parser)`` to add its own options (e.g. li2022's
``--case``; ``satenv reproduce --help`` lists them, ``satenv reproduce <paper> --help`` explains
them); their values are passed to ``reproduce`` as keyword arguments, and ``RUN_TIME`` (str, e.g.
``"about 1 s"``), the expected wall time that ``--help`` lists and the command prints first. Progress goes to stderr
(:func:`satenv.bench._io.progress`).

Register it in :data:`PAPERS` (no other name is loaded). The command prints the table, writes the
JSON to ``--out`` and the figures to ``--plots DIR``; it exits with status 0 only when every
paper-valued claim of our default run is met (:func:`satenv.bench.claims.passed`; as-published and
ablation rows and claims without a paper value are reported, not gating), else 1.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
from pathlib import Path
from types import ModuleType

from satenv.bench._io import write_json
from satenv.bench.claims import passed

PAPERS: dict[str, str] = {
    "pereira2023": "satenv.bench.reproductions.pereira2023",
    "pereira2022-platoon": "satenv.bench.reproductions.pereira2022_platoon",
    "pereira2022-servicing": "satenv.bench.reproductions.pereira2022_servicing",
    "kannan2022": "satenv.bench.reproductions.kannan2022",
    "li2022": "satenv.bench.reproductions.li2022",
}
"""Paper name -> module implementing ``reproduce`` and ``format_table``."""


def load(paper: str) -> ModuleType:
    """The reproduction module of ``paper`` (a name of :data:`PAPERS`; anything else is a
    ``ValueError`` naming the known papers, so no other module or path is ever imported)."""
    if not isinstance(paper, str) or paper not in PAPERS:
        raise ValueError(f"no reproduction for paper {paper!r}; known: {sorted(PAPERS)}")
    return importlib.import_module(PAPERS[paper])


def build_parser() -> argparse.ArgumentParser:
    """``satenv reproduce PAPER [options]``: one sub-parser per paper with the common options
    (``--out``, ``--plots``, ``--seed``) and the paper's own; the epilog lists each paper's
    expected wall time and its own options."""
    from satenv.cliargs import new_parser

    common = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    common.add_argument("--out", type=Path, default=None, help="write the result JSON here (a new .json file "
                        "or an earlier result)")
    common.add_argument("--plots", type=Path, default=None, help="save the figures (PNG) in this directory")
    common.add_argument("--seed", type=int, default=0, help="seed of the env and the policy (default 0)")
    parser = new_parser("satenv reproduce", __doc__.split("\n\n")[0])
    papers = parser.add_subparsers(dest="paper", metavar="PAPER", required=True,
                                   parser_class=argparse.ArgumentParser)
    for paper in sorted(PAPERS):
        module = load(paper)
        run_time = getattr(module, "RUN_TIME", "not stated")
        own = argparse.ArgumentParser(add_help=False)
        if hasattr(module, "add_arguments"):
            module.add_arguments(own)
        flags = [a.option_strings[0] for a in own._actions if a.option_strings]
        papers.add_parser(paper, parents=[common, own], allow_abbrev=False,
                                help=f"{run_time}" + (f"; own options: {' '.join(flags)}" if flags else ""),
                                description=f"{(module.__doc__ or paper).strip().splitlines()[0]}\n\n"
                                            f"Expected wall time: {run_time}.",
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.epilog = ("PAPER is followed by --out, --plots, --seed and its own options; "
                     "satenv reproduce PAPER --help explains them.")
    return parser


MAX_RESULT_BYTES = 64 * 2**20
"""The largest existing file ``--out`` may replace (a reproduction JSON is well under a MB)."""


def _unsafe_out(path: Path) -> str | None:
    """Why ``--out path`` must not be written, or None: it names a new ``.json`` file, or an
    earlier reproduction's result (a JSON object with ``paper`` and ``claims``), nothing else —
    the command never overwrites another file (it may run as root)."""
    if path.suffix != ".json":
        return "expected a .json file name"
    if not os.path.lexists(path):
        return None
    if path.is_symlink() or not path.is_file():
        return "exists and is not a regular file"
    if path.stat().st_size > MAX_RESULT_BYTES:
        return "exists and is not a reproduction result (too large); choose another name"
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        data = None
    if not (isinstance(data, dict) and "paper" in data and "claims" in data):
        return "exists and is not an earlier reproduction result; choose another name"
    return None


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.out is not None and (problem := _unsafe_out(args.out)):
        parser.error(f"--out {str(args.out)!r}: {problem}")
    module = load(args.paper)
    extra = {k: v for k, v in vars(args).items() if k not in {"paper", "out", "plots", "seed"}}
    print(f"reproducing {args.paper}: expected wall time {getattr(module, 'RUN_TIME', 'not stated')}"
          + (f"; the result goes to {args.out}" if args.out else "; --out FILE.json keeps the result")
          + (f", the figures to {args.plots}/" if args.plots else ""), file=sys.stderr, flush=True)
    result = module.reproduce(plots=args.plots, seed=args.seed, **extra)
    print(module.format_table(result))
    if args.out is not None:
        write_json(args.out, result)
        print(f"wrote {args.out}")
    return 0 if passed(result) else 1


if __name__ == "__main__":
    sys.exit(main())
