"""Regenerate the reproduction results the site shows (committed under docs/assets/reproductions/).

Usage:  python docs/gen_reproductions.py [--slow] [--only pereira2023,kannan2022]

For each paper, runs ``python -m benchmarks.reproduce <paper> --out <paper>.json --plots <paper>/``
and keeps the printed table as ``<paper>.txt``. The reproduction pages render these files at build
time (``docs/hooks.py``: the per-claim ``paper`` / ``measured`` / ``met`` fields of the JSON, the
text table and every figure), so nothing on them is pasted. By default only the fast papers run
(seconds); ``--slow`` adds the ones that take minutes. A paper's exit status 1 (a claim not met)
is recorded in its JSON (``pass``) and shown on its page, not treated as an error here.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
OUT = DOCS / "assets" / "reproductions"

PAPERS: dict[str, bool] = {
    "pereira2023": False,
    "kannan2022": False,
    "pereira2022-platoon": False,
    "pereira2022-servicing": True,
    "li2022": True,
}
"""Paper name (as ``benchmarks.reproduce`` knows it) -> slow (minutes rather than seconds)."""


def reproduce(paper: str) -> int:
    """Run one reproduction into ``OUT``; returns its exit status (0: every claim met)."""
    plots = OUT / paper
    shutil.rmtree(plots, ignore_errors=True)
    cmd = [sys.executable, "-m", "benchmarks.reproduce", paper,
           "--out", str(OUT / f"{paper}.json"), "--plots", str(plots)]
    start = time.perf_counter()
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if out.returncode not in (0, 1) or not (OUT / f"{paper}.json").exists():
        sys.stderr.write(out.stdout + out.stderr)
        raise SystemExit(f"{' '.join(cmd[1:])} failed with status {out.returncode}")
    table = "\n".join(line for line in out.stdout.splitlines() if not line.startswith("wrote "))
    (OUT / f"{paper}.txt").write_text(table.rstrip() + "\n")
    print(f"{paper}: status {out.returncode}, {time.perf_counter() - start:.0f} s")
    return out.returncode


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slow", action="store_true", help="also run the slow reproductions")
    parser.add_argument("--only", default=None, help="comma-separated papers (overrides --slow)")
    args = parser.parse_args(argv)
    papers = args.only.split(",") if args.only else [p for p, slow in PAPERS.items() if args.slow or not slow]
    unknown = sorted(set(papers) - set(PAPERS))
    if unknown:
        parser.error(f"--only: unknown papers {unknown}; known: {sorted(PAPERS)}")
    OUT.mkdir(parents=True, exist_ok=True)
    for paper in papers:
        reproduce(paper)
    return 0


if __name__ == "__main__":
    sys.exit(main())
