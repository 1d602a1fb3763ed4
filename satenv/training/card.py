"""Policy cards: the shipped policies' numbers, both ways, read from each folder's own files.

    satenv card             # the shipped-policies table of docs/training.md
    satenv card NAME        # one folder's evaluation table and its targets
    satenv card --readmes   # rewrite each folder README's both-ways section

Each row compares the learned policy with the scripted baseline its ``eval.json`` names (the
``vs_<BASELINE>`` entry: ratios on the same held-out seeds) against the targets of
:func:`satenv.scoring.targets`: no collision episode, no hard-constraint violation, success >=
:data:`~satenv.scoring.SUCCESS_MIN` and >= the baseline's minus
:data:`~satenv.scoring.SUCCESS_MARGIN`, RMSE and total delta-v within
:data:`~satenv.scoring.RATIO_LIMIT` of the baseline's on matched, completed episodes
(:func:`satenv.metrics.matched_ratios`, the ``matched`` entry). An evaluation written before the
matched rule has only all-seed ratios (``all_seeds``): the card shows them, marked, and holds
them to the same limit.

Every policy is reported **both ways** (:mod:`satenv.training.both_ways`): the network alone and as shipped (behind
``satenv.safety.shield`` when its ``env.json`` has ``"safety_filter"``), with the filter's
interventions and infeasible steps per agent-step. A folder's both-ways evaluation is
:data:`BOTH_WAYS_FILE` (one entry of ``satenv.bench.safety_alone``: both variants on the same test
seeds of its task, ratios to the controller on matched episodes), or its ``eval.json`` when that is
in the same format; it is then the source of the folder's whole row. A folder shipped without the
filter has the network alone as its shipped policy: the same numbers both ways, no interventions.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from satenv import scoring
from satenv.training import POLICIES_DIR
from satenv.training.both_ways import AS_SHIPPED, NETWORK_ALONE

__all__ = ["AS_SHIPPED", "BOTH_WAYS_FILE", "INTERVENTIONS_LIMIT", "NETWORK_ALONE", "both_ways", "both_ways_file",
           "card", "targets", "shipped_table", "folder_table", "readme", "update_readme"]

BOTH_WAYS_FILE = "safety_alone.json"
"""A policy folder's both-ways evaluation (``python -m satenv.bench.safety_alone --write-folders``)."""

INTERVENTIONS_LIMIT = 0.01
"""A policy shipped behind the filter: at most this fraction of its agent-steps changed by it."""


def both_ways_file(folder: Path) -> Path | None:
    """The folder's both-ways evaluation (module docstring): :data:`BOTH_WAYS_FILE`, else
    ``eval.json`` when it is one; ``None`` when it has neither."""
    for name in (BOTH_WAYS_FILE, "eval.json"):
        path = folder / name
        if path.is_file() and NETWORK_ALONE in json.loads(path.read_text()):
            return path
    return None


def card(folder: Path) -> dict[str, Any]:
    """The headline numbers of one policy folder, both ways (from its both-ways evaluation, else
    ``eval.json``; ``env.json``, ``scoreboard.json``)."""
    meta = json.loads((folder / "env.json").read_text())
    filtered = meta.get("safety_filter") is not None
    path = both_ways_file(folder)
    if path is not None:
        f = _safety_alone_fields(json.loads(path.read_text()), filtered)
    else:
        path = folder / "eval.json"
        f = _recipe_fields(json.loads(path.read_text()))
    own, ratios, base = f["own"], f["ratios"], f["base"]
    scen = folder / "scoreboard.json"
    return {
        "name": folder.name,
        "scenarios": json.loads(scen.read_text())["scenarios"] if scen.is_file() else [],
        "source": json.loads((folder / "policy.json").read_text()).get("source", ""),
        "filtered": filtered,
        "evaluation": path.name,
        "shipped": f["shipped"],
        **_numbers(own),
        "interventions_per_agent_step": _per_agent_step(own, "safety_interventions") if filtered else None,
        "infeasible_per_agent_step": _per_agent_step(own, "safety_infeasible") if filtered else None,
        "rmse_ratio": ratios.get("rmse_ratio"),
        "delta_v_ratio": ratios.get("delta_v_ratio"),
        "matched_seeds": ratios.get("matched_seeds"),
        "network_alone": {**_numbers(f["alone"]), "rmse_ratio": f["alone_ratios"].get("rmse_ratio"),
                          "delta_v_ratio": f["alone_ratios"].get("delta_v_ratio"),
                          "matched_seeds": f["alone_ratios"].get("matched_seeds")},
        "baseline": f["reference"],
        "baseline_success": None if base is None else base["success_rate"],
        "baseline_episodes": None if base is None else base["episodes"],
        "controller": None if base is None else _numbers(base),
        "ratios_on": "matched" if f["matched"] else "all seeds",
    }


