"""Compare the target-KL runs (``run.sh``) with the reference grid's runs of the same cells and seeds:
validation success (seeds 700000-700019) at each 2 M agent-step checkpoint, and how many runs ended
at least ``LATE_DROP`` below their best checkpoint (the reference page's count, on validation seeds).
Writes ``curves.json`` beside this file and prints a markdown table.

    .venv/bin/python studies/runs/target_kl_collapse/summarize.py runs/target_kl
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from satenv.bench.learning.render import LATE_DROP

HERE = Path(__file__).parent
RESULTS = HERE.parents[1] / "reference_results" / "results.json"


def _grid_curves(task: str, variant: str) -> dict[int, list[float]]:
    records = json.loads(RESULTS.read_text())["records"]
    return {r["seed"]: r["validation_success"] for r in records
            if r["task"] == task and r["algorithm"] == variant and not r["filter"]}


def _study_curve(folder: Path) -> list[float]:
    kept = sorted((folder / "kept").iterdir(), key=lambda p: int(p.name)) if (folder / "kept").is_dir() else []
    out = []
    for k in kept:
        agg = json.loads((k / "eval.json").read_text())["aggregate"]
        out.append(agg.get("learned", agg)["success_rate"])
    return out


def _drops(curves: dict[int, list[float]]) -> int:
    return sum(1 for c in curves.values() if c and max(c) - c[-1] >= LATE_DROP)


def main(root: Path) -> None:
    table = {}
    for cell in sorted(p for p in root.glob("*/*") if p.is_dir()):
        task, variant = cell.parent.name, cell.name
        mine = {int(s.name[4:]): _study_curve(s) for s in sorted(cell.glob("seed*"))}
        mine = {s: c for s, c in mine.items() if len(c) == 5}        # finished runs only
        grid = {s: c for s, c in _grid_curves(task, variant).items() if s in mine}
        table[f"{task}/{variant}"] = {"target_kl": mine, "default": grid}
        for name, curves in (("default", grid), ("target_kl 0.02", mine)):
            last = sum(c[-1] for c in curves.values()) / max(len(curves), 1)
            best = sum(max(c) for c in curves.values()) / max(len(curves), 1)
            print(f"| {task} | {variant} | {name} | {len(curves)} | {best:.2f} | {last:.2f} | {_drops(curves)} |")
    (HERE / "curves.json").write_text(json.dumps(table, indent=1) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
