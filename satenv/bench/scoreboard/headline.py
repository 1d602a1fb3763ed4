"""The board's headline: per system of the papers (:data:`satenv.tasks.SYSTEMS`),
the best scripted and the best learned policy side by side, as a table at the top of
``scoreboard.md`` and one figure, ``plots/headline.png``.

On each system's task (the first of its tasks on the board: the one its learned policies are ranked
on), the best of each kind by the board's own safety-first ranking (success rate desc, collision
episodes asc, violation episodes asc, RMSE asc, delta-v asc); learned means a ``trained:`` or
``user:`` policy (with or without the safety filter), scripted everything else. The RMSE and delta-v
ratios (learned / scripted, ratio of the means) are taken on *matched, completed* episodes only
(``satenv.metrics.matched_ratios``): the seeds where both episodes ran to the end without an error
and without a collision, so an episode that ends early cannot improve a ratio.

Pure functions of the episode records and the board's ranking.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from satenv.bench.scoreboard.specs import NETWORK_SUFFIX, SHIELD_SUFFIX
from satenv.metrics import matched_ratios
from satenv.scoring import aggregate
from satenv.scoring import wilson as _wilson  # the board's success-rate interval

__all__ = ["FIGURE", "LEARNED_PREFIXES", "headline", "headline_figure", "headline_section", "is_learned",
           "paper_systems"]

LEARNED_PREFIXES = ("trained:", "user:")
"""Names of learned policies: shipped (``trained:<folder>``) and user checkpoints (``user:<run>``)."""
FIGURE = "plots/headline.png"
"""The headline figure, relative to the board's folder."""
HEADING = "Summary: best scripted and best learned policy per system"


def is_learned(policy: str) -> bool:
    """Whether a board policy name is a learned policy (its ``+shield`` variant included)."""
    return policy.startswith(LEARNED_PREFIXES)


def _policy_stats(recs: list[dict[str, Any]]) -> dict[str, Any]:
    """The headline's numbers of one policy: :func:`satenv.scoring.aggregate` of its records,
    under the headline's names (the interval also on one episode)."""
    agg = aggregate(recs)
    lo, hi = agg["success_ci95"] or _wilson(agg["successes"], agg["episodes"])[1:]
    return {"episodes": agg["episodes"], "successes": agg["successes"],
            "success": agg["success_rate"], "success_ci95": [lo, hi],
            "collision_episodes": agg["collision_episodes"], "violation_episodes": agg["violation_episodes"],
            "errors": agg["errors"], "interventions_per_agent_step": agg.get("interventions_per_agent_step")}


def _ratios(learned: list[dict[str, Any]], scripted: list[dict[str, Any]]) -> dict[str, Any]:
    """``matched_ratios`` of the episodes that ran (an errored episode is not completed); a
    non-finite ratio (a scripted mean of 0) is ``None``."""
    ran = [[r for r in recs if r.get("error") is None] for recs in (learned, scripted)]
    out = {"matched_seeds": 0, "rmse_ratio": None, "delta_v_ratio": None}
    out.update(matched_ratios(*ran))
    for k in ("rmse_ratio", "delta_v_ratio"):
        if out[k] is not None and not math.isfinite(out[k]):
            out[k] = None
    return out


def paper_systems() -> dict[str, tuple[str, ...]]:
    """``{label: (training task, paper task)}`` of :data:`satenv.tasks.SYSTEMS`: each system is
    shown on the first of its tasks that is on the board (first: its training task, the one its
    learned policies are ranked on; then its paper task)."""
    from satenv import tasks

    return {s.label: (s.training_task, s.paper_task) for s in tasks.SYSTEMS.values()}


def headline(records: Iterable[dict[str, Any]], ranking: Mapping[str, list[str]],
             systems: Mapping[str, tuple[str, ...]] | None = None) -> list[dict[str, Any]]:
    """One row per system (:func:`paper_systems` unless given) with a task on the board: ``system``,
    ``task``, ``scripted`` and
    ``learned`` (``{"policy", "episodes", "successes", "success", "success_ci95",
    "collision_episodes", "violation_episodes", "errors"}`` or ``None`` when the task has no policy of that kind; a
    best learned ``<name>+shield`` also holds ``unfiltered``, the same of ``<name>`` when it ran, and a
    best learned that ships with its filter the same of ``<name>:network``)
    and ``ratios``
    (``matched_seeds``, ``rmse_ratio``, ``delta_v_ratio``; ``None`` when not computable)."""
    systems = paper_systems() if systems is None else systems
    by_pair: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for rec in records:
        by_pair.setdefault((rec["scenario"], rec["policy"]), []).append(rec)
    rows = []
    for system, names in systems.items():
        scen = next((s for s in names if s in ranking), None)
        if scen is None:
            continue
        best = {kind: next((p for p in ranking[scen] if is_learned(p) == (kind == "learned")), None)
                for kind in ("scripted", "learned")}
        row: dict[str, Any] = {"system": system, "task": scen}
        for kind, pol in best.items():
            row[kind] = None if pol is None else {"policy": pol, **_policy_stats(by_pair[(scen, pol)])}
        net = (best["learned"] or "").removesuffix(SHIELD_SUFFIX)
        if net == best["learned"]:                               # shipped with its filter: <name>:network
            net = f"{net}{NETWORK_SUFFIX}"
        if best["learned"] and (scen, net) in by_pair:          # the network alone, beside the filtered one
            row["learned"]["unfiltered"] = {"policy": net, **_policy_stats(by_pair[(scen, net)])}
        row["ratios"] = (_ratios(by_pair[(scen, best["learned"])], by_pair[(scen, best["scripted"])])
                         if None not in best.values() else {"matched_seeds": 0, "rmse_ratio": None,
                                                            "delta_v_ratio": None})
        rows.append(row)
    return rows