def _numbers(agg: dict[str, Any]) -> dict[str, Any]:
    """Episodes, success, collision and violation episodes, violations per episode of an aggregate."""
    return {"episodes": agg["episodes"], "success": agg["success_rate"],
            "collision_episodes": agg["collision_episodes"], "violation_episodes": agg.get("violation_episodes"),
            "violations": agg["violations"]}


def _per_agent_step(agg: dict[str, Any], key: str) -> float | None:
    """The filter's ``key`` count over the agent-steps it decided (``None`` when not counted)."""
    steps = agg.get("safety_agent_steps")
    return agg[key] / steps if steps and agg.get(key) is not None else None


def _recipe_fields(ev: dict[str, Any]) -> dict[str, Any]:
    """An evaluation of ``satenv.training.evaluate`` / the held-out recipe: ``aggregate`` and ``vs_<REF>``;
    a folder shipped behind the filter has ``learned+shield`` beside the network alone. An older
    aggregate without violation episodes gets them from its episode records."""
    ref_key = next(k for k in ev if k.startswith("vs_"))
    ratios = ev[ref_key]
    reference = ratios.get("reference", ref_key[3:].lower())
    agg = ev["aggregate"]
    shipped = ratios.get("shipped", "learned")
    alone_ratios = ratios.get("matched", ratios.get("all_seeds", {}))
    alone = dict(agg["learned"])
    if alone.get("violation_episodes") is None and ev.get("learned_episodes"):
        alone["violation_episodes"] = scoring.aggregate(ev["learned_episodes"])["violation_episodes"]
    return {"own": alone if shipped == "learned" else agg[shipped],
            "ratios": alone_ratios if shipped == "learned" else ratios.get(shipped, {}),
            "alone": alone, "alone_ratios": alone_ratios, "reference": reference,
            "base": next((v for k, v in agg.items() if k.lower() == reference.lower()), None),
            "matched": "matched" in ratios or shipped != "learned", "shipped": shipped}


def _safety_alone_fields(ev: dict[str, Any], filtered: bool) -> dict[str, Any]:
    """An evaluation of ``satenv.bench.safety_alone``: the network alone and behind the filter on the
    same test seeds, ratios to the controller on matched episodes; what ships is the filtered
    variant only when the folder ships with the filter."""
    shipped = AS_SHIPPED if filtered else NETWORK_ALONE
    return {"own": ev[shipped]["aggregate"], "ratios": ev[shipped].get("ratios_vs_controller", {}),
            "alone": ev[NETWORK_ALONE]["aggregate"], "alone_ratios": ev[NETWORK_ALONE].get("ratios_vs_controller", {}),
            "reference": ev["controller"], "base": ev.get("controller_aggregate"), "matched": True,
            "shipped": shipped}


def targets(c: dict[str, Any]) -> dict[str, bool]:
    """:func:`satenv.scoring.targets` of one card, as shipped (``True`` = met); a policy shipped
    behind the filter also: interventions <= :data:`INTERVENTIONS_LIMIT` of its agent-steps and
    success not below the network alone's."""
    met = scoring.targets({"success_rate": c["success"], "collision_episodes": c["collision_episodes"],
                           "violation_episodes": c["violation_episodes"]},
                          None if c["baseline_success"] is None else {"success_rate": c["baseline_success"]},
                          {"rmse_ratio": c["rmse_ratio"], "delta_v_ratio": c["delta_v_ratio"]})
    out = {k: met[k] for k in ("no_collisions", "no_violations", "success", "rmse", "delta_v")}
    if c.get("filtered"):
        rate = c.get("interventions_per_agent_step")
        out["interventions"] = rate is not None and rate <= INTERVENTIONS_LIMIT
        out["not_below_alone"] = c["success"] >= c["network_alone"]["success"]
    return out


