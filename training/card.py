"""Policy cards: the shipped policies' numbers, read from their ``eval.json`` (one source).

    python -m training.card            # the shipped-policies table of docs/training.md
    python -m training.card NAME       # one folder's evaluation table and its targets

Each row compares the learned policy with the scripted baseline its ``eval.json`` names (the
``vs_<BASELINE>`` entry: ratios on the same held-out seeds) against the targets of
:func:`satenv.scoring.targets`: no collision episode, no hard-constraint violation, success >=
:data:`~satenv.scoring.SUCCESS_MIN` and >= the baseline's minus
:data:`~satenv.scoring.SUCCESS_MARGIN`, RMSE and total delta-v within
:data:`~satenv.scoring.RATIO_LIMIT` of the baseline's on matched, completed episodes
(:func:`satenv.metrics.matched_ratios`, the ``matched`` entry). An evaluation written before the
matched rule has only all-seed ratios (``all_seeds``): the card shows them, marked, and holds
them to the same limit.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from satenv import scoring
from training import POLICIES_DIR

__all__ = ["card", "targets", "shipped_table", "folder_table", "readme"]



def card(folder: Path) -> dict[str, Any]:
    """The headline numbers of one policy folder (from ``eval.json``, ``env.json``, ``scoreboard.json``)."""
    ev = json.loads((folder / "eval.json").read_text())
    read = _safety_alone_fields if "network alone" in ev else _recipe_fields
    own, ratios, alone, reference, base, matched, shipped = read(folder, ev)
    scen = folder / "scoreboard.json"
    return {
        "name": folder.name,
        "scenarios": json.loads(scen.read_text())["scenarios"] if scen.is_file() else [],
        "source": json.loads((folder / "policy.json").read_text()).get("source", ""),
        "shipped": shipped,
        "episodes": own["episodes"],
        "success": own["success_rate"],
        "collision_episodes": own["collision_episodes"],
        "violations": own["violations"],
        "violation_episodes": own.get("violation_episodes", int(bool(own["violations"]))),
        "rmse_ratio": ratios.get("rmse_ratio"),
        "delta_v_ratio": ratios.get("delta_v_ratio"),
        "network_alone": None if alone is None else {
            k: alone[k] for k in ("success_rate", "collision_episodes", "violations")},
        "baseline": reference,
        "baseline_success": None if base is None else base["success_rate"],
        "baseline_episodes": None if base is None else base["episodes"],
        "ratios_on": "matched" if matched else "all seeds",
    }


def _recipe_fields(folder: Path, ev: dict[str, Any]) -> tuple:
    """An evaluation of ``training.evaluate`` / the held-out recipe: ``aggregate`` and ``vs_<REF>``;
    a folder shipped behind the filter has ``learned+shield`` beside the network alone."""
    ref_key = next(k for k in ev if k.startswith("vs_"))
    ratios = ev[ref_key]
    reference = ratios.get("reference", ref_key[3:].lower())
    agg = ev["aggregate"]
    base = next((v for k, v in agg.items() if k.lower() == reference.lower()), None)
    shipped = ratios.get("shipped", "learned")
    own_ratios = (ratios.get("matched", ratios.get("all_seeds", {})) if shipped == "learned"
                  else ratios.get(shipped, {}))
    alone = None if shipped == "learned" else agg["learned"]
    return agg[shipped], own_ratios, alone, reference, base, "matched" in ratios or shipped != "learned", shipped


def _safety_alone_fields(folder: Path, ev: dict[str, Any]) -> tuple:
    """An evaluation of ``benchmarks.safety_alone``: the network alone and behind the filter on the
    same test seeds, ratios to the controller on matched episodes."""
    filtered = json.loads((folder / "env.json").read_text()).get("safety_filter") is not None
    shipped = "network + filter" if filtered else "network alone"
    block = ev[shipped]
    return (block["aggregate"], block.get("ratios_vs_controller", {}),
            ev["network alone"]["aggregate"] if filtered else None, ev["controller"],
            ev.get("controller_aggregate"), True, shipped)


def targets(c: dict[str, Any]) -> dict[str, bool]:
    """:func:`satenv.scoring.targets` of one card (``True`` = met)."""
    met = scoring.targets({"success_rate": c["success"], "collision_episodes": c["collision_episodes"],
                           "violation_episodes": c["violation_episodes"]},
                          None if c["baseline_success"] is None else {"success_rate": c["baseline_success"]},
                          {"rmse_ratio": c["rmse_ratio"], "delta_v_ratio": c["delta_v_ratio"]})
    return {k: met[k] for k in ("no_collisions", "no_violations", "success", "rmse", "delta_v")}


def _f(v: Any, fmt: str = ".2f") -> str:
    return "–" if v is None else format(v, fmt)


ALL_SEEDS_MARK = "†"
"""Marks a ratio taken over every seed (an older evaluation) instead of matched episodes."""


def _mark(c: dict[str, Any]) -> str:
    return "" if c["ratios_on"] == "matched" or c["rmse_ratio"] is None else ALL_SEEDS_MARK


def _alone(c: dict[str, Any]) -> str:
    """For a policy shipped behind the safety filter: that, and the network's own numbers."""
    n = c["network_alone"]
    if n is None:
        return ""
    return (f" (ships with the safety filter; the network alone: success {_f(n['success_rate'])}, "
            f"{n['collision_episodes']} collision episodes, {_f(n['violations'], '.3g')} violations / episode)")


