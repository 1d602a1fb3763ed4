"""Regenerate the reproduction results the site shows (committed under docs/assets/reproductions/).

Usage:  python docs/gen_reproductions.py [--slow] [--only pereira2023,kannan2022] [--render-only]

For each paper, runs ``python -m satenv.bench.reproduce <paper> --out <paper>.json --plots <paper>/``,
keeps the printed table as ``<paper>.txt`` and renders the JSON into ``<paper>.md`` (:func:`render`:
the departures table, the claims with the paper's sentence, value, rule and our measurement, the
as-published / ablation / analysis tables). The reproduction pages include these files at build
time (``docs/hooks.py``), so nothing on them is typed in: the JSON is the one source.
``--render-only`` re-renders the ``.md`` files from the committed JSONs (after a run made by hand,
e.g. ``reproduce li2022 --case 1``). By default only the fast papers run (seconds); ``--slow`` adds
the ones that take minutes. Every call also rewrites the time column of
``docs/reproductions/index.md`` from the committed JSONs' ``wall_time_s``. A paper's exit status 1
(a paper-valued claim of our run not met) is recorded in its JSON (``pass``) and shown on its page,
not treated as an error here.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
OUT = DOCS / "assets" / "reproductions"

sys.path.insert(0, str(ROOT))
from satenv.bench.claims import (  # noqa: E402
    count,
    design_comparisons,
    markdown_claims,
    markdown_departures,
    paper_claims,
)

PAPERS: dict[str, bool] = {
    "pereira2023": False,
    "kannan2022": False,
    "pereira2022-platoon": False,
    "pereira2022-servicing": True,
    "li2022": True,
}
"""Paper name (as ``satenv.bench.reproduce`` knows it) -> slow (minutes rather than seconds)."""


def reproduce(paper: str) -> int:
    """Run one reproduction into ``OUT``; returns its exit status (0: every claim met)."""
    plots = OUT / paper
    shutil.rmtree(plots, ignore_errors=True)
    cmd = [sys.executable, "-m", "satenv.bench.reproduce", paper,
           "--out", str(OUT / f"{paper}.json"), "--plots", str(plots)]
    start = time.perf_counter()
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wrote = any(line.startswith("wrote ") for line in out.stdout.splitlines())
    if out.returncode not in (0, 1) or not wrote:      # status 1 is also a crash's: the result must be written
        sys.stderr.write(out.stdout + out.stderr)
        raise SystemExit(f"{' '.join(cmd[1:])} failed with status {out.returncode}")
    table = "\n".join(line for line in out.stdout.splitlines() if not line.startswith("wrote "))
    (OUT / f"{paper}.txt").write_text(table.rstrip() + "\n")
    write_page(paper)
    print(f"{paper}: status {out.returncode}, {time.perf_counter() - start:.0f} s")
    return out.returncode


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "; ".join(_value(x) for x in v) if v else "-"
    return "-" if v is None else str(v).replace("|", "\\|")


def table(rows: list[dict], keys: list[str] | None = None) -> str:
    """A Markdown table of a list of flat dicts (``keys``: the columns, default every key)."""
    keys = keys or list(dict.fromkeys(k for r in rows for k in r))
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    return "\n".join(out + ["| " + " | ".join(_value(r.get(k)) for k in keys) + " |" for r in rows])


def render(result: dict) -> str:
    """The page body of one reproduction result: verdict, departures, claims, analyses."""
    n = count(result.get("claims", []))
    verdict = "all met" if result.get("pass") else "**not all met**"
    parts = [f"**Verdict:** the paper-valued claims of our run: {n['gating_met']} of {n['gating']} met ({verdict}). "
             "All rows (our run, as published, ablations, other readings, comparisons with our own designs): "
             f"{n['met']} met, {n['not met']} not met, "
             f"{n['paper gives no value']} where the paper gives no value (reported, never counted as met). "
             "A claim's rule comes from the paper's sentence it quotes: a value is judged as a +-10 % band "
             "around it, a stated limit or fact as stated."]
    if result.get("not_run"):
        parts.append("**Not run in this result** (run it and re-render): "
                     + "; ".join(f"`{c}`" for c in result["not_run"]))
    if result.get("departures"):
        parts += ["### Departures from the paper",
                  "Every setting where our run differs from the paper, with its measured effect on the claims.",
                  markdown_departures(result["departures"])]
    claims = result.get("claims", [])
    parts += ["### Claims", markdown_claims(paper_claims(claims))]
    ours_designs = design_comparisons(claims)
    if ours_designs:
        designs = ", ".join(dict.fromkeys(c["against_our_design"] for c in ours_designs))
        parts += ["### Comparisons with our own designs (not gating)",
                  f"These rows compare with a design of ours the paper does not give ({designs}): they say how the "
                  "two designs compare here, not whether the paper reproduces, and never count in the verdict.",
                  markdown_claims(ours_designs, verdict=False)]
    if result.get("readings"):
        parts += ["### Other readings (our run under each)",
                  "Where the paper's text allows two readings of a setting, our run under the other one (its claims "
                  "are the variant rows of the table above) and the claims whose status it changes:",
                  table(result["readings"], ["variant", "case", "convergence_time_s", "final_error_m", "max_rise_m",
                                             "collisions", "max_thrust_N", "delta_v_total_mps",
                                             "gating_claims_changed", "changed_claims"])]
    timed = [r for r in result.get("rows", []) if isinstance(r, dict) and r.get("convergence_time_by_tolerance_s")]
    if timed:
        tols = list(dict.fromkeys(k for r in timed for k in r["convergence_time_by_tolerance_s"]))
        parts += ["### Convergence time by criterion",
                  "The paper states no criterion for its convergence time: the time [s] after which every "
                  "satellite stays within each distance of its target (`-`: not by the end).",
                  table([{"case": r["case"], "run": r.get("variant", "ours"), "controller": r["controller"],
                          **{f"within {k} m": r["convergence_time_by_tolerance_s"].get(k) for k in tols}}
                         for r in timed])]
    if result.get("ablation"):
        parts += ["### Ablation: ours minus each addition (case 1)",
                  table(result["ablation"], ["variant", "removed", "convergence_time_s", "satellites_within_1m_at_end",
                                             "final_error_m", "max_rise_m", "collisions", "min_pair_distance_m",
                                             "min_obstacle_distance_m", "failed_solves",
                                             "relaxed_solves", "fallbacks", "changed_claims"])]
    if result.get("sensitivity"):
        parts += ["### Accuracy against our Lyapunov tolerance (case 1, started on the targets)",
                  table(result["sensitivity"], ["lyapunov_tolerance", "floor_m", "final_error_m",
                                                "max_error_last_10_m", "nominal_residual_m", "max_tube_error_m",
                                                "relaxed_solves", "fallbacks"])]
    if result.get("foe_analysis"):
        parts += ["### FOE analysis",
                  "Offset per cell: ours / Table II (`foe_ratio`) and how many steps our decaying tail runs behind "
                  "the paper's (`steps_behind` = ln(FOE / paper) / ln(1 / tail_rate)):",
                  table(result["rows"], ["topology", "follower", "foe", "paper_foe", "foe_ratio", "tail_rate",
                                         "steps_behind"]),
                  "What was varied, one setting at a time, and what moved the FOE (ratio range over the 12 cells, "
                  "largest relative change of a cell against our default, cells within 10 % of Table II, "
                  "violations, worst RMSE error):",
                  table(result["foe_analysis"])]
    notes = result.get("notes")
    if isinstance(notes, dict):
        parts += ["### Notes"] + [f"**{k}.** {v}" for k, v in notes.items()]
        if "plf_tplf_followers_1_2_max_state_difference" in result:
            parts.append("Measured: the largest difference between the PLF and TPLF states of followers 1-2 is "
                         f"{result['plf_tplf_followers_1_2_max_state_difference']:.3g}.")
    elif isinstance(notes, list) and notes:
        parts += ["### Notes"] + notes
    return "\n\n".join(parts) + "\n"


INDEX = DOCS / "reproductions" / "index.md"
_INDEX_ROW = re.compile(r"^\| \[(?P<label>[^\]]+)\]\((?P<page>[\w.-]+)\.md\) \|(?P<middle>.*)\| (?P<time>[^|]*) \|$")


def wall_time_text(seconds: float) -> str:
    """A committed run's wall time as the index shows it (``"2.4 min"``, ``"59 s"``)."""
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def index_text(text: str) -> str:
    """The reproductions index with each row's time column set from the committed JSON's
    ``wall_time_s`` (the run that wrote the page; the machine's load varies)."""
    out = []
    for line in text.splitlines():
        m = _INDEX_ROW.match(line)
        if m and m.group("page") in PAPERS and (OUT / f"{m.group('page')}.json").exists():
            wall = json.loads((OUT / f"{m.group('page')}.json").read_text()).get("wall_time_s")
            if wall is not None:
                line = f"| [{m.group('label')}]({m.group('page')}.md) |{m.group('middle')}| {wall_time_text(wall)} |"
        out.append(line)
    return "\n".join(out) + "\n"


def write_index() -> Path:
    """Rewrite the index's time column from the committed JSONs (:func:`index_text`)."""
    INDEX.write_text(index_text(INDEX.read_text()))
    return INDEX


def write_page(paper: str) -> Path:
    """Render ``OUT/<paper>.json`` into ``OUT/<paper>.md``."""
    path = OUT / f"{paper}.md"
    path.write_text(render(json.loads((OUT / f"{paper}.json").read_text())))
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slow", action="store_true", help="also run the slow reproductions")
    parser.add_argument("--only", default=None, help="comma-separated papers (overrides --slow)")
    parser.add_argument("--render-only", action="store_true",
                        help="re-render <paper>.md from the committed JSONs, run nothing")
    args = parser.parse_args(argv)
    papers = args.only.split(",") if args.only else [p for p, slow in PAPERS.items() if args.slow or not slow]
    unknown = sorted(set(papers) - set(PAPERS))
    if unknown:
        parser.error(f"--only: unknown papers {unknown}; known: {sorted(PAPERS)}")
    OUT.mkdir(parents=True, exist_ok=True)
    for paper in papers:
        if args.render_only:
            print(f"rendered {write_page(paper)}")
        else:
            reproduce(paper)
    print(f"rewrote the run times of {write_index()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