def _f(v: Any, fmt: str = ".2f") -> str:
    return "–" if v is None else format(v, fmt)


ALL_SEEDS_MARK = "†"
"""Marks a ratio taken over every seed (an older evaluation) instead of matched episodes."""


def _mark(c: dict[str, Any]) -> str:
    return "" if c["ratios_on"] == "matched" or c["rmse_ratio"] is None else ALL_SEEDS_MARK


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100 * v:.3g} %"


def _eps(n: dict[str, Any], key: str) -> str:
    """``k/n`` episodes (``–`` when not counted)."""
    return "–" if n[key] is None else f"{n[key]}/{n['episodes']}"


def _met(met: dict[str, bool]) -> str:
    return f"{sum(met.values())}/{len(met)}" + (
        "" if all(met.values()) else f" (not: {', '.join(k for k, v in met.items() if not v)})")


NO_FILTER = "— (no filter)"
"""The interventions cell of a policy shipped without the filter."""


def shipped_table(root: Path = POLICIES_DIR) -> str:
    """A Markdown table of every shipped policy, the network alone and as shipped, against its
    controller and the targets."""
    lines = ["| policy | scenario | how it was trained | network alone: success | collision ep. | violation ep. "
             "| as shipped: success | collision ep. | violation ep. | interventions / agent-step "
             "| infeasible / agent-step | RMSE ratio | Δv ratio | controller success | targets met |",
             "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|---|"]
    for folder in sorted(p for p in root.iterdir() if (p / "eval.json").is_file()):
        c = card(folder)
        n = c["network_alone"]
        lines.append(
            f"| `{c['name']}`{' (filter)' if c['filtered'] else ''} "
            f"| {', '.join(f'`{s}`' for s in c['scenarios'][:1])} | {c['source']} "
            f"| {_f(n['success'], '.3f')} | {_eps(n, 'collision_episodes')} | {_eps(n, 'violation_episodes')} "
            f"| {_f(c['success'], '.3f')} | {_eps(c, 'collision_episodes')} | {_eps(c, 'violation_episodes')} "
            + (f"| {_pct(c['interventions_per_agent_step'])} | {_pct(c['infeasible_per_agent_step'])} "
               if c["filtered"] else f"| {NO_FILTER} | — ")
            + f"| {_f(c['rmse_ratio'])}{_mark(c)} | {_f(c['delta_v_ratio'])}{_mark(c)} "
            f"| {c['baseline']} {_f(c['baseline_success'], '.3f')} ({c['baseline_episodes']}) | {_met(targets(c))} |")
    return "\n".join(lines + [
        "", "(filter): ships behind the safety filter (`env.json` `\"safety_filter\"`), the as-shipped columns "
        f"are the network behind it; without it the network alone is the shipped policy (the same numbers, "
        f"interventions {NO_FILTER}). Episodes as k/n of the n test seeds each way was run on. "
        f"{ALL_SEEDS_MARK} ratio over every test seed: an evaluation written "
        "before the matched-episode rule (an episode that ended early may lower it)."])


def folder_table(folder: Path) -> str:
    """The folder's full evaluation table (``eval.json``'s ``table``), its both-ways table and its
    targets."""
    ev = json.loads((folder / "eval.json").read_text())
    met = targets(card(folder))
    return "\n\n".join(t for t in (ev.get("table", ""), both_ways(folder)) if t) + "\n\ntargets: " + ", ".join(
        f"{k} {'met' if v else 'NOT met'}" for k, v in met.items())


BOTH_WAYS_BEGIN = "<!-- both ways: written by `python -m satenv.training.card --readmes` from the folder's files -->"
BOTH_WAYS_END = "<!-- end of both ways -->"
"""The markers around the both-ways section of a policy README (:func:`update_readme`)."""


def _seed_span(seeds: list[int]) -> str:
    return f"{min(seeds)}-{max(seeds)}" if seeds else "–"


