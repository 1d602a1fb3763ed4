"""What the safety filter (:mod:`satenv.safety`) achieves, on held-out seeds (>= 900000).

* ``random``: the random policy under the filter on every scoreboard scenario (every env family at
  its defaults and every randomised scenario; and formation_v0 with a 5 m separation, which its
  presets do not have), one episode per seed, all seeds as one
  ``make_vec`` batch: collision episodes, episodes with hard-constraint violations (the env's own
  ``violations`` info; formation_v0 counts graph cuts there, which the filter does not enforce),
  interventions, infeasible agent-steps, and *unsafe starts* (a collision or violation in the
  reset info, or the filter infeasible at the first decision), beside the same policy unfiltered.
* ``learned``: every shipped policy (``satenv/training/policies/*``, loaded by ``satenv.training.load``) on its
  first scoreboard scenario, filtered and unfiltered, through the scoreboard (success, collisions,
  violations, and the filter's columns).

    nice -n 10 python -m satenv.bench.safety_benchmark --out results/safety.json [--seeds 100]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np

from satenv.tasks import SEED_SPLITS

HELD_OUT = SEED_SPLITS["test"].start
"""First held-out seed: the test split of :data:`satenv.tasks.SEED_SPLITS`."""
SKIP = {"platoon-swarm256-ring-cw": "256 followers: the pairwise rows of 100 copies do not fit the "
                                    "benchmark's time budget (the filter itself handles them)"}


def _extra_scenarios() -> dict[str, Any]:
    """Scenarios beside the scoreboard's: formation_v0 with a separation to keep (its presets have
    ``collision_distance = 0``: no separation constraint at all)."""
    from satenv.bench.scoreboard.specs import TaskSpec

    return {"formation-kannan2022-position-random-sep5": TaskSpec(
        "formation-kannan2022-position-random-sep5", "formation_v0",
        {"preset": "kannan2022-position", "randomize": True, "collision_distance": 5.0},
        "kannan2022 §5.1, randomised starts, collision_distance = 5 m")}


def random_policy(scenario: Any, seeds: int, filtered: bool, base: int = HELD_OUT) -> dict[str, Any]:
    """One episode per seed ``base + b`` (copy ``b`` of a ``make_vec`` batch) of uniform random
    actions, filtered or not; the first episode of every copy is counted."""
    import satenv

    vec = satenv.make_vec(scenario.env_id, seeds, seed=base, safety_filter=filtered, **dict(scenario.kwargs))
    obs, info = vec.reset()
    unsafe = np.asarray(info["collision"]).any(axis=1) | (np.asarray(info["violations"]) > 0).any(axis=1)
    rng = np.random.default_rng(base)
    live = np.ones(seeds, dtype=bool)
    coll = np.zeros(seeds, dtype=bool)
    viol = np.zeros(seeds, dtype=bool)
    inter = np.zeros(seeds)
    infeas = np.zeros(seeds)
    first = True
    start = time.perf_counter()
    while live.any():
        _, _, term, trunc, infos = vec.step(rng.uniform(-1.0, 1.0, vec.action_shape))
        step_info = infos.get("final_info", infos)
        coll |= live & np.asarray(step_info["collision"]).any(axis=1)
        viol |= live & (np.asarray(step_info["violations"]) > 0).any(axis=1)
        if filtered:
            inter += live * infos["safety_intervened"].sum(axis=1)
            infeas += live * infos["safety_infeasible"].sum(axis=1)
            if first:
                unsafe |= infos["safety_infeasible"].any(axis=1)
        first = False
        live &= ~(term.any(axis=1) | trunc.any(axis=1))
    safe = ~unsafe
    return {"episodes": seeds, "unsafe_starts": int(unsafe.sum()),
            "collision_episodes": int(coll.sum()), "violation_episodes": int(viol.sum()),
            "collision_episodes_safe_starts": int((coll & safe).sum()),
            "violation_episodes_safe_starts": int((viol & safe).sum()),
            "interventions_per_episode": float(inter.mean()), "infeasible_agent_steps": int(infeas.sum()),
            "wall_s": time.perf_counter() - start}


def random_benchmark(seeds: int = 100, names: list[str] | None = None, log=print) -> dict[str, Any]:
    """:func:`random_policy` filtered and unfiltered on every scoreboard scenario (or ``names``)."""
    from satenv.bench.scoreboard.registry import TASKS

    out: dict[str, Any] = {}
    for name, spec in {**TASKS, **_extra_scenarios()}.items():
        if names is not None and name not in names:
            continue
        if name in SKIP:
            out[name] = {"skipped": SKIP[name]}
            continue
        res = {"env_id": spec.env_id, "filtered": random_policy(spec, seeds, True),
               "unfiltered": random_policy(spec, seeds, False)}
        f, u = res["filtered"], res["unfiltered"]
        log(f"{name}: filtered {f['collision_episodes']} collision / {f['violation_episodes']} violation "
            f"episodes of {seeds} (unsafe starts {f['unsafe_starts']}, infeasible agent-steps "
            f"{f['infeasible_agent_steps']}, {f['interventions_per_episode']:.1f} interventions/ep); "
            f"unfiltered {u['collision_episodes']} / {u['violation_episodes']}")
        out[name] = res
    return out


def learned_benchmark(seeds: int = 50, out_dir: str = "results/safety_learned", log=print,
                      names: list[str] | None = None) -> dict[str, Any]:
    """Every shipped policy (or ``names``) on its first scoreboard scenario, with and without the
    filter, on seeds ``HELD_OUT ... HELD_OUT + seeds - 1`` (the scoreboard's episodes and
    aggregates); a policy whose board fails is recorded with its error."""
    from satenv.bench.scoreboard.registry import discover_trained_policies

    res: dict[str, Any] = {}
    for name, spec in discover_trained_policies().items():
        if names is not None and name not in names:
            continue
        scen = spec.scenarios[0]
        try:
            res[name] = {"scenario": scen, **_learned_pair(name, scen, seeds, out_dir)}
        except Exception as exc:  # noqa: BLE001 - one policy's failure is a result, not the end
            res[name] = {"scenario": scen, "error": f"{type(exc).__name__}: {exc}"}
            log(f"{name} on {scen}: error {res[name]['error']}")
            continue
        f, u = res[name]["filtered"], res[name]["unfiltered"]
        log(f"{name} on {scen}: success {u['success']:.2f} -> {f['success']:.2f}; collision episodes "
            f"{u['collision_episodes']} -> {f['collision_episodes']}; violation episodes "
            f"{u['violation_episodes']} -> {f['violation_episodes']}; infeasible steps/ep {f['infeasible_steps']}")
    return res


def _learned_pair(name: str, scen: str, seeds: int, out_dir: str) -> dict[str, Any]:
    """``name`` and ``name+shield`` on ``scen`` through the scoreboard: their summary metrics."""
    from satenv.bench.scoreboard import run_scoreboard

    board = run_scoreboard(f"{out_dir}/{name.split(':')[1]}", scenarios=scen, policies=f"{name},{name}+shield",
                           seeds=f"{HELD_OUT}-{HELD_OUT + seeds - 1}", plots=False, progress=False, overwrite=True)
    agg = board.aggregates[scen]
    names = {"interventions": "safety_interventions", "mean_du": "safety_mean_du",
             "infeasible_steps": "safety_infeasible"}
    out = {}
    for pol in agg:
        out["filtered" if pol.endswith("+shield") else "unfiltered"] = {
            **{m: agg[pol][names.get(m, m)]["mean"] for m in ("success", "collisions", "violations", "interventions",
                                                              "mean_du", "infeasible_steps", "min_separation_m")},
            "collision_episodes": agg[pol]["collision_episodes"], "violation_episodes": agg[pol]["violation_episodes"]}
    return out


def main(argv: list[str] | None = None) -> int:
    from satenv.bench._env import single_thread_blas

    single_thread_blas()
    p = argparse.ArgumentParser(prog="python -m satenv.bench.safety_benchmark", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="results/safety.json")
    p.add_argument("--seeds", type=int, default=100, help="random-policy episodes per scenario")
    p.add_argument("--learned-seeds", type=int, default=50)
    p.add_argument("--parts", default="random,learned")
    p.add_argument("--scenarios", help="comma-separated scoreboard scenarios (random part)")
    p.add_argument("--policies", help="comma-separated shipped policies, e.g. trained:a (learned part)")
    args = p.parse_args(argv)
    parts = args.parts.split(",")
    result: dict[str, Any] = {"held_out_from": HELD_OUT}
    log = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    if "random" in parts:
        result["random"] = random_benchmark(args.seeds, args.scenarios.split(",") if args.scenarios else None, log)
    if "learned" in parts:
        result["learned"] = learned_benchmark(args.learned_seeds, log=log,
                                              names=args.policies.split(",") if args.policies else None)
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
