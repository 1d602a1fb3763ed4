"""``results.json`` from the evaluation log: one record per complete run, the controllers, the grid.

A run is complete when every one of its checkpoints is logged; its record has

* ``system``, ``task``, ``algorithm``, ``filter`` (trained with the safety filter), ``seed``;
* ``budget_agent_steps`` (the grid's budget: agent-steps, or expert labels for DAgger) and
  ``agent_steps`` (what was run, whole collection rounds or episodes);
* ``wall_s``: training wall time (evaluations excluded) on the machine that ran it;
* ``curve``: ``[agent_steps, success_rate, mean_return, collision_episodes]`` per checkpoint, on
  the run's test seeds;
* ``test``: the last checkpoint's :func:`satenv.scoring.aggregate` fields (success, collision
  and violation episodes, RMSE, delta-v, interventions per agent-step when filtered) and the RMSE
  and delta-v ratios to the controller on matched episodes (:func:`satenv.scoring.matched_ratios`);
* ``command``: the command that reproduces it.

Runs with some checkpoints missing are listed in ``incomplete`` (with what they have), crashed
runs in ``errors``, the runs of the default grid (:data:`~satenv.bench.learning.grid.DEFAULT_SEEDS`)
with nothing logged yet in ``not_run``.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from satenv import scoring, tasks
from satenv.bench.learning import grid as G

__all__ = ["build_results", "command", "run_key", "write_results"]

TEST_FIELDS = ("episodes", "success_rate", "collision_episodes", "violation_episodes", "safe_success_rate",
               "rmse", "delta_v", "final_error_m", "compute_ms_per_agent", "interventions_per_agent_step")


def command(system: str, algorithm: str, filtered: bool, seed: int, budget: int = 0) -> str:
    """The command that reproduces one row (a filtered row runs with its unfiltered twin; an RL row
    at another budget than the grid's says ``--budget``)."""
    filt = f" --filter-systems {system}" if filtered else " --filter-systems ''"
    if algorithm == "controller":
        filt = ""
    if budget and G.Run(system, algorithm, filtered, seed, budget_override=budget).longer:
        filt += f" --budget {budget}"
    return (f"python -m satenv.bench.learning run --systems {system} --algorithms {algorithm} --seeds {seed}"
            f"{filt}")


def _round(x: Any, nd: int = 4) -> Any:
    return None if x is None else (round(float(x), nd) if isinstance(x, (float, np.floating)) else x)


def _agents(system: str) -> int:
    return len(tasks.training_task(system).make_env().possible_agents)


def _with_agent_steps(episodes: list[dict[str, Any]], n_agents: int) -> list[dict[str, Any]]:
    """Episodes logged before ``safety_agent_steps`` was kept: the filter's decisions x agents
    (:func:`satenv.scoring.episode_record`'s rule)."""
    return [{**e, "safety_agent_steps": e["safety_steps"] * n_agents}
            if "safety_steps" in e and "safety_agent_steps" not in e else e for e in episodes]


def _test_block(episodes: list[dict[str, Any]], ref: list[dict[str, Any]] | None, n_agents: int) -> dict[str, Any]:
    agg = scoring.aggregate(_with_agent_steps(episodes, n_agents))
    out = {k: _round(agg.get(k)) for k in TEST_FIELDS if k in agg}
    if ref:
        out.update({k: _round(v) for k, v in scoring.matched_ratios(episodes, ref).items()})
    return out


def _point(rec: dict[str, Any]) -> list[Any]:
    """A curve point (``grid.curve_fields``): the :func:`satenv.scoring.aggregate` of one checkpoint."""
    agg = scoring.aggregate(rec["episodes"])
    return [int(rec["agent_steps"]), _round(agg["success_rate"]), _round(agg["episode_return"], 3),
            int(agg["collision_episodes"])]


def run_key(rec: dict[str, Any]) -> tuple[Any, ...]:
    """One run of a results or error record: system, algorithm, filter, seed and budget."""
    return (rec["system"], rec["algorithm"], rec["filter"], rec["seed"], rec.get("budget_agent_steps"))


def build_results(records: list[dict[str, Any]]) -> dict[str, Any]:
    """The ``results.json`` data of the log ``records``."""
    runs: dict[tuple, dict[int, dict[str, Any]]] = defaultdict(dict)
    errors = []
    for rec in records:
        if rec.get("error") is not None:
            errors.append({k: rec.get(k) for k in ("system", "algorithm", "filter", "seed", "budget_agent_steps",
                                                   "error")})
            continue
        runs[(rec["system"], rec["algorithm"], rec["filter"], rec["seed"], int(rec["budget_agent_steps"]))][
            rec["checkpoint"]] = rec
    controllers = {}
    for (system, algo, _, _, _), cps in runs.items():
        if algo == "controller" and 0 in cps:
            rec = cps[0]
            controllers[system] = {"controller": tasks.system(system).controller, "task": rec["task"],
                                   "test_seeds": rec["test_seeds"], "test": _test_block(rec["episodes"], None, _agents(system)),
                                   "mean_return": _point(rec)[2], "eval_s": rec.get("eval_s"),
                                   "command": command(system, "controller", False, 0)}
    out, incomplete = [], []
    order = {s: i for i, s in enumerate(tasks.SYSTEMS)}
    for key in sorted(runs, key=lambda k: (order[k[0]], G.ALGORITHMS.index(k[1]), k[2], k[4], k[3])):
        system, algo, filtered, seed, budget = key
        if algo == "controller":
            continue
        cps = runs[key]
        n = len(G.Run(system, algo, filtered, seed, budget_override=budget).checkpoints)
        if any(k not in cps for k in range(n)):
            incomplete.append({"system": system, "algorithm": algo, "filter": filtered, "seed": seed,
                               "budget_agent_steps": budget, "checkpoints_logged": sorted(cps)})
            continue
        last = cps[n - 1]
        ref = None
        for r in records:
            if r.get("error") is None and r["system"] == system and r["algorithm"] == "controller":
                ref = r["episodes"]
                break
        out.append({"system": system, "task": last["task"], "algorithm": algo, "filter": filtered, "seed": seed,
                    "budget_agent_steps": int(last["budget_agent_steps"]), "agent_steps": int(last["agent_steps"]),
                    "wall_s": _round(last["wall_s"], 1), "test_seeds": last["test_seeds"],
                    "load_avg_1m": last.get("load_avg_1m"),
                    "curve": [_point(cps[k]) for k in range(n)], "test": _test_block(last["episodes"], ref, _agents(system)),
                    "command": command(system, algo, filtered, seed, budget)})
    seen = {run_key(r) for r in (*out, *incomplete, *errors)} | {(s, "controller", False, 0, 0) for s in controllers}
    not_run = [r.to_json() for r in G.grid(tasks.SYSTEMS, G.DEFAULT_ALGORITHMS, G.DEFAULT_SEEDS)
               if (r.system, r.algorithm, r.filter, r.seed, r.budget) not in seen]
    return {"grid": {"checkpoints": G.CHECKPOINTS, "test_seeds_per_checkpoint": G.TEST_SEEDS_PER_CHECKPOINT,
                     "budget_agent_steps": G.BUDGET_AGENT_STEPS, "dagger_labels": G.DAGGER_LABELS,
                     "filter_penalty": G.FILTER_PENALTY,
                     "curve_fields": ["agent_steps", "success_rate", "mean_return", "collision_episodes"]},
            "controllers": controllers, "records": out, "incomplete": incomplete, "errors": errors,
            "not_run": not_run}


def write_results(log: Path, out: Path) -> Path:
    """Write ``results.json`` from the log (sorted keys, stable order: a re-run changes only what changed)."""
    from satenv.bench.learning.runner import read_log
    from satenv.training import runfolder

    return runfolder.write_json(out, build_results(read_log(log)), sort_keys=True)   # whole or absent