def _who(e: dict[str, Any] | None) -> list[str]:
    if e is None:
        return ["–", "–", "–", "–"]
    cells = [f"`{e['policy']}`", f"{100 * e['success']:.0f} % ({e['successes']}/{e['episodes']})",
             f"{e['collision_episodes']}/{e['episodes']}", f"{e.get('violation_episodes', 0)}/{e['episodes']}"]
    if "unfiltered" in e:
        cells = [f"{a} (network alone: {b})" for a, b in zip(cells, _who(e["unfiltered"]), strict=True)]
    return cells


def _interventions(e: dict[str, Any] | None) -> str:
    """A learned policy's interventions per agent-step behind the filter (``—`` without it)."""
    rate = None if e is None else e.get("interventions_per_agent_step")
    return "—" if rate is None else f"{100 * rate:.3g} %"


def _ratio(x: float | None) -> str:
    return "–" if x is None else f"{x:.2f}"


def headline_section(rows: list[dict[str, Any]], figure: bool = True) -> list[str]:
    """The markdown section (empty without rows); ``figure``: link :data:`FIGURE`."""
    if not rows:
        return []
    lines = [f"## {HEADING}", "",
             "Per system of the papers, on the task its learned policies are ranked on, the best "
             "scripted and the best learned policy by this board's safety-first ranking (success rate, "
             "then collision episodes, then violation episodes, then RMSE, then Δv), so the best learned "
             "policy is the best *safe* one among equally successful ones. Collision episodes, violation "
             "episodes: episodes with at least one collision, with at least "
             "one hard-constraint violation counted by the env. RMSE and Δv ratios: "
             "learned / scripted, ratio of the means over the *matched, completed* episodes (seeds "
             "where both episodes ran to the end without a collision), so an episode that ends "
             "early cannot improve a ratio; `matched`: how many seeds; – when none. A learned policy "
             "behind the safety filter has its network alone beside it and the share of its agent-steps "
             "the filter changed (interventions / agent-step; — without the filter).", "",
             "| system | task | best scripted | success | collision episodes | violation episodes | best learned | "
             "success | collision episodes | violation episodes | interventions / agent-step | RMSE ratio | Δv ratio "
             "| matched |",
             "|---|---|---|--:|--:|--:|---|--:|--:|--:|--:|--:|--:|--:|"]
    for row in rows:
        r = row["ratios"]
        cells = [row["system"], f"`{row['task']}`", *_who(row["scripted"]), *_who(row["learned"]),
                 _interventions(row["learned"]), _ratio(r["rmse_ratio"]), _ratio(r["delta_v_ratio"]),
                 str(r["matched_seeds"])]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    if figure:
        lines += [f"![Success and collision episodes, best scripted vs best learned per system]({FIGURE})", ""]
    return lines


def headline_figure(rows: list[dict[str, Any]], path: Path) -> Path:
    """Two panels, a pair of bars per system (best scripted, best learned, each named on its bar):
    the success rate with its 95 % Wilson interval, and the share of episodes with a collision."""
    from satenv.render import new_figure

    fig = new_figure((11, 0.8 * len(rows) + 1.6), 90, layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for j, kind in enumerate(("scripted", "learned")):
        for i, row in enumerate(rows):
            e, y = row[kind], i + (0.2 if j else -0.2)
            if e is None:
                axes[0].text(1, y, f"no {kind} policy", va="center", fontsize=7)
                continue
            rate, (lo, hi) = 100 * e["success"], e["success_ci95"]
            label = f"best {kind}" if i == 0 else None
            axes[0].barh(y, rate, 0.4, xerr=[[rate - 100 * lo], [100 * hi - rate]], capsize=2,
                         color=f"C{j}", ecolor="0.45", label=label)
            axes[0].text(1, y, e["policy"], va="center", fontsize=7,
                         bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0, "pad": 1})
            share = 100 * e["collision_episodes"] / e["episodes"]
            axes[1].barh(y, share, 0.4, color=f"C{j}", label=label)
            axes[1].text(share + 1, y, f"{e['collision_episodes']}/{e['episodes']}", va="center", fontsize=7)
    axes[0].set_yticks(range(len(rows)), [f"{r['system']}\n{r['task']}" for r in rows], fontsize=8)
    axes[0].invert_yaxis()
    for ax, label in ((axes[0], "success rate [% of episodes] (95 % Wilson interval)"),
                      (axes[1], "collision episodes [% of episodes]")):
        ax.set_xlim(0, 112)
        ax.set_xlabel(label, fontsize=9)
    axes[1].legend(fontsize=8, loc="lower right")
    fig.savefig(path)
    return path
