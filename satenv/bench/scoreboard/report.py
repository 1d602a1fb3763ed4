"""Scoreboard results: the header, aggregation (mean and 95 % CI), ranking, the aggregates across
tasks, and the written outputs (``scoreboard.md``, ``scoreboard.json``, ``scoreboard.csv``,
``episodes.csv``, ``plots/``).

Intervals respect each metric's range: the success rate's is the Wilson score interval
(``scipy.stats.binomtest``), every other metric's a percentile bootstrap of the mean over seeds
(as ``scipy.stats.bootstrap(method="percentile")``), so it stays inside the observed values (a separation is never
negative). Across tasks (:func:`summarize`, after rliable, Agarwal et al. 2021): the
interquartile mean of a normalised score and the probability of improvement over the paper's
controller, with stratified bootstrap confidence intervals.

Pure functions of the episode records written by :mod:`satenv.bench.scoreboard.runner`.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import subprocess
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring
from satenv.scoring import rank_key
from satenv.scoring import wilson as _wilson  # the success rate's interval: one home
from satenv.tasks import CONTROLLERS

__all__ = ["KEY", "METRICS", "PAPER_CONTROLLER", "TIMING_FIELDS", "Board", "aggregate", "jsonable", "machine",
           "rank", "render_markdown", "summarize", "write_outputs", "write_plots"]

KEY = ("scenario", "policy", "seed")
METRICS: tuple[str, ...] = (
    "success", "rmse", "rmsee", "foe", "final_error_m", "delta_v", "time_to_converge_s",
    "min_separation_m", "collisions", "violations", "safety_cost", "fallbacks",
    "compute_ms_per_decision", "episode_return", "steps", "safety_interventions", "interventions_per_agent_step",
    "safety_mean_du", "safety_infeasible",
)
"""Aggregated per (task, policy), fields of the one episode record (:func:`satenv.scoring.episode_record`):
``satenv.metrics.summary`` plus ``episode_return``, and for a shielded policy the safety filter's
``safety_interventions``, ``interventions_per_agent_step``, ``safety_mean_du``, ``safety_infeasible``."""
TIMING_FIELDS: tuple[str, ...] = ("compute_ms_per_decision", "compute_ms_per_agent", "wall_s")
"""Measured wall times: the only record fields that differ between two runs of the same key."""

_TABLE = [  # (metric, column header) of the markdown table
    ("success", "success"), ("rmse", "RMSE"), ("rmsee", "RMSEE"), ("foe", "FOE"),
    ("delta_v", "Δv [m/s]"), ("time_to_converge_s", "t_conv [s]*"),
    ("min_separation_m", "min sep [m]"), ("collisions", "collision flags"), ("violations", "violations"),
    ("safety_cost", "cost"), ("fallbacks", "fallbacks"), ("compute_ms_per_decision", "ms/decision"),
]
_SHIELD_TABLE = [("safety_interventions", "interventions"),
                 ("interventions_per_agent_step", "interventions / agent-step"),
                 ("safety_mean_du", "mean ‖Δu‖"), ("safety_infeasible", "infeasible")]
"""Columns of a task with a shielded policy (``+shield``): per episode, agent-steps (and
their share of the episode's agent-steps)."""
PAPER_CONTROLLER = CONTROLLERS
"""The controller each env's paper proposes (:data:`satenv.tasks.CONTROLLERS`): the reference
(score 1) of the normalised score."""
FLOOR = "zero"
"""The policy that scores 0 on the normalised score (no thrust)."""
BOOTSTRAP_RESAMPLES = 2000

_PLOTS = ("success", "rmse", "rmsee", "foe", "delta_v", "time_to_converge_s", "min_separation_m",
          "collisions", "violations", "compute_ms_per_decision")


def jsonable(value: Any) -> Any:
    """Plain JSON values; NaN / inf become ``None``."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    return value


@dataclass
class Board:
    """A finished board (:func:`satenv.bench.scoreboard.run_scoreboard`): header, records in plan
    order, aggregates and ranking per task, notes and the markdown table."""

    out: Path
    header: dict[str, Any]
    records: list[dict[str, Any]]
    aggregates: dict[str, Any]
    ranking: dict[str, list[str]]
    notes: list[str] = field(default_factory=list)
    markdown: str = ""
    summary: dict[str, Any] = field(default_factory=dict)
    headline: list[dict[str, Any]] = field(default_factory=list)


# ----------------------------------------------------------------------------------------------
# Aggregation.
# ----------------------------------------------------------------------------------------------
def _bootstrap_interval(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and percentile-bootstrap 95 % interval of the mean (inside the observed range); the
    percentile method of ``scipy.stats.bootstrap``, vectorised over the resamples (a board has
    thousands of (task, policy, metric) cells) and seeded, so a board is reproducible."""
    mean = float(values.mean())
    if values.size < 2:
        return mean, math.nan, math.nan
    if np.ptp(values) == 0:
        return mean, mean, mean
    idx = np.random.default_rng(0).integers(0, values.size, (BOOTSTRAP_RESAMPLES, values.size))
    lo, hi = np.clip(np.percentile(values[idx].mean(axis=1), [2.5, 97.5]), values.min(), values.max())
    return mean, float(lo), float(hi)   # (clipped: round-off of resampled means can step outside)


def aggregate(records: Iterable[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    """``{task: {policy: {"n", "errors", "collision_episodes", "violation_episodes", metric:
    {"mean", "ci95": [lo, hi], "n"}}}}`` (module docstring: Wilson for the success rate, percentile
    bootstrap for the rest). The counts are :func:`satenv.scoring.aggregate`'s (the one rule:
    episodes with at least one collision, with at least one violation, each counted once).

    Errored episodes count as failures in the success rate and are left out of the other
    metrics; ``None`` (e.g. no convergence) values are left out of that metric's mean.
    """
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for rec in records:
        groups.setdefault((rec["scenario"], rec["policy"]), []).append(rec)
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for (task, pol), recs in sorted(groups.items()):
        ok = [r for r in recs if r.get("error") is None]
        counts = scoring.aggregate(recs)
        entry: dict[str, Any] = {"n": counts["episodes"], "errors": counts["errors"],
                                 "collision_episodes": counts["collision_episodes"],
                                 "violation_episodes": counts["violation_episodes"]}
        for m in METRICS:
            if m == "success":
                mean, lo, hi = _wilson(counts["successes"], counts["episodes"])
                n = counts["episodes"]
            else:
                vals = np.array([float(r[m]) for r in ok if r.get(m) is not None], dtype=float)
                n = int(vals.size)
                mean, lo, hi = _bootstrap_interval(vals) if n else (math.nan, math.nan, math.nan)
            entry[m] = {"mean": mean, "ci95": [lo, hi], "n": n}
        out.setdefault(task, {})[pol] = entry
    return jsonable(out)


RANKING = ("success rate (desc), then collision episodes (asc), then violation episodes (asc), then RMSE "
           "(asc), then delta-v (asc): safety first")
"""The board's ranking rule in words (:func:`rank`)."""


def rank(agg: dict[str, dict[str, Any]]) -> list[str]:
    """Policies of one task, best first, safety first (:func:`satenv.scoring.rank_key`):
    success rate, then collision episodes, then violation episodes, then RMSE, then delta-v."""
    def key(item):
        pol, e = item
        def mean(m):
            return (e.get(m) or {}).get("mean")
        return (*rank_key(mean("success"), e.get("collision_episodes"), e.get("violation_episodes"),
                          mean("rmse"), mean("delta_v")), pol)
    return [pol for pol, _ in sorted(agg.items(), key=key)]


# ----------------------------------------------------------------------------------------------
# Across tasks (rliable-style).
# ----------------------------------------------------------------------------------------------
def summarize(records: Iterable[dict[str, Any]], envs: dict[str, str], metric: str = "rmse",
              resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0) -> dict[str, Any]:
    """Aggregates of every policy across the tasks (after rliable, Agarwal et al. 2021).

    The normalised score of an episode on a task is ``(m0 - m) / (m0 - m1)`` of its ``metric``
    (lower is better: RMSE by default), with ``m0`` the mean of :data:`FLOOR` (no thrust) and
    ``m1`` the mean of the env's paper controller (:data:`PAPER_CONTROLLER`) on that task:
    0 = no thrust, 1 = the paper's controller; an errored episode scores 0. A task without
    both references is left out (``skipped``). Per policy, over the tasks it ran on (``tasks``):
    ``iqm`` (interquartile mean of the pooled episode scores) and ``p_improvement`` (the mean over
    tasks of P(score > the paper controller's score), ties count half), each with a 95 %
    stratified bootstrap interval (episodes resampled within each task). ``envs``: each task's env id.
    """
    from scipy import stats

    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for rec in records:
        groups.setdefault((rec["scenario"], rec["policy"]), []).append(rec)

    def values(task: str, pol: str) -> np.ndarray:
        return np.array([float(r[metric]) if r.get("error") is None and r.get(metric) is not None else np.nan
                         for r in groups.get((task, pol), [])])

    scores: dict[str, dict[str, np.ndarray]] = {}
    refs: dict[str, str] = {}
    skipped: dict[str, str] = {}
    for task, env in envs.items():
        ref = PAPER_CONTROLLER.get(env)
        m0, m1 = np.nanmean(values(task, FLOOR)) if (task, FLOOR) in groups else np.nan, \
            np.nanmean(values(task, ref)) if (task, ref) in groups else np.nan
        if not (np.isfinite(m0) and np.isfinite(m1)) or m0 == m1:
            skipped[task] = f"needs {FLOOR} and the paper's controller {ref} on it, with different {metric}"
            continue
        refs[task] = ref
        scores[task] = {pol: np.nan_to_num((m0 - values(task, pol)) / (m0 - m1), nan=0.0)
                        for (sc, pol) in groups if sc == task}
    rng = np.random.default_rng(seed)
    out: dict[str, Any] = {}
    for pol in sorted({p for per in scores.values() for p in per}):
        tasks = [s for s in scores if pol in scores[s]]
        boot = [scores[s][pol][rng.integers(0, scores[s][pol].size, (resamples, scores[s][pol].size))]
                for s in tasks]
        pooled = np.concatenate([scores[s][pol] for s in tasks])
        iqm_boot = stats.trim_mean(np.concatenate(boot, axis=1), 0.25, axis=1)
        entry = {"tasks": len(tasks), "episodes": int(pooled.size),
                 "iqm": float(stats.trim_mean(pooled, 0.25)),
                 "iqm_ci95": [float(q) for q in np.percentile(iqm_boot, [2.5, 97.5])],
                 "p_improvement": None, "p_improvement_ci95": [None, None]}
        vs = [s for s in tasks if refs[s] != pol]
        if vs:
            point, reps = [], []
            for s in vs:
                x, y = scores[s][pol], scores[s][refs[s]]
                point.append(_p_greater(x[None], y[None])[0])
                bx = x[rng.integers(0, x.size, (resamples, x.size))]
                by = y[rng.integers(0, y.size, (resamples, y.size))]
                reps.append(_p_greater(bx, by))
            entry["p_improvement"] = float(np.mean(point))
            entry["p_improvement_ci95"] = [float(q) for q in np.percentile(np.mean(reps, axis=0), [2.5, 97.5])]
        out[pol] = entry
    return {"metric": metric, "floor": FLOOR, "reference": refs, "skipped": skipped, "policies": out}


def _p_greater(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per row: P(X > Y) + P(X = Y) / 2 over every pair of the rows of ``x`` (R, n) and ``y`` (R, m)."""
    diff = x[:, :, None] - y[:, None, :]
    return np.mean((diff > 0) + 0.5 * (diff == 0), axis=(1, 2))


# ----------------------------------------------------------------------------------------------
# Outputs.
# ----------------------------------------------------------------------------------------------
def _fmt(x: float | None) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if x == 0:
        return "0"
    if abs(x) >= 1e4 or abs(x) < 1e-3:
        return f"{x:.2e}"
    return f"{x:.3g}"


def _cell(stat: dict[str, Any], metric: str) -> str:
    """``mean [lo, hi]`` (the 95 % interval; the success rate in %)."""
    mean, (lo, hi) = stat["mean"], stat["ci95"]
    if mean is None:
        return "–"
    if metric == "success":   # no interval on one episode (a deterministic task runs one seed)
        one = stat.get("n", 2) < 2
        if lo is not None and not one:
            return f"{100 * mean:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"
        return f"{100 * mean:.0f} %"
    if lo is None or hi is None or hi - lo <= 1e-9 * max(1.0, abs(mean)):  # one seed, or the same value on all
        return _fmt(mean)
    return f"{_fmt(mean)} [{_fmt(lo)}, {_fmt(hi)}]"


def _preamble(h: dict[str, Any]) -> list[str]:
    m = h["machine"]
    seeds = h["seeds"]
    seed_text = f"{seeds[0]}–{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else str(seeds)
    lines = [f"# {h['title']}", "",
             f"satenv {h['satenv_version']}" + (f" (git {h['git']})" if h.get("git") else "")
             + f" · envs {', '.join(h['env_versions'])} · seeds {seed_text} ({len(seeds)} per pair) · "
             f"{h['generated']}",
             f"machine: {m['cpu']}, {m['cpus']} CPUs, {m['platform']}, Python {m['python']}, "
             f"numpy {m['numpy']}", ""]
    if h.get("scenario_seeds"):
        lines += ["Fewer seeds for the expensive tasks: "
                  + ", ".join(f"{n}: {v}" for n, v in h["scenario_seeds"].items()), ""]
    return lines + [
        f"Ranked by {RANKING}. Cells: mean over seeds [95 % interval]: success rate with the "
        "Wilson score interval, every other metric with a percentile bootstrap of the mean (inside "
        "the observed values).", "",
        "Definitions (satenv.metrics; per episode, then averaged over seeds): **RMSE** [m] root mean "
        "square tracking error over the episode, mean over agents; **RMSEE** [m/s²] root mean square "
        "commanded acceleration; **FOE** [m] final tracking error; **Δv** [m/s] total velocity change, "
        "summed over agents; **t_conv** [s]* time until every agent stays converged (mean over the "
        "episodes that converged, n in scoreboard.json); **min sep** [m] smallest distance between "
        "any agent and any other body (0 on the kannan2022 formations: the paper starts the three spacecraft at one "
        "point, and those tasks have no collision distance, so no separation is flagged); **collision flags** "
        "(step, agent) collision flags per episode; **violations** "
        "constraint violations counted by the env (speed, keep-out, line of sight, ... as the "
        "scenario defines them); **cost** the env's safety cost summed over the episode; "
        "**fallbacks** solver failures replaced by a safe action; **ms/decision** wall time of one "
        "act() call; behind the safety filter, **interventions** agent-steps it changed per episode, "
        "**interventions / agent-step** their share of the episode's agent-steps, **infeasible** "
        "agent-steps it applied its backup action.", ""]


def _task_section(board: Board, task: str) -> list[str]:
    info = board.header["scenarios"].get(task, {})
    rule = (f"success: every agent within {info.get('success_tol_m', '?')} m of its target at the end"
            + (" and no collision" if info.get("collision_free_success", True) else ""))
    desc = info.get("description", "")
    lines = [f"## {task} ({info.get('env', '?')})", "", (f"{desc}. " if desc else "") + f"{rule}.", ""]
    table = _TABLE + (_SHIELD_TABLE if any(e.get("safety_interventions", {}).get("n")
                                           for e in board.aggregates[task].values()) else [])
    cols = ["#", "policy", "n"] + [c for _, c in table] + ["errors"]
    lines.append("| " + " | ".join(cols) + " |")
    lines.append("|" + "|".join("---" if i < 2 else "--:" for i in range(len(cols))) + "|")
    for i, pol in enumerate(board.ranking[task], 1):
        e = board.aggregates[task][pol]
        row = [str(i), pol, str(e["n"])] + [_cell(e[mname], mname) for mname, _ in table] + [str(e["errors"])]
        lines.append("| " + " | ".join(row) + " |")
    return lines + [""]


def _summary_section(summary: dict[str, Any]) -> list[str]:
    if not summary.get("policies"):
        return []
    refs = ", ".join(f"{s}: {r}" for s, r in summary["reference"].items())
    lines = ["## Across tasks", "",
             f"Normalised score per episode: 0 = {summary['floor']} (no thrust), 1 = the env's paper "
             f"controller, on mean {summary['metric'].upper()} (errored episodes score 0); IQM: "
             "interquartile mean of the pooled episode scores; P(improvement): probability that an "
             "episode scores higher than the paper controller's on the same task, averaged over "
             "tasks (ties half). [95 % stratified bootstrap intervals.] After rliable (Agarwal et "
             f"al., NeurIPS 2021). Paper controllers: {refs}.", "",
             "| policy | tasks | episodes | IQM normalised score | P(improvement over the paper's controller) |",
             "|---|--:|--:|--:|--:|"]
    order = sorted(summary["policies"].items(), key=lambda kv: -kv[1]["iqm"])
    for pol, e in order:
        lo, hi = e["iqm_ci95"]
        poi = "–" if e["p_improvement"] is None else \
            f"{e['p_improvement']:.2f} [{e['p_improvement_ci95'][0]:.2f}, {e['p_improvement_ci95'][1]:.2f}]"
        lines.append(f"| {pol} | {e['tasks']} | {e['episodes']} | {e['iqm']:.2f} [{lo:.2f}, {hi:.2f}] | {poi} |")
    if summary["skipped"]:
        lines += ["", "Left out of these aggregates: "
                  + "; ".join(f"{s} ({why})" for s, why in summary["skipped"].items()) + "."]
    return lines + [""]


def robustness(board: Board) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """``{task: {policy: {perturbation: {"n", "successes", "collision_episodes",
    "violation_episodes"}}}}`` (:func:`satenv.scoring.aggregate`'s counts) of the board's
    ``<task>@<perturbation>`` entries, with the nominal task as perturbation ``"nominal"`` when it
    is on the board."""
    perturbed = {s.partition("@")[0] for s in board.aggregates if "@" in s}
    groups: dict[str, dict[str, dict[str, list[dict[str, Any]]]]] = {}
    for rec in board.records:
        base, _, pert = rec["scenario"].partition("@")
        if base in perturbed:
            groups.setdefault(base, {}).setdefault(rec["policy"], {}).setdefault(pert or "nominal", []).append(rec)

    def cell(recs: list[dict[str, Any]]) -> dict[str, Any]:
        agg = scoring.aggregate(recs)
        return {"n": agg["episodes"], "successes": agg["successes"], "collision_episodes": agg["collision_episodes"],
                "violation_episodes": agg["violation_episodes"]}

    return {base: {pol: {pert: cell(recs) for pert, recs in perts.items()} for pol, perts in pols.items()}
            for base, pols in groups.items()}


def _robustness_section(board: Board) -> list[str]:
    table = robustness(board)
    if not table:
        return []
    lines = ["## Robustness: each task under its perturbations", "",
             "Per policy and perturbation (`satenv.perturbations`; navigation error is read by the "
             "policy, the controllers and a filter wrapped around the policy alike; the truth is "
             "scored): successes / episodes, then collision episodes and violation episodes. "
             "`nominal`: the task itself on the same board.", ""]
    for base, pols in table.items():
        perts = sorted({p for cells in pols.values() for p in cells}, key=lambda p: (p != "nominal", p))
        lines += [f"### `{base}`", "", "| policy | " + " | ".join(perts) + " |",
                  "|---|" + "--:|" * len(perts)]
        for pol, cells in sorted(pols.items()):
            row = [f"{c['successes']}/{c['n']} · {c['collision_episodes']} · {c['violation_episodes']}"
                   if (c := cells.get(p)) else "–" for p in perts]
            lines.append(f"| `{pol}` | " + " | ".join(row) + " |")
        lines.append("")
    return lines


def render_markdown(board: Board, plots: bool = True) -> str:
    """``scoreboard.md``: header, the headline (``plots``: with its figure), the aggregates across
    tasks, one ranked table per task, notes."""
    from satenv.bench.scoreboard.headline import headline_section

    lines = _preamble(board.header)
    lines += headline_section(board.headline, figure=plots)
    lines += _summary_section(board.summary)
    lines += _robustness_section(board)
    for task in board.aggregates:
        lines += _task_section(board, task)
    if board.notes:
        lines += ["## Notes", ""] + [f"- {n}" for n in board.notes] + [""]
    return "\n".join(lines)


def _write_json(board: Board) -> None:
    payload = {"header": board.header, "ranking": board.ranking, "aggregates": board.aggregates,
               "summary": board.summary, **({"headline": board.headline} if board.headline else {}),
               "episodes": [{k: v for k, v in r.items() if k != "traceback"} for r in board.records]}
    tmp = board.out / "scoreboard.json.tmp"
    tmp.write_text(json.dumps(jsonable(payload), indent=1, allow_nan=False))
    tmp.replace(board.out / "scoreboard.json")


def _write_csv(board: Board) -> None:
    with open(board.out / "scoreboard.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scenario", "rank", "policy", "n", "errors"]
                   + [f"{m}_{s}" for m in METRICS for s in ("mean", "ci95_lo", "ci95_hi", "n")])
        for task, order in board.ranking.items():
            for i, pol in enumerate(order, 1):
                e = board.aggregates[task][pol]
                w.writerow([task, i, pol, e["n"], e["errors"]]
                           + [v for m in METRICS for v in (e[m]["mean"], *e[m]["ci95"], e[m]["n"])])


def _write_episodes_csv(board: Board) -> None:
    fields = list(KEY) + ["env"] + list(METRICS) + [k for k in ("final_error_m", "terminated",
                                                                 "wall_s", "error") if k not in METRICS]
    with open(board.out / "episodes.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        for r in board.records:
            w.writerow(r)


def write_outputs(board: Board, plots: bool = True) -> None:
    """Write every output file of ``board`` into ``board.out``."""
    board.out.mkdir(parents=True, exist_ok=True)
    (board.out / "scoreboard.md").write_text(board.markdown)
    _write_json(board)
    _write_csv(board)
    _write_episodes_csv(board)
    if plots:
        try:
            write_plots(board)
        except Exception as exc:  # the tables are written; a plotting problem must not lose them
            print(f"warning: plots not written ({type(exc).__name__}: {exc})", file=sys.stderr)


_PLOT_LABELS = {  # metric -> axis label (with its unit) of its bar chart
    "success": "success rate (fraction of episodes)", "rmse": "RMSE [m]", "rmsee": "RMSEE [m/s²]",
    "foe": "FOE [m]", "delta_v": "Δv [m/s]", "time_to_converge_s": "t_conv [s] (converged episodes)",
    "min_separation_m": "min separation [m]", "collisions": "collision flags per episode",
    "violations": "constraint violations per episode", "compute_ms_per_decision": "act() wall time [ms]",
}


def policy_colors(names: Iterable[str]) -> dict[str, Any]:
    """One colour per policy, the same in every panel and figure of a board (up to 60 distinct:
    tab20, tab20b, tab20c; beyond that they repeat)."""
    from matplotlib import colormaps

    palette = [c for m in ("tab20", "tab20b", "tab20c") for c in colormaps[m].colors]
    return {n: palette[j % len(palette)] for j, n in enumerate(sorted(set(names)))}


def _bar_rows(board: Board, task: str, metric: str) -> list[tuple[str, float, float, float]]:
    """``(policy, mean, minus, plus)`` of ``task`` in ranked order, policies without a value left out."""
    rows = []
    for pol in board.ranking[task]:
        stat = board.aggregates[task][pol][metric]
        mean, (lo, hi) = stat["mean"], stat["ci95"]
        if mean is None or not math.isfinite(mean):
            continue
        rows.append((pol, mean, 0.0 if lo is None else max(0.0, mean - lo),
                     0.0 if hi is None else max(0.0, hi - mean)))
    return rows


def _metric_figure(board: Board, metric: str, path: Path, colors: dict[str, Any]) -> Path | None:
    """One panel per task with a value (own x scale), one horizontal bar per policy in ranked
    order, named on the axis and coloured as in every other panel; ``None`` when no task has a
    value (no empty figure is written)."""
    from satenv.render import new_figure

    panels = [(task, rows) for task in board.aggregates if (rows := _bar_rows(board, task, metric))]
    if not panels:
        path.unlink(missing_ok=True)
        return None
    ncols = min(2, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    heights = [max(len(r) for _, r in panels[i * ncols:(i + 1) * ncols]) for i in range(nrows)]
    fig = new_figure((6.4 * ncols, sum(0.22 * h + 0.9 for h in heights) + 0.6), 90, layout="constrained")
    grid = fig.add_gridspec(nrows, ncols, height_ratios=[0.22 * h + 0.9 for h in heights])
    for k, (task, rows) in enumerate(panels):
        ax = fig.add_subplot(grid[k // ncols, k % ncols])
        names = [r[0] for r in rows]
        bars = ax.barh(range(len(rows)), [r[1] for r in rows], xerr=[[r[2] for r in rows], [r[3] for r in rows]],
                       capsize=2, color=[colors[n] for n in names], ecolor="0.3")
        ax.bar_label(bars, fmt="%.3g", fontsize=6, padding=3)  # every value readable, zeros too
        top = max(r[1] + r[3] for r in rows)
        if min(r[1] - r[2] for r in rows) >= 0:  # a non-negative metric: the axis starts at 0
            ax.set_xlim(0, 1.18 * top if top > 0 else 1.0)
        ax.set_yticks(range(len(rows)), names, fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel(_PLOT_LABELS.get(metric, metric), fontsize=8)
        ax.tick_params(axis="x", labelsize=7)
        ax.set_title(task, fontsize=9)
    fig.suptitle(f"{_PLOT_LABELS.get(metric, metric)}: mean over seeds, 95 % interval", fontsize=10)
    fig.savefig(path)
    return path


def _trajectory_plots(board: Board, pdir: Path) -> list[Path]:
    from satenv.render import plot_trajectory
    from satenv.rollout import Trajectory

    written = []
    for npz in sorted((board.out / "trajectories").glob("*.npz")):
        task, pol, seed = npz.stem.split("__")
        try:
            traj = Trajectory.load(npz)
        except (OSError, ValueError, KeyError):
            continue
        written.append(plot_trajectory(traj, pdir / "trajectories" / f"{npz.stem}.png",
                                       title=f"{task} · {pol} · {seed}"))
    return written


def write_plots(board: Board) -> list[Path]:
    """Bar charts (mean with 95 % interval) per metric, and the example trajectories. Figures are
    drawn on their own canvas (:func:`satenv.render.new_figure`): the caller's matplotlib backend
    and pyplot state are left alone."""
    pdir = board.out / "plots"
    pdir.mkdir(parents=True, exist_ok=True)
    colors = policy_colors(p for s in board.aggregates for p in board.aggregates[s])
    written = [f for metric in _PLOTS if (f := _metric_figure(board, metric, pdir / f"{metric}.png", colors))]
    if board.summary.get("policies"):
        written.append(_summary_figure(board.summary, pdir / "summary.png", colors))
    if board.headline:
        from satenv.bench.scoreboard.headline import FIGURE, headline_figure

        written.append(headline_figure(board.headline, board.out / FIGURE))
    return written + _trajectory_plots(board, pdir)


def _summary_figure(summary: dict[str, Any], path: Path, colors: dict[str, Any]) -> Path:
    """IQM of the normalised score and P(improvement over the paper's controller), 95 % intervals,
    each policy in its board colour."""
    from satenv.render import new_figure

    order = sorted(summary["policies"].items(), key=lambda kv: kv[1]["iqm"])
    names = [p for p, _ in order]
    fig = new_figure((11, 0.3 * len(names) + 1.8), 90, layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for ax, key, label, ref in ((axes[0], "iqm", "IQM normalised score (0 = zero thrust, 1 = paper controller)", 1.0),
                                (axes[1], "p_improvement", "P(improvement over the paper's controller)", 0.5)):
        for y, (pol, e) in enumerate(order):
            if e[key] is None:
                continue
            lo, hi = e[f"{key}_ci95"]
            ax.errorbar(e[key], y, xerr=[[e[key] - lo], [hi - e[key]]], fmt="o", color=colors.get(pol, "k"),
                        capsize=3)
        ax.axvline(ref, color="k", ls="--", lw=0.8)
        ax.set_xlabel(label, fontsize=8)
        ax.tick_params(axis="x", labelsize=7)
        ax.set_yticks(range(len(names)), names, fontsize=7)
    fig.suptitle(f"across {len(summary['reference'])} tasks (95 % stratified bootstrap intervals)", fontsize=10)
    fig.savefig(path)
    return path


# ----------------------------------------------------------------------------------------------
# The header: where and how the board was made.
# ----------------------------------------------------------------------------------------------
def machine() -> dict[str, Any]:
    """CPU, core count, platform, Python and numpy versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"platform": platform.platform(), "cpu": cpu, "cpus": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__}


def git_revision() -> str | None:
    """Short git revision of the checkout (``-dirty`` with uncommitted changes), if any."""
    root = Path(__file__).resolve().parents[2]
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def satenv_version() -> str:
    try:
        import satenv

        return satenv.__version__
    except (ImportError, AttributeError):
        return "unknown"
