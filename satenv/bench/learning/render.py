"""The docs page "Reference results" (``docs/reference_results.md``) and its figures, rendered
from ``results.json`` alone (:func:`render_page` is a pure function of the file: a test checks
that the committed page equals it).

Statistics are rliable's (Agarwal et al. 2021), written with numpy: the interquartile mean (IQM,
:func:`iqm`) of the runs' scores and its 95 % percentile interval by the stratified bootstrap
(:func:`iqm_ci`: the runs of each task resampled with replacement, independently per task).
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring, tasks
from satenv.bench.learning import grid as G

__all__ = ["ASSETS", "PAGE", "SOLVED_MIN_SEEDS", "iqm", "iqm_ci", "read_manifest", "render_page", "write_figures",
           "write_page"]

ROOT = Path(__file__).resolve().parents[3]
PAGE = ROOT / "docs" / "reference_results.md"
ASSETS = ROOT / "docs" / "assets" / "reference_results"
BOOTSTRAP_REPS = 2000
"""Bootstrap resamples of each interval (seeded: the page is reproducible)."""
SOLVED_MIN_SEEDS = 5
"""A rung is solved by a row when its mean test success is at least ``scoring.SUCCESS_MIN`` over at
least this many training seeds (the target: "some standard RL algorithm reaches mean test success
>= 0.9 over >= 5 training seeds")."""
UPPER_RUNG_MIN = 0.5
"""The cluster and servicing target on a rung above the first: success >= 0.5."""
LABELS = {"ppo": "PPO (lean)", "ippo": "IPPO (lean)", "mappo": "MAPPO (lean)", "ppo_lag": "PPO-Lagrangian (lean)",
          "masac": "MASAC (BenchMARL)", "dagger": "DAgger of the expert"}
LATE_DROP = 0.5
"""A run's late drop: its last checkpoint's test success at least this far below its published
(selected) checkpoint's, i.e. half the test seeds lost by training on."""
FAILURE_LABELS = {"timeout": "timeout", "left_region": "left", "collision": "collision", "violation": "violation"}


def iqm(scores: Any) -> float:
    """Interquartile mean of every score (rliable's ``scipy.stats.trim_mean(x, 0.25, axis=None)``:
    ``int(n / 4)`` scores cut at each end of the sorted scores, the rest averaged)."""
    x = np.sort(np.asarray(scores, dtype=float).ravel())
    k = int(0.25 * x.size)
    return float(x[k:x.size - k].mean())


def iqm_ci(scores: Any, reps: int = BOOTSTRAP_REPS, seed: int = 0) -> tuple[float, float, float]:
    """IQM of ``scores`` ``(runs,)`` or ``(runs, tasks)`` and its 95 % stratified-bootstrap interval
    (percentile): each resample draws ``runs`` runs with replacement from each task's column,
    independently per task, and takes the IQM of all the drawn scores."""
    s = np.asarray(scores, dtype=float)
    s = s[:, None] if s.ndim == 1 else s
    runs, n_tasks = s.shape
    idx = np.random.default_rng(seed).integers(0, runs, size=(reps, runs, n_tasks))
    boot = np.sort(np.take_along_axis(np.broadcast_to(s, (reps, runs, n_tasks)), idx, axis=1).reshape(reps, -1), axis=1)
    k = int(0.25 * boot.shape[1])
    stats = boot[:, k:boot.shape[1] - k].mean(axis=1)
    return iqm(s), float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


Group = tuple[str, bool, int]
"""A row of the page: algorithm, filter in training, and the budget when it is not the grid's (else 0)."""


def _longer(rec: dict[str, Any]) -> int:
    if rec["algorithm"] not in G.RL_ALGORITHMS:
        return 0
    run = G.Run(rec["system"], rec["algorithm"], rec["filter"], budget_override=int(rec.get("budget_agent_steps") or 0))
    return run.budget if run.longer else 0


def _groups(results: dict[str, Any]) -> dict[str, dict[Group, dict[int, list[dict[str, Any]]]]]:
    """system -> row -> rung -> the row's runs on that rung."""
    out: dict[str, Any] = defaultdict(lambda: defaultdict(lambda: defaultdict(list)))
    for rec in results["records"]:
        out[rec["system"]][(rec["algorithm"], rec["filter"], _longer(rec))][rec["rung"]].append(rec)
    return out


def _order(group: Group) -> tuple[int, bool, int]:
    return G.ALGORITHMS.index(group[0]), group[1], group[2]


def _label(algo: str, filtered: bool, budget: int = 0) -> str:
    return (LABELS.get(algo, algo) + (" + filter in training" if filtered else "")
            + (f", {budget:,} agent-steps" if budget else ""))


def _successes(recs: list[dict[str, Any]]) -> np.ndarray:
    return np.array([r["test"]["success_rate"] for r in recs], dtype=float)


def _solved(recs: list[dict[str, Any]]) -> bool:
    return len(recs) >= SOLVED_MIN_SEEDS and float(_successes(recs).mean()) >= scoring.SUCCESS_MIN


def _cell(recs: list[dict[str, Any]] | None) -> str:
    if not recs:
        return "–"
    mid, lo, hi = iqm_ci(_successes(recs))
    mark = " **solved**" if _solved(recs) else ""
    return f"{mid:.2f} [{lo:.2f}, {hi:.2f}] ({len(recs)}){mark}"


def _seeds(recs: list[dict[str, Any]]) -> str:
    return tasks.show_seeds(sorted(r["seed"] for r in recs))


def _failures(recs: list[dict[str, Any]]) -> str:
    total = {m: sum(r["test"]["failure_modes"][m] for r in recs) for m in scoring.FAILURE_MODES}
    shown = [f"{FAILURE_LABELS[m]} {n}" for m, n in total.items() if n]
    return ", ".join(shown) if shown else "none"


def _late_drops(results: dict[str, Any]) -> str:
    """How many learning runs ended far below the checkpoint validation picked (:data:`LATE_DROP`);
    ``results["records"]`` holds the learning runs only (the controllers are ``results["controllers"]``)."""
    runs = results["records"]
    drops = [r for r in runs if r["test"]["success_rate"] - r["last_test"]["success_rate"] >= LATE_DROP]
    below = [r for r in runs if r["last_test"]["success_rate"] < r["test"]["success_rate"]]
    return (f"Training success is not monotone at these budgets: of the {len(runs)} learning runs on this page, "
            f"{len(below)} ended below their published checkpoint's test success and {len(drops)} at least "
            f"{LATE_DROP:.1f} below it (half the test seeds lost by training on).")


def _per_seed(recs: list[dict[str, Any]]) -> str:
    """Each seed's published success, with the failure modes of a seed below the success bar and,
    where validation picked an earlier checkpoint, which one and the last checkpoint's success."""
    out = []
    for r in sorted(recs, key=lambda r: r["seed"]):
        cell = f"{r['seed']}: {r['test']['success_rate']:.2f}"
        if r["selected_checkpoint"] != len(r["curve"]) - 1:
            cell += f" [checkpoint {r['selected_checkpoint'] + 1}; last {r['last_test']['success_rate']:.2f}]"
        if r["test"]["success_rate"] < scoring.SUCCESS_MIN:
            cell += f" ({_failures([r])})"
        out.append(cell)
    return "; ".join(out)


def _detail_row(group: Group, rung: int, recs: list[dict[str, Any]]) -> str:
    t = [r["test"] for r in recs]
    n_eps = sum(x["episodes"] for x in t)
    mid, lo, hi = iqm_ci(_successes(recs))
    cmd = recs[0]["command"].replace(f"--seeds {recs[0]['seed']}", f"--seeds {_seeds(recs)}")
    steps = sorted({r["agent_steps"] for r in recs})
    return (f"| {rung} | {_label(*group)} | {len(recs)} | {_successes(recs).mean():.2f} | "
            f"{mid:.2f} [{lo:.2f}, {hi:.2f}] | "
            f"{sum(x['collision_episodes'] for x in t)}/{n_eps} | {sum(x['violation_episodes'] for x in t)}/{n_eps} | "
            f"{_failures(recs)} | {_per_seed(recs)} | {'/'.join(f'{s:,}' for s in steps)} | "
            f"{np.mean([r['wall_s'] for r in recs]):.0f} | "
            f"`{cmd}` |")


def _load_note(results: dict[str, Any]) -> str:
    loads = [r["load_avg_1m"] for r in results["records"] if r.get("load_avg_1m") is not None]
    if not loads:
        return "on two CPU cores shared with other jobs"
    return (f"on two CPU cores shared with other jobs (1-minute load average {min(loads):.0f}-{max(loads):.0f} "
            "at the checkpoints): compare algorithms by their budgets, not by this column")


def _rates(results: dict[str, Any]) -> list[str]:
    """Measured training speed per system and algorithm (agent-steps per second of training wall
    time, median over runs) and what the default grid costs at it."""
    speed: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in results["records"]:
        if r["algorithm"] in G.RL_ALGORITHMS and r.get("wall_s"):
            speed[(r["system"], r["algorithm"])].append(r["agent_steps"] / r["wall_s"])
    if not speed:
        return []
    lines = ["Measured training speed (agent-steps per second of training wall time, median over the runs, "
             "one worker under `nice` on the shared cores) and the training minutes one run of the grid's budget "
             "takes at it:",
             "",
             "| system | algorithm | runs | agent-steps/s | minutes per run at the grid's budget |",
             "|---|---|---|---|---|"]
    for (system, algo), v in sorted(speed.items(), key=lambda kv: (list(tasks.SYSTEMS).index(kv[0][0]),
                                                                  G.ALGORITHMS.index(kv[0][1]))):
        rate = float(np.median(v))
        budget = (results["grid"]["masac_budget_agent_steps"] if algo == "masac"
                  else results["grid"]["budget_agent_steps"][system])
        minutes = budget / rate / 60
        lines.append(f"| {system} | {LABELS[algo]} | {len(v)} | {rate:,.0f} | {minutes:.1f} |")
    return lines + [""]


def _solved_rungs(groups: dict[Group, dict[int, list[dict[str, Any]]]],
                  standard: tuple[str, ...]) -> dict[int, list[str]]:
    out: dict[int, list[str]] = defaultdict(list)
    for group, rungs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        if group[0] in standard and not group[1]:
            for rung, recs in rungs.items():
                if _solved(recs):
                    out[rung].append(_label(*group))
    return out


def _targets(results: dict[str, Any], groups: dict[str, Any]) -> list[str]:
    """The targets, each with its measured number (best row) or 'not run yet'."""
    lines = ["## Targets", "",
             f"Rule: a row solves a rung when its mean test success over >= {SOLVED_MIN_SEEDS} training seeds is "
             f">= {scoring.SUCCESS_MIN} (`satenv.scoring.SUCCESS_MIN`); standard RL = "
             f"{', '.join(LABELS[a] for a in G.STANDARD_RL)}; constrained RL = {LABELS['ppo_lag']}.", "",
             "| target | measured (best row: mean success over its seeds) | met |", "|---|---|---|"]

    def best(system: str, rung: int, algos: tuple[str, ...]) -> tuple[float, str, int] | None:
        found = [(float(_successes(recs).mean()), _label(*g), len(recs))
                 for g, rungs in groups.get(system, {}).items() if g[0] in algos and not g[1]
                 for r, recs in rungs.items() if r == rung]
        return max(found) if found else None

    for name, sysdef in tasks.SYSTEMS.items():
        ladder = results["grid"]["ladders"][name]
        checks = [(f"{sysdef.label}: standard RL solves rung 1 ({ladder[0]})", 1, G.STANDARD_RL, scoring.SUCCESS_MIN)]
        if name == "platoon-pereira2023":
            checks.append((f"{sysdef.label}: standard RL solves the training task ({ladder[-1]})", len(ladder),
                           G.STANDARD_RL, scoring.SUCCESS_MIN))
        if name in ("cluster-li2022", "servicing-pereira2022"):
            for rung in range(2, len(ladder) + 1):
                checks.append((f"{sysdef.label}: standard or constrained RL >= {UPPER_RUNG_MIN} on rung {rung} "
                               f"({ladder[rung - 1]})", rung, (*G.STANDARD_RL, "ppo_lag"), UPPER_RUNG_MIN))
        for text, rung, algos, bar in checks:
            b = best(name, rung, algos)
            if b is None:
                lines.append(f"| {text} | not run yet | – |")
                continue
            met = b[0] >= bar and b[2] >= SOLVED_MIN_SEEDS
            lines.append(f"| {text} | {b[0]:.2f} ({b[1]}, {b[2]} seed{'s' if b[2] > 1 else ''}) | "
                         f"{'yes' if met else 'no'} |")
    lines += ["", "Success along each ladder (mean success of the best standard-RL row per rung; the target: it falls "
              "from rung 1 to the last rung):", ""]
    for name, sysdef in tasks.SYSTEMS.items():
        ladder = results["grid"]["ladders"][name]
        vals = []
        for rung in range(1, len(ladder) + 1):
            b = best(name, rung, G.STANDARD_RL)
            vals.append("–" if b is None else f"{b[0]:.2f}")
        known = [float(v) for v in vals if v != "–"]
        verdict = ("not measured on every rung yet" if len(known) < len(ladder)
                   else "falls" if all(a >= b for a, b in zip(known, known[1:], strict=False)) and known[0] > known[-1]
                   else "does not fall")
        lines.append(f"- {sysdef.label}: {' -> '.join(vals)} ({verdict})")
    return lines + [""]


def _says(system: str, groups: dict[Group, dict[int, list[dict[str, Any]]]], n_rungs: int) -> str:
    solved = _solved_rungs(groups, G.STANDARD_RL)
    if not groups:
        return "No RL run complete yet."
    parts = []
    for rung in range(1, n_rungs + 1):
        if rung in solved:
            parts.append(f"rung {rung}: solved by {', '.join(solved[rung])}")
        elif any(rung in r for r in groups.values()):
            parts.append(f"rung {rung}: not solved by standard RL at the budgets run")
        else:
            parts.append(f"rung {rung}: not run yet")
    return "Standard RL: " + "; ".join(parts) + "."


def _controller_cell(ctrl: dict[str, Any] | None) -> str:
    """The controller's test success on a rung, with how its episodes failed below the success bar."""
    if not ctrl:
        return "not run yet"
    test = ctrl["test"]
    modes = f"; {_failures([ctrl])}" if test["success_rate"] < scoring.SUCCESS_MIN else ""
    return f"{test['success_rate']:.2f} ({test['episodes']} seeds{modes})"


def _system_section(name: str, results: dict[str, Any],
                    groups: dict[Group, dict[int, list[dict[str, Any]]]]) -> list[str]:
    sysdef = tasks.SYSTEMS[name]
    ladder = results["grid"]["ladders"][name]
    lines = [f"## {sysdef.label}", "",
             f"Controller `{sysdef.controller}`, expert `{sysdef.expert}`. Ladder (easiest first; "
             "the last rung is the training task):", "",
             "| rung | task | what it changes | controller success (test seeds) |",
             "|---|---|---|---|"]
    for k, task in enumerate(ladder, start=1):
        lines.append(f"| {k} | `{task}` | {tasks.get(task).description} | "
                     f"{_controller_cell(results['controllers'].get(task))} |")
    lines += ["", _says(name, groups, len(ladder)), ""]
    if not groups:
        return lines
    lines += [f"![learning curves, {sysdef.label}](assets/reference_results/{name}.png)", "",
              "Final test success per rung: IQM over training seeds [95 % stratified-bootstrap interval] (seeds); "
              "**solved**: mean success >= 0.9 over >= 5 seeds.", "",
              "| algorithm | " + " | ".join(f"rung {k}" for k in range(1, len(ladder) + 1)) + " |",
              "|---" * (len(ladder) + 1) + "|"]
    for group, rungs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        lines.append(f"| {_label(*group)} | "
                     + " | ".join(_cell(rungs.get(k)) for k in range(1, len(ladder) + 1)) + " |")
    lines += ["", "| rung | algorithm | seeds | success (mean) | success IQM [95 % CI] | collision episodes | "
              "violation episodes | failure modes (episodes) | per seed: success (failure modes of a seed below 0.9) | "
              "agent-steps (labels) | train wall [s] | command |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for group, rungs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
        for rung in sorted(rungs):
            lines.append(_detail_row(group, rung, rungs[rung]))
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
    budgets = ", ".join(f"{s}: {b:,}" for s, b in g["budget_agent_steps"].items())
    lines = [
        "# Reference results",
        "",
        "What standard learning algorithms reach on every rung of each paper system's **ladder** "
        "(`satenv.tasks.ladder(system)`: easiest first, ending at the system's training task), next to the "
        "system's controller: learning curves and final test results, every number from "
        "`studies/reference_results/results.json`, rendered by `satenv results render --update-published` "
        "from that file alone.",
        "",
        "## Protocol",
        "",
        f"- **Budget**: the grid's budget is the same number of agent-steps for every RL algorithm and rung of a "
        f"system ({budgets}); DAgger gets expert labels instead "
        f"({', '.join(f'{s}: {b:,}' for s, b in g['dagger_labels'].items())}). A row labelled with a number of "
        "agent-steps ran at that budget instead (`--budget`), everything else the same: the first table of the "
        "grid was run at 3,000,000 agent-steps to have numbers within minutes. The cluster and servicing get the "
        "same budget: the lean loop steps them at the same order of agent-steps per second as the platoon "
        "(measured, table below), so 10 M agent-steps is as far "
        "as five seeds of every lean row on every rung go in a few days of one shared worker. MASAC's budget is "
        f"{g['masac_budget_agent_steps']:,} agent-steps on every rung: it keeps the standard update-to-data ratio "
        f"({g['masac_utd']} gradient steps per frame, of {g['masac_batch']} frames each, BenchMARL's "
        "standard off-policy batch), and at that ratio a BenchMARL gradient step costs about 6 ms here "
        "(measured on the TPLF platoon's first rung, `satenv.bench.learning.grid.MASAC_BUDGET_AGENT_STEPS`): "
        "10 M agent-steps would take about an hour per run, 30 hours per rung of five seeds on the six systems.",
        "- **Smoke tests**: the earlier grid of this page (SB3 PPO, BenchMARL MAPPO and MASAC at 200,000 "
        "agent-steps, 3 seeds, 5 test seeds, on the training tasks only) was a smoke test of the pipeline, not a "
        "result; its log is kept in `studies/reference_results/smoke_200k_log.jsonl` and is not on this page.",
        "- **Former rungs**: the platoons' second rungs first drew their starts within 10 m of the targets; the "
        "runs on them are kept in `studies/reference_results/former_rungs_log.jsonl` and are not on this page "
        "(`docs/tasks.md`, Ladders, says why the rung moved).",
        "- **Learner defaults**: the lean learner's first defaults (observations by running statistics, 2 epochs of "
        "4,096-agent-step minibatches) left the section 5.1 platoon's first rung at 0/20 on validation seeds, its "
        "policies drifting hundreds of metres; its current ones (the envs' own fixed observation scales, 10 epochs "
        "of 1,024) solved it there (module docstring of `satenv.training.rl.ppo`). Every row on this page ran at "
        "the current defaults; the grid under the first ones is kept in "
        "`studies/reference_results/running_obs_norm_log.jsonl` and is not on this page. The first cells at the "
        "current defaults ran with the training reward's earlier flat in-tolerance bonus (`satenv.rewards`: the "
        "policies drifted to the tolerance's edge late in training); their log is "
        "`studies/reference_results/flat_bonus_log.jsonl`, not on this page. The cells run before the "
        "checkpoint selection on validation seeds (each published at its last checkpoint) are kept in "
        "`studies/reference_results/last_checkpoint_log.jsonl`, not on this page.",
        f"- **Evaluations**: {g['checkpoints']} per run, evenly spaced over the budget. Each flies the "
        f"deterministic policy on the rung's first {g['curve_test_seeds']} test seeds (the curves; the last "
        f"one on its first {g['final_test_seeds']}) and on its first {g['validation_seeds']} validation seeds. "
        "The published result is the checkpoint with the most validation successes (then the fewest "
        "collision or violation episodes, then the latest: early stopping on validation seeds, "
        "`satenv.bench.learning.grid.select_checkpoint`), flown on the first "
        f"{g['final_test_seeds']} test seeds; where it is not the last checkpoint, the per-seed column names "
        f"it and gives the last checkpoint's success. {_late_drops(results)} No test seed chose "
        "anything: the learners run at their defaults (the lean learner's own on every task; the tuned "
        "configurations beside them, chosen on validation seeds, are not used by the grid).",
        f"- **Seeds**: training seeds {tasks.show_seeds(g['default_seeds'])} per row; the tables say how many "
        "have run.",
        f"- **Statistics**: IQM of the final success over training seeds with its 95 % stratified-bootstrap "
        f"interval ({BOOTSTRAP_REPS} resamples, percentile), rliable's method written with numpy "
        "(`satenv.bench.learning.render.iqm_ci`); the curves show the IQM and its interval at each evaluation.",
        "- **Algorithms**: the lean batched learner `satenv.training.rl` (`satenv ppo`, the grid's default "
        "trainer) as PPO (shared parameters), IPPO (per-agent parameters) and MAPPO (centralised critic), and as "
        "**PPO-Lagrangian** (constrained RL: a dual variable on the episode `safety_cost` against the task's "
        "`cost_budget`, `--lagrangian`); BenchMARL **MASAC** with "
        f"{g['masac_utd']} gradient steps per frame; DAgger of the system's expert (`satenv imitate`, one round "
        "per checkpoint); and PPO once more with the **safety filter in the training env** "
        "(`task.make_env(safety_filter=True)`, the filter's defaults) on the cluster, servicing and §5.1 "
        "platoon, evaluated behind the filter, as trained.",
        "- **Failure modes** of each failed test episode (`satenv.scoring.failure_mode`, the first that applies): "
        "collision, violation (a hard bound), left (ended early without either: an agent left the region), "
        "timeout (reached the horizon outside the tolerance).",
        f"- **Wall time**: training only (evaluations excluded), mean over seeds, {_load_note(results)}.",
        "",
        "Run, resume (the log is kill-safe; the same command skips what is logged) and render:",
        "",
        "```bash",
        "nohup studies/reference_results/run_all.sh > studies/reference_results/run_all.out 2>&1 &  "
        "# cheapest cells first",
        "satenv results results --update-published   # studies/reference_results/log.jsonl -> results.json",
        "satenv results render --update-published    # results.json -> this page and its figures",
        "```",
        "",
        *_rates(results),
        *_targets(results, groups),
    ]
    for name in tasks.SYSTEMS:
        lines += _system_section(name, results, groups.get(name, {}))
    lines += _datasets_section(datasets or {})
    lines += ["## Not complete yet", ""]
    from satenv.bench.learning.results import run_key

    complete = {run_key(r) for r in results["records"]}
    errors = [e for e in results["errors"] if run_key(e) not in complete]
    missing = results["incomplete"] + [
        {**e, "checkpoints_logged": "none (the run crashed: " + e["error"].split(" (")[0][:80] + ")"}
        for e in errors]
    if not missing and not results.get("not_run"):
        lines.append("Every run of the grid is complete.")
    if missing:
        lines += ["Runs with checkpoints missing (the resume command above completes them):", ""]
        lines += [f"- {m['task']} / "
                  + (_label(m["algorithm"], m["filter"], _longer(m)) if m["algorithm"] != "controller"
                     else "controller")
                  + f" / seed {m['seed']}: checkpoints logged {m['checkpoints_logged']}" for m in missing] + [""]
    if results.get("not_run"):
        lines += [f"Runs of the grid at its budgets not run yet ({sum(results['not_run'].values())}; the resume "
                  "command above runs them), per rung:", ""]
        lines += [f"- `{t}`: {n}" for t, n in results["not_run"].items()]
    lines.append("")
    return "\n".join(lines)


def write_figures(results: dict[str, Any], folder: Path = ASSETS) -> list[Path]:
    """One learning-curve figure per system, a panel per rung: success rate on the test seeds (IQM
    and 95 % stratified-bootstrap band over training seeds) against agent-steps for the RL rows; the
    rung's controller as a horizontal line (DAgger, counted in expert labels, is in the tables)."""
    from matplotlib.ticker import EngFormatter

    from satenv.render import new_figure

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    groups_of = _groups(results)
    for name in set(tasks.SYSTEMS) - set(groups_of):   # no figure for a system without runs
        (folder / f"{name}.png").unlink(missing_ok=True)
    for name, groups in groups_of.items():
        ladder = results["grid"]["ladders"][name]
        fig = new_figure(figsize=(4.6 * len(ladder), 3.6), dpi=80)
        axes = fig.subplots(1, len(ladder), squeeze=False)[0]
        for k, (ax, task) in enumerate(zip(axes, ladder, strict=True), start=1):
            for (algo, filtered, budget), rungs in sorted(groups.items(), key=lambda kv: _order(kv[0])):
                if algo == "dagger" or k not in rungs:
                    continue
                curves = np.array([r["curve"] for r in rungs[k]], dtype=float)   # seeds x checkpoints x 4
                x = np.median(curves[:, :, 0], axis=0)
                band = np.array([iqm_ci(curves[:, j, 1]) for j in range(curves.shape[1])])
                line, = ax.plot(x, band[:, 0], "o-", ms=3, label=_label(algo, filtered, budget))
                ax.fill_between(x, band[:, 1], band[:, 2], color=line.get_color(), alpha=0.2)
            if not any(k in rungs for rungs in groups.values()):
                ax.set_xticks([])
                ax.text(0.5, 0.5, "not run yet", ha="center", va="center", transform=ax.transAxes)
            ctrl = results["controllers"].get(task)
            if ctrl:
                ax.axhline(ctrl["test"]["success_rate"], color="k", ls="--", lw=1,
                           label=f"controller {ctrl['controller']}")
            ax.set_title(f"rung {k}: {task}", fontsize=8)
            ax.set_xlabel("agent-steps")
            ax.xaxis.set_major_formatter(EngFormatter(sep=" "))
            ax.set_ylabel("success rate (test seeds)")
            ax.set_ylim(-0.05, 1.05)
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7)
        fig.suptitle(f"{tasks.SYSTEMS[name].label}: IQM over training seeds, 95 % stratified-bootstrap band")
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
