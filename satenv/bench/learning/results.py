"""``results.json`` from the evaluation log: one record per complete run, the controllers, the grid.

A run is complete when every one of its checkpoints is logged; its record has

* ``system``, ``task`` (the ladder rung it trained and was tested on), ``rung`` (1: the easiest),
  ``algorithm``, ``filter`` (trained with the safety filter), ``seed``;
* ``budget_agent_steps`` (agent-steps, or expert labels for DAgger) and ``agent_steps`` (what was
  run, whole collection rounds or episodes);
* ``wall_s``: training wall time (evaluations excluded) on the machine that ran it;
* ``curve``: ``[agent_steps, success_rate, mean_return, collision_episodes]`` per checkpoint, on
  the run's test seeds (the final point on all of them);
* ``test``: the selected checkpoint's (the published result: the checkpoint the validation seeds
  picked, :func:`satenv.bench.learning.grid.select_checkpoint`) :func:`satenv.scoring.aggregate`
  fields on the final test seeds (success, collision and violation episodes, RMSE, delta-v,
  interventions per agent-step when filtered), the count of each failure mode
  (:data:`satenv.scoring.FAILURE_MODES`) and the RMSE and delta-v ratios to the rung's controller
  on matched episodes (:func:`satenv.scoring.matched_ratios`);
* ``selected_checkpoint`` (0-based) and ``validation_success`` (per checkpoint, the validation
  seeds' success rate); ``last_test``: the same fields as ``test`` for the last checkpoint;
* ``command``: the command that reproduces it.

Controllers are keyed by task. Runs with some checkpoints missing are listed in ``incomplete``
(with what they have), crashed runs in ``errors``; ``not_run`` counts, per task, the runs of the
default grid (:data:`~satenv.bench.learning.grid.DEFAULT_SEEDS`, the grid's budgets) with nothing
logged yet.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring, tasks
from satenv.bench.learning import grid as G

__all__ = ["build_results", "command", "run_key", "write_results"]

TEST_FIELDS = ("episodes", "success_rate", "collision_episodes", "violation_episodes", "safe_success_rate",
               "rmse", "delta_v", "final_error_m", "compute_ms_per_agent", "interventions_per_agent_step")


def command(system: str, rung: int, algorithm: str, filtered: bool, seeds: str, budget: int = 0) -> str:
    """The command that runs one row (a filtered row runs with its unfiltered twin; a run at another
    budget than the grid's says ``--budget``)."""
    extra = ""
    if algorithm != "controller":
        extra = f" --filter-systems {system}" if filtered else " --filter-systems ''"
    if budget and G.Run(system, algorithm, filtered, budget_override=budget).longer:
        extra += f" --budget {budget}"
    return f"satenv results run --systems {system} --rungs {rung} --algorithms {algorithm} --seeds {seeds}{extra}"


def _round(x: Any, nd: int = 4) -> Any:
    return None if x is None else (round(float(x), nd) if isinstance(x, (float, np.floating)) else x)


def _agents(task: str) -> int:
    return len(tasks.get(task).make_env().possible_agents)


def _with_agent_steps(episodes: list[dict[str, Any]], n_agents: int) -> list[dict[str, Any]]:
    """Episodes logged before ``safety_agent_steps`` was kept: the filter's decisions x agents
    (:func:`satenv.scoring.episode_record`'s rule)."""
    return [{**e, "safety_agent_steps": e["safety_steps"] * n_agents}
            if "safety_steps" in e and "safety_agent_steps" not in e else e for e in episodes]


def failure_modes(episodes: list[dict[str, Any]]) -> dict[str, int]:
    """How many episodes failed by each :data:`satenv.scoring.FAILURE_MODES` entry."""
    counts = Counter(e.get("failure_mode", scoring.failure_mode(e)) for e in episodes)
    return {mode: counts.get(mode, 0) for mode in scoring.FAILURE_MODES}


def _test_block(episodes: list[dict[str, Any]], ref: list[dict[str, Any]] | None, n_agents: int) -> dict[str, Any]:
    agg = scoring.aggregate(_with_agent_steps(episodes, n_agents))
    out = {k: _round(agg.get(k)) for k in TEST_FIELDS if k in agg}
    out["failure_modes"] = failure_modes(episodes)
    if ref:
        out.update({k: _round(v) for k, v in scoring.matched_ratios(episodes, ref).items()})
    return out


def _point(rec: dict[str, Any]) -> list[Any]:
    """A curve point (``grid.curve_fields``): the :func:`satenv.scoring.aggregate` of one checkpoint."""
    agg = scoring.aggregate(rec["episodes"])
    return [int(rec["agent_steps"]), _round(agg["success_rate"]), _round(agg["episode_return"], 3),
            int(agg["collision_episodes"])]


def run_key(rec: dict[str, Any]) -> tuple[Any, ...]:
    """One run of a results or error record: task, algorithm, filter, seed and budget."""
    return (rec["task"], rec["algorithm"], rec["filter"], rec["seed"], rec.get("budget_agent_steps"))


def _run(system: str, task: str, algo: str, filtered: bool, seed: int, budget: int) -> G.Run:
    return G.Run(system, algo, filtered, seed, budget_override=budget if algo in G.RL_ALGORITHMS else 0, rung=task)


def build_results(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The ``results.json`` data of the log ``records``."""
    runs: dict[tuple, dict[int, dict[str, Any]]] = defaultdict(dict)
    errors = []
    for rec in records:
        if rec.get("error") is not None:
            errors.append({k: rec.get(k) for k in ("system", "task", "rung", "algorithm", "filter", "seed",
                                                   "budget_agent_steps", "error")})
            continue
        runs[(rec["system"], rec["task"], rec["algorithm"], rec["filter"], rec["seed"],
              int(rec["budget_agent_steps"]))][rec["checkpoint"]] = rec
    controllers, reference = {}, {}
    for (system, task, algo, _, _, _), cps in runs.items():
        if algo == "controller" and 0 in cps:
            rec = cps[0]
            reference[task] = rec["episodes"]
            controllers[task] = {"system": system, "rung": rec["rung"], "controller": tasks.system(system).controller,
                                 "test_seeds": rec["test_seeds"],
                                 "test": _test_block(rec["episodes"], None, _agents(task)),
                                 "mean_return": _point(rec)[2], "eval_s": rec.get("eval_s"),
                                 "command": command(system, rec["rung"], "controller", False, "0")}
    out, incomplete = [], []
    order = {s: i for i, s in enumerate(tasks.SYSTEMS)}
    for key in sorted(runs, key=lambda k: (order[k[0]], tasks.ladder(k[0]).index(k[1]), G.ALGORITHMS.index(k[2]),
                                           k[3], k[5], k[4])):
        system, task, algo, filtered, seed, budget = key
        if algo == "controller":
            continue
        cps = runs[key]
        run = _run(system, task, algo, filtered, seed, budget)
        n = len(run.checkpoints)
        if any(k not in cps for k in run.records):
            incomplete.append({"system": system, "task": task, "rung": run.rung_index, "algorithm": algo,
                               "filter": filtered, "seed": seed, "budget_agent_steps": budget,
                               "checkpoints_logged": sorted(cps)})
            continue
        last, chosen = cps[n - 1], cps[run.selected_index]
        ref = reference.get(task)
        val = [cps[k]["validation"] for k in range(n)]
        out.append({"system": system, "task": task, "rung": run.rung_index, "algorithm": algo, "filter": filtered,
                    "seed": seed, "budget_agent_steps": int(last["budget_agent_steps"]),
                    "agent_steps": int(last["agent_steps"]), "wall_s": _round(last["wall_s"], 1),
                    "test_seeds": last["test_seeds"], "load_avg_1m": last.get("load_avg_1m"),
                    "curve": [_point(cps[k]) for k in range(n)],
                    "test": _test_block(chosen["episodes"], ref, _agents(task)),
                    "selected_checkpoint": int(chosen["selected_checkpoint"]),
                    "validation_success": [_round(v["success"] / len(v["seeds"])) for v in val],
                    "last_test": _test_block(last["episodes"], ref, _agents(task)),
                    "command": command(system, run.rung_index, algo, filtered, str(seed), budget)})
    seen = {run_key(r) for r in (*out, *incomplete, *errors)} | {(t, "controller", False, 0, 0) for t in controllers}
    not_run: Counter[str] = Counter()
    for r in G.grid(tasks.SYSTEMS, G.DEFAULT_ALGORITHMS, G.DEFAULT_SEEDS):
        if (r.task.name, r.algorithm, r.filter, r.seed, r.budget) not in seen:
            not_run[r.task.name] += 1
    return {"grid": {"checkpoints": G.CHECKPOINTS, "curve_test_seeds": G.CURVE_TEST_SEEDS,
                     "final_test_seeds": G.FINAL_TEST_SEEDS,
                     "validation_seeds": G.VALIDATION_SEEDS, "budget_agent_steps": G.BUDGET_AGENT_STEPS,
                     "dagger_labels": G.DAGGER_LABELS, "masac_utd": G.MASAC_UTD, "masac_batch": G.MASAC_BATCH,
                     "masac_budget_agent_steps": G.MASAC_BUDGET_AGENT_STEPS,
                     "default_seeds": list(G.DEFAULT_SEEDS),
                     "ladders": {s: list(tasks.ladder(s)) for s in tasks.SYSTEMS},
                     "curve_fields": ["agent_steps", "success_rate", "mean_return", "collision_episodes"]},
            "controllers": controllers, "records": out, "incomplete": incomplete, "errors": errors,
            "not_run": dict(not_run)}


def write_results(log: Path, out: Path) -> Path:
    """Write ``results.json`` from the log (sorted keys, stable order: a re-run changes only what changed)."""
    from satenv.bench.learning.runner import read_log
    from satenv.training import runfolder

    return runfolder.write_json(out, build_results(read_log(log)), sort_keys=True)   # whole or absent
