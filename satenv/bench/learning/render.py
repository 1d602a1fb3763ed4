"""The docs page "Reference results" (``docs/reference_results.md``) and its figures, rendered
from ``results.json`` alone (:func:`render_page` is a pure function of the file: a test checks
that the committed page equals it).

Learning curves: per algorithm, the interquartile mean (IQM) of the success rate over seeds at
each checkpoint, with a 95 % stratified bootstrap interval over seeds (one task per figure, so
the stratified bootstrap resamples the seeds; :func:`iqm_band`, the estimator of rliable, with
numpy and scipy: rliable's ``arch`` dependency does not import with this project's pandas).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring, tasks
from satenv.bench.learning import grid as G

__all__ = ["ASSETS", "PAGE", "iqm", "iqm_band", "read_manifest", "render_page", "write_figures", "write_page"]

ROOT = Path(__file__).resolve().parents[3]
PAGE = ROOT / "docs" / "reference_results.md"
ASSETS = ROOT / "docs" / "assets" / "reference_results"
BOOTSTRAP_REPS = 2000
"""Bootstrap resamples of each interval (seeded: the figures are reproducible)."""
LABELS = {"ppo": "PPO (SB3)", "mappo": "MAPPO (BenchMARL)", "ippo": "IPPO (BenchMARL)",
          "masac": "MASAC (BenchMARL)", "isac": "ISAC (BenchMARL)", "dagger": "DAgger of the expert"}


def iqm(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Interquartile mean (the mean of the middle 50 %, ``scipy.stats.trim_mean(x, 0.25)``)."""
    from scipy import stats

    return stats.trim_mean(x, 0.25, axis=axis)