def shipped_table(root: Path = POLICIES_DIR) -> str:
    """A Markdown table of every shipped policy against its baseline and the targets."""
    lines = ["| policy | scenario | how it was trained | success | collision episodes | violations / episode "
             "| RMSE ratio | Δv ratio | baseline success | targets met |",
             "|---|---|---|--:|--:|--:|--:|--:|---|---|"]
    for folder in sorted(p for p in root.iterdir() if (p / "eval.json").is_file()):
        c = card(folder)
        met = targets(c)
        lines.append(
            f"| `{c['name']}`{_alone(c)} | {', '.join(f'`{s}`' for s in c['scenarios'][:1])} | {c['source']} "
            f"| {_f(c['success'])} | {c['collision_episodes']} | {_f(c['violations'], '.3g')} "
            f"| {_f(c['rmse_ratio'])}{_mark(c)} | {_f(c['delta_v_ratio'])}{_mark(c)} "
            f"| {c['baseline']} {_f(c['baseline_success'])} ({c['baseline_episodes']}) "
            f"| {sum(met.values())}/{len(met)}" + ("" if all(met.values()) else
                                                   f" (not: {', '.join(k for k, v in met.items() if not v)})")
            + " |")
    return "\n".join(lines + ["", f"{ALL_SEEDS_MARK} ratio over every test seed: an evaluation written "
                                    "before the matched-episode rule (an episode that ended early may lower it)."])


def folder_table(folder: Path) -> str:
    """The folder's full evaluation table (``eval.json``'s ``table``) and its targets."""
    ev = json.loads((folder / "eval.json").read_text())
    met = targets(card(folder))
    return ev.get("table", "") + "\n\ntargets: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in met.items())


def readme(folder: Path, *, title: str, about: str, command: str, notes: str = "") -> str:
    """A policy folder's README: what it is, how to load and retrain it, its learning curve and
    evaluation table (from ``eval.json``) and which targets it meets."""
    meta = json.loads((folder / "env.json").read_text())
    c = card(folder)
    kwargs = ", ".join(f"{k}={v!r}" for k, v in meta["eval_env_kwargs"].items())
    parts = [
        f"# {folder.name} — {title}\n", about.strip() + "\n",
        "```python\nimport satenv, training\nfrom satenv.rollout import rollout\n"
        f"env = satenv.make({meta['env_id']!r}, {kwargs})\n"
        f"policy = training.load(training.POLICIES_DIR / {folder.name!r}, env=env)\n"
        f"traj = rollout(env, policy, seed={json.loads((folder / 'eval.json').read_text())['test_seeds'][0]})\n```\n",
        f"**Retrain** ({c['source']}; `config.json` holds every setting):\n\n```bash\n{command}\n```\n",
    ]
    if (folder / "learning_curve.png").is_file():
        parts.append("**Learning curve** (evaluation seeds, not the held-out ones):\n\n![learning curve](learning_curve.png)\n")
    parts.append(f"**Evaluation** (`eval.json`: {c['episodes']} held-out seeds, never used for training or "
                 f"selection; ratios against `{c['baseline']}` on the same seeds):\n\n{folder_table(folder)}\n")
    if notes:
        parts.append(notes.strip() + "\n")
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if argv:
        folder = POLICIES_DIR / argv[0]
        if not (folder / "eval.json").is_file():
            raise SystemExit(f"error: no shipped policy {argv[0]!r} with an eval.json under {POLICIES_DIR}")
        print(folder_table(folder))
    else:
        print(shipped_table())


if __name__ == "__main__":
    main()