def both_ways(folder: Path) -> str:
    """A policy README's both-ways section: the network alone and as shipped (success, collision
    and violation episodes, the filter's interventions and infeasible steps per agent-step, ratios
    to the controller on matched episodes) and the controller, from :func:`card`."""
    c = card(folder)
    ev = json.loads((folder / c["evaluation"]).read_text())
    n = c["network_alone"]
    seeds = _seed_span(ev.get("test_seeds", []))
    where = (f"test seeds {seeds} of task `{ev['task']}`" if "task" in ev else f"held-out seeds {seeds}")
    made = f", written by `{ev['command']}`" if ev.get("command") else ""
    if c["filtered"]:
        meta = json.loads((folder / "env.json").read_text())
        opts = meta["safety_filter"].get("options") or {}
        how = ("It **ships behind the safety filter** (`env.json` `\"safety_filter\"`"
               + (f", options {json.dumps(opts)}" if opts else ", default options")
               + "): `satenv.training.load(folder, env=env)` returns the network + filter (as shipped), "
               "`satenv.training.load(folder, env=env, shielded=False)` the network alone.")
    else:
        how = ("It **ships without the safety filter**: the network alone is the shipped policy (one row; "
               "no interventions).")

    def row(label: str, x: dict[str, Any], rates: tuple[str, str]) -> str:
        mark = "" if label.startswith("controller") else _mark(c)
        return (f"| {label} | {x['episodes']} | {_f(x['success'], '.3f')} | {_eps(x, 'collision_episodes')} "
                f"| {_eps(x, 'violation_episodes')} | {rates[0]} | {rates[1]} | {_f(x.get('rmse_ratio'))}{mark} "
                f"| {_f(x.get('delta_v_ratio'))}{mark} | {x.get('matched_seeds') or '–'} |")

    rows = [row("network alone" + ("" if c["filtered"] else " (= as shipped)"), n, (NO_FILTER, "—")
                if not c["filtered"] else ("—", "—"))]
    if c["filtered"]:
        rows.append(row("as shipped: network + filter", c, (_pct(c["interventions_per_agent_step"]),
                                                           _pct(c["infeasible_per_agent_step"]))))
    if c["controller"] is not None:
        rows.append(row(f"controller `{c['baseline']}`", {**c["controller"], "rmse_ratio": 1.0,
                                                          "delta_v_ratio": 1.0, "matched_seeds": None}, ("—", "—")))
    return "\n".join([
        BOTH_WAYS_BEGIN,
        f"**Network alone and as shipped** (`{c['evaluation']}`: {where}{made}). {how}", "",
        "| variant | episodes | success | collision ep. | violation ep. | interventions / agent-step "
        "| infeasible / agent-step | RMSE ratio | Δv ratio | matched |",
        "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|", *rows, "",
        "Ratios: this variant / the controller, means over the matched episodes (seeds where both ran to "
        "the end without a collision)" + ("" if c["ratios_on"] == "matched" else
                                        f"; {ALL_SEEDS_MARK} over every seed (an older evaluation)") + ".",
        *perturbation_table(ev, c["baseline"]),
        BOTH_WAYS_END])


PERTURBATION_VARIANTS = ((NETWORK_ALONE, "network alone"), (AS_SHIPPED, "as shipped"), ("controller", "controller"))
"""The variants of a both-ways evaluation's ``perturbations`` block, and their labels."""


def perturbation_table(ev: dict[str, Any], controller: str) -> list[str]:
    """The both-ways evaluation's ``perturbations`` (``satenv.bench.safety_alone --perturbation-seeds``:
    every perturbation of the task, each variant on the same first test seeds) as Markdown lines;
    none when it has no such block."""
    pert = ev.get("perturbations")
    if not pert:
        return []
    lines = [f"**Under the task's perturbations** (`satenv.perturbations`; a navigation error is read by the "
             f"filter too; test seeds {_seed_span(pert['seeds'])}, the controller `{controller}` on the first "
             "n of them):", "",
             "| perturbation | variant | episodes | success | collision ep. | violation ep. | Δv [m/s] "
             "| interventions / agent-step |", "|---|---|--:|--:|--:|--:|--:|--:|"]
    for name, row in pert.items():
        if name == "seeds":
            continue
        for key, label in PERTURBATION_VARIANTS:
            a = row.get(key)
            if not a or "episodes" not in a:
                continue
            lines.append(f"| {name} | {label} | {a['episodes']} | {_f(a['success_rate'])} "
                         f"| {_eps(a, 'collision_episodes')} | {_eps(a, 'violation_episodes')} "
                         f"| {_f(a.get('delta_v'), '.1f')} | {_pct(a.get('interventions_per_agent_step'))} |")
    return ["", *lines]