def iqm_band(scores: np.ndarray, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IQM over seeds of ``scores`` ``(seeds, checkpoints)`` and its 95 % bootstrap interval
    (percentile; seeds resampled with replacement, the same resample for every checkpoint)."""
    scores = np.asarray(scores, dtype=float)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, scores.shape[0], size=(reps, scores.shape[0]))
    boot = np.stack([iqm(scores[i]) for i in idx])
    return iqm(scores), np.percentile(boot, 2.5, axis=0), np.percentile(boot, 97.5, axis=0)


Group = tuple[str, bool, int]
"""A row of the page: algorithm, filter in training, and the budget when it is not the grid's (else 0)."""


def _longer(rec: dict[str, Any]) -> int:
    run = G.Run(rec["system"], rec["algorithm"], rec["filter"], rec["seed"],
                budget_override=int(rec.get("budget_agent_steps") or 0))
    return run.budget if run.longer else 0


def _groups(results: dict[str, Any]) -> dict[str, dict[Group, list[dict[str, Any]]]]:
    out: dict[str, dict[Group, list[dict[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for rec in results["records"]:
        out[rec["system"]][(rec["algorithm"], rec["filter"], _longer(rec))].append(rec)
    return out


def _order(group: Group) -> tuple[int, bool, int]:
    return G.ALGORITHMS.index(group[0]), group[1], group[2]


def _label(algo: str, filtered: bool, budget: int = 0) -> str:
    return (LABELS[algo] + (" + filter in training" if filtered else "")
            + (f", {budget:,} agent-steps" if budget else ""))


def _fmt(x: Any, nd: int = 2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return f"{x:.{nd}f}" if isinstance(x, float) else str(x)


def _final_row(label: str, recs: list[dict[str, Any]], n_test: int) -> str:
    t = [r["test"] for r in recs]
    succ = [x["success_rate"] for x in t]

    def mean(key: str, nd: int = 2) -> str:
        vals = [x[key] for x in t if x.get(key) is not None]
        return _fmt(float(np.mean(vals)), nd) if vals else "–"

    steps = sorted({r["agent_steps"] for r in recs})
    cmd = recs[0]["command"].replace(f"--seeds {recs[0]['seed']}", f"--seeds {_seeds(recs)}")
    return (f"| {label} | {len(recs)} | {np.mean(succ):.2f} [{min(succ):.1f}, {max(succ):.1f}] | "
            f"{sum(x['collision_episodes'] for x in t)}/{n_test * len(recs)} | "
            f"{sum(x['violation_episodes'] for x in t)}/{n_test * len(recs)} | {mean('rmse_ratio')} | "
            f"{mean('delta_v_ratio')} | {mean('interventions_per_agent_step', 3)} | "
            f"{'/'.join(f'{s:,}' for s in steps)} | {np.mean([r['wall_s'] for r in recs]):.0f} | `{cmd}` |")


def _seeds(recs: list[dict[str, Any]]) -> str:
    return tasks.show_seeds(sorted(r["seed"] for r in recs))


def _load_note(results: dict[str, Any]) -> str:
    loads = [r["load_avg_1m"] for r in results["records"] if r.get("load_avg_1m") is not None]
    if not loads:
        return "on two CPU cores shared with other jobs"
    spread = max((max(w) / min(w) for rows in _groups(results).values() for recs in rows.values()
                  if len(w := [r["wall_s"] for r in recs if r.get("wall_s")]) > 1), default=1.0)
    return (f"on two CPU cores shared with other jobs (1-minute load average {min(loads):.0f}-{max(loads):.0f} "
            f"at the checkpoints); the seeds of one row differ by up to {spread:.0f}x with the load and the run's "
            "share of the CPU, so compare algorithms by their budgets, not by this column")


def _says(system: str, groups: dict[Group, list[dict[str, Any]]], ctrl: dict[str, Any] | None) -> str:
    """What the curves say, from the numbers (the rule is written on the page)."""
    learned, partial, none = [], [], []
    for group, recs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        finals = np.array([r["test"]["success_rate"] for r in recs])
        label = _label(*group)
        if iqm(finals) >= scoring.SUCCESS_MIN:
            learned.append(label)
        elif finals.max() > 0:
            partial.append(f"{label} (final success IQM {iqm(finals):.2f}, best seed {finals.max():.2f})")
        else:
            none.append(label)
    parts = []
    if ctrl:
        parts.append(f"The controller ({ctrl['controller']}) succeeds on "
                     f"{ctrl['test']['success_rate']:.2f} of the test seeds.")
    parts.append("Reaches the success bar at the budget: " + (", ".join(learned) if learned else "none") + ".")
    if partial:
        parts.append("Some success, below the bar: " + "; ".join(partial) + ".")
    if none:
        parts.append("No success on any seed at the budget: " + ", ".join(none) + ".")
    return " ".join(parts)


def _summary(results: dict[str, Any], groups: dict[str, Any]) -> list[str]:
    """Final success per system and row: IQM over seeds (number of seeds)."""
    cols = sorted({g for s in tasks.SYSTEMS for g in groups.get(s, {})}, key=_order)
    lines = ["## Summary", "",
             "Final test success rate per system (IQM over seeds, number of seeds in brackets; `–`: not run "
             "yet). The sections below have the curves, every test metric and the commands.", "",
             "| system | controller | " + " | ".join(_label(*g) for g in cols) + " |",
             "|---" * (len(cols) + 2) + "|"]
    for name, sysdef in tasks.SYSTEMS.items():
        ctrl = results["controllers"].get(name)
        cells = [f"{ctrl['test']['success_rate']:.2f}" if ctrl else "–"]
        for key in cols:
            recs = groups.get(name, {}).get(key)
            cells.append(f"{iqm(np.array([r['test']['success_rate'] for r in recs])):.2f} ({len(recs)})"
                         if recs else "–")
        lines.append(f"| {sysdef.label} | " + " | ".join(cells) + " |")
    return lines + [""]


def _datasets_section(manifest: dict[str, Any]) -> list[str]:
    lines = ["## Demonstration datasets (Minari)", "",
             "Each system's controller flying its training task on train seeds, recorded through the "
             "centralised Gymnasium view `satenv/<Env>-v0` and written in Minari's format "
             "(`satenv.bench.learning.datasets`; the layout of the multi-agent data is in each dataset's "
             "description, its card). The datasets are not in git; one command writes them into Minari's "
             "folder (`--root` or `MINARI_DATASETS_PATH`) and reads them back with `minari.load_dataset`:",
             "", "```bash",
             "python -m satenv.bench.learning.datasets write --systems all --episodes 50",
             "python -m satenv.bench.learning.datasets read --systems all",
             "```", "",
             "Layout: observation = every agent's observation concatenated in `possible_agents` order, action = "
             "their normalised actions concatenated, reward = team sum; infos per agent: `collision`, "
             "`violations`, `cost`, `min_separation`, `delta_v`, `tracking_error`, and `state` (the env's full "
             "state; `reset(seed=episode seed)` and the recorded actions replay it exactly, with the controller "
             "reset after the env as in the recording: the cluster's tube-RDMPC also acts inside the env, its "
             "tube controller correcting the action at every physics step (`env.set_inner_loop`), and the "
             "recorded actions are its decision-rate commands without that correction; "
             "`satenv.bench.learning.datasets.replay` attaches it).", "",
             "| system | dataset id | train seeds | episodes | steps (agent-steps) | collision / violation episodes | "
             "written in [s] |", "|---|---|---|---|---|---|---|"]
    for name in tasks.SYSTEMS:
        e = manifest.get(name)
        if e is None:
            lines.append(f"| {name} | not generated yet | – | – | – | – | – |")
        else:
            lines.append(f"| {name} | `{e['dataset_id']}` | {e['train_seeds']} | {e['episodes']} | {e['steps']:,} "
                         f"({e['agent_steps']:,}) | {e['collision_episodes']} / {e['violation_episodes']} | "
                         f"{e['wall_s']:.0f} |")
    return lines + [""]


def render_page(results: dict[str, Any], datasets: dict[str, Any] | None = None) -> str:
    """The markdown of the page (a pure function of ``results`` and the datasets' manifest)."""
    g = results["grid"]
    groups = _groups(results)
    n_test = g["test_seeds_per_checkpoint"]
    lines = [
        "# Reference results",
        "",
        "What standard algorithms reach on each paper system's **training task** (randomised starts, "
        "`satenv.tasks`) at a fixed, small budget, next to the system's controller: "
        "learning curves and final test results, every number from "
        "`studies/reference_results/results.json`, rendered by "
        "`python -m satenv.bench.learning render` from that file alone.",
        "",
        "## Protocol",
        "",
        f"- **Budget**: the same number of agent-steps for every RL algorithm of a task "
        f"({', '.join(f'{s}: {b:,}' for s, b in g['budget_agent_steps'].items())}); DAgger gets expert "
        f"labels instead ({', '.join(f'{s}: {b:,}' for s, b in g['dagger_labels'].items())}). The "
        "budgets were sized for two shared CPU cores, not for convergence: a row that does not learn "
        "here may learn with more. A row labelled with a number of agent-steps ran at that longer budget "
        "(`--budget`), on the systems and algorithms where it was run, with everything else the same.",
        f"- **Checkpoints**: {g['checkpoints']} evaluations per run, evenly spaced over the budget "
        "(RL budgets are rounded up to whole collection rounds; the agent-steps actually run are in the "
        "table). Each evaluation flies the deterministic policy on the task's **first "
        f"{n_test} test seeds** (900000-{900000 + n_test - 1}); the controller flies the same seeds. "
        "The last checkpoint is the test result.",
        "- **Seeds**: training seeds 0-2 per row (the table's `seeds` column says how many have run); "
        "curves show the interquartile mean (IQM) over seeds and its 95 % stratified bootstrap interval "
        f"(seeds resampled, {BOOTSTRAP_REPS} resamples): rliable's estimator, computed with numpy and "
        "scipy (rliable's `arch` dependency does not import beside this project's pandas).",
        f"- **Wall time**: training only (evaluations excluded), mean over seeds, {_load_note(results)}.",
        "- **Algorithms**, each at its trainer's documented defaults plus the fast configuration "
        "(`satenv.bench.perf.learning.FAST_CONFIGS`, [Training](training.md#fast-configurations)): "
        "SB3 PPO with parameter sharing (`satenv.training.train`), BenchMARL MAPPO and MASAC "
        "(`satenv.training.benchmarl_train`), DAgger of the system's expert (`satenv imitate`, "
        "one round per checkpoint), and PPO once more with the **safety filter in the training env** "
        f"(`satenv.make(..., safety_filter=SafetyConfig(penalty={g['filter_penalty']}))`: the filter "
        "corrects every action and the reward pays for each unit of correction) on the cluster, "
        "servicing and §5.1 platoon; that row is evaluated behind the filter, as trained.",
        "- **Success bar** (the sentence under each figure): final success IQM over seeds >= "
        f"{scoring.SUCCESS_MIN} (`satenv.scoring.SUCCESS_MIN`).",
        "- **Ratios**: RMSE and Δv over the controller's, on matched completed episodes "
        "(`satenv.scoring.matched_ratios`), mean over seeds; `–` where no episode matched.",
        "",
        "Run, resume (the log is kill-safe; the same command skips what is logged) and render:",
        "",
        "```bash",
        "nohup studies/reference_results/run_all.sh &  # the whole grid, breadth first; run it again to resume",
        "python -m satenv.bench.learning results   # studies/reference_results/log.jsonl -> results.json",
        "python -m satenv.bench.learning render    # results.json -> this page and its figures",
        "```",
        "",
        "`--backend ray --address HOST:PORT` runs the grid on a Ray cluster (the scoreboard's backends).",
        "",
        *_summary(results, groups),
    ]
    for name, sysdef in tasks.SYSTEMS.items():
        task = tasks.get(sysdef.training_task)
        ctrl = results["controllers"].get(name)
        lines += [f"## {sysdef.label}", "",
                  f"Training task `{task.name}` ({task.description}); controller `{sysdef.controller}`, "
                  f"expert `{sysdef.expert}`.", ""]
        if name not in groups and not ctrl:
            lines += ["Not run yet.", ""]
            continue
        lines += [f"![learning curves, {sysdef.label}](assets/reference_results/{name}.png)", "",
                  _says(name, groups.get(name, {}), ctrl), "",
                  "| algorithm | seeds | success (mean [min, max]) | collision episodes | violation episodes | "
                  "RMSE ratio | Δv ratio | interventions / agent-step | agent-steps (labels) | train wall [s] | command |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        if ctrl:
            t = ctrl["test"]
            lines.append(f"| controller `{ctrl['controller']}` | – | {t['success_rate']:.2f} | "
                         f"{t['collision_episodes']}/{t['episodes']} | {t['violation_episodes']}/{t['episodes']} | "
                         f"1 | 1 | – | – | – | `{ctrl['command']}` |")
        for group, recs in sorted(groups.get(name, {}).items(), key=lambda kv: _order(kv[0])):
            lines.append(_final_row(_label(*group), recs, n_test))
        lines.append("")
    lines += _datasets_section(datasets or {})
    lines += ["## Not complete yet", ""]
    from satenv.bench.learning.results import run_key

    complete = {run_key(r) for r in results["records"]}
    errors = [e for e in results["errors"] if run_key(e) not in complete]
    missing = results["incomplete"] + [{**e, "checkpoints_logged": "none (the run crashed: " + e["error"].split(" (")[0][:80] + ")"}
                                       for e in errors]
    if not missing and not results.get("not_run"):
        lines.append("Every run of the grid is complete.")
    if missing:
        lines += ["Runs with checkpoints missing (the resume command above completes them):", ""]
        lines += [f"- {m['system']} / {_label(m['algorithm'], m['filter'], _longer(m)) if m['algorithm'] != 'controller' else 'controller'}"
                  f" / seed {m['seed']}: checkpoints logged {m['checkpoints_logged']}" for m in missing] + [""]
    if results.get("not_run"):
        by: dict[str, list[str]] = defaultdict(list)
        for r in results["not_run"]:
            name = "controller" if r["algorithm"] == "controller" else _label(r["algorithm"], r["filter"])
            by[r["system"]].append(f"{name} seed {r['seed']}")
        lines += [f"Not run yet ({len(results['not_run'])} runs of the grid; the resume command above runs them):", ""]
        lines += [f"- {s}: {', '.join(v)}" for s, v in by.items()]
    lines.append("")
    return "\n".join(lines)


def write_figures(results: dict[str, Any], folder: Path = ASSETS) -> list[Path]:
    """One learning-curve figure per system: success rate (IQM and 95 % band over seeds) and mean
    return against agent-steps for the RL rows; DAgger against expert labels; the controller as a
    horizontal line."""
    from matplotlib.ticker import EngFormatter

    from satenv.render import new_figure

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, groups in _groups(results).items():
        ctrl = results["controllers"].get(name)
        fig = new_figure(figsize=(14, 3.8), dpi=80)
        axes = fig.subplots(1, 3)
        for (algo, filtered, budget), recs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
            curves = np.array([r["curve"] for r in recs], dtype=float)    # seeds x checkpoints x 4
            x = np.median(curves[:, :, 0], axis=0)
            panels = [(axes[2], 1)] if algo == "dagger" else [(axes[0], 1), (axes[1], 2)]
            for ax, col in panels:
                mid, lo, hi = iqm_band(curves[:, :, col])
                line, = ax.plot(x, mid, "o-", ms=3, label=_label(algo, filtered, budget))
                ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
        if ctrl:
            for ax, value in ((axes[0], ctrl["test"]["success_rate"]), (axes[1], ctrl["mean_return"]),
                              (axes[2], ctrl["test"]["success_rate"])):
                ax.axhline(value, color="k", ls="--", lw=1, label=f"controller {ctrl['controller']}")
        for ax, ylabel, xlabel in ((axes[0], "success rate (test seeds)", "agent-steps"),
                                   (axes[1], "mean episode return", "agent-steps"),
                                   (axes[2], "success rate (test seeds)", "expert labels (DAgger)")):
            ax.set_xlabel(xlabel)
            ax.xaxis.set_major_formatter(EngFormatter(sep=" "))
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
        for ax in (axes[0], axes[2]):
            ax.set_ylim(-0.05, 1.05)
        if not any(group[0] == "dagger" for group in groups):
            axes[2].set_xticks([])
            axes[2].text(0.5, 0.5, "DAgger: not run yet", ha="center", va="center", transform=axes[2].transAxes)
        fig.suptitle(f"{tasks.SYSTEMS[name].label}: IQM over seeds, 95 % bootstrap band")
        fig.tight_layout()
        path = folder / f"{name}.png"
        fig.savefig(path)
        paths.append(path)
    return paths


def read_manifest(path: Path) -> dict[str, Any]:
    """The datasets' manifest (``satenv/bench/learning/datasets.json``), empty when absent."""
    return json.loads(path.read_text()) if path.is_file() else {}


def write_page(results_path: Path, page: Path = PAGE, assets: Path = ASSETS, manifest: Path | None = None) -> Path:
    """Render the page and the figures from ``results_path`` (and the datasets' manifest)."""
    from satenv.bench.learning.datasets import MANIFEST

    results = json.loads(results_path.read_text())
    write_figures(results, assets)
    page.write_text(render_page(results, read_manifest(MANIFEST if manifest is None else manifest)))
    return page