def update_readme(folder: Path) -> bool:
    """Write :func:`both_ways` into the folder's README: in place of its section, else before
    its first ``## `` heading, else at its end; whether the README changed."""
    path = folder / "README.md"
    text = path.read_text()
    section = both_ways(folder)
    if BOTH_WAYS_BEGIN in text and BOTH_WAYS_END in text:
        head, rest = text.split(BOTH_WAYS_BEGIN, 1)
        new = head + section + rest.split(BOTH_WAYS_END, 1)[1]
    elif "\n## " in text:
        head, rest = text.split("\n## ", 1)
        new = head.rstrip("\n") + "\n\n" + section + "\n\n## " + rest
    else:
        new = text.rstrip("\n") + "\n\n" + section + "\n"
    if new != text:
        path.write_text(new)
    return new != text


def readme(folder: Path, *, title: str, about: str, command: str, notes: str = "") -> str:
    """A policy folder's README: what it is, how to load and retrain it, its learning curve and
    evaluation table (from ``eval.json``), the network alone and as shipped (:func:`both_ways`) and
    which targets it meets."""
    meta = json.loads((folder / "env.json").read_text())
    c = card(folder)
    kwargs = ", ".join(f"{k}={v!r}" for k, v in meta["eval_env_kwargs"].items())
    parts = [
        f"# {folder.name} — {title}\n", about.strip() + "\n",
        "```python\nimport satenv, training\nfrom satenv.rollout import rollout\n"
        f"env = satenv.make({meta['env_id']!r}, {kwargs})\n"
        f"policy = satenv.training.load(satenv.training.POLICIES_DIR / {folder.name!r}, env=env)\n"
        f"traj = rollout(env, policy, seed={json.loads((folder / 'eval.json').read_text())['test_seeds'][0]})\n```\n",
        f"**Retrain** ({c['source']}; `config.json` holds every setting):\n\n```bash\n{command}\n```\n",
    ]
    if (folder / "learning_curve.png").is_file():
        parts.append("**Learning curve** (evaluation seeds, not the held-out ones):\n\n"
                     "![learning curve](learning_curve.png)\n")
    parts.append(f"**Evaluation** (`eval.json`: {c['episodes']} held-out seeds, never used for training or "
                 f"selection; ratios against `{c['baseline']}` on the same seeds):\n\n{folder_table(folder)}\n")
    if notes:
        parts.append(notes.strip() + "\n")
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> None:
    """Print the shipped-policies table, one folder's table (``NAME``), or rewrite the READMEs."""
    from satenv.cliargs import new_parser

    folders = sorted(p for p in POLICIES_DIR.iterdir() if (p / "eval.json").is_file())
    parser = new_parser("satenv card", __doc__)
    parser.add_argument("name", nargs="?", metavar="NAME",
                        help="a shipped policy: print its evaluation table and targets "
                             f"(one of: {', '.join(f.name for f in folders)})")
    parser.add_argument("--readmes", action="store_true",
                        help="rewrite the both-ways section of every shipped folder's README.md")
    args = parser.parse_args(argv)
    if args.readmes and args.name:
        parser.error(f"give NAME or --readmes, not both (got NAME {args.name!r})")
    if args.readmes:
        for folder in folders:
            if update_readme(folder):
                print("updated", folder / "README.md")
    elif args.name is not None:
        if args.name not in {f.name for f in folders}:
            parser.error(f"NAME {args.name!r}: expected a shipped policy with an eval.json, one of "
                         f"{', '.join(f.name for f in folders)}")
        print(folder_table(POLICIES_DIR / args.name))
    else:
        print(shipped_table())


if __name__ == "__main__":
    main()
