"""Held-out evaluation against issue 27's targets: a policy folder beside the system's controller.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m training.recipes.heldout \\
        --system platoon-pereira2022 --policy training/policies/<name> --out eval_heldout.json

On the system's randomised scoreboard scenario (``--seeds``, default 900000-900049: seeds no
training run, validation or selection of issue 27 touches) and on the paper's own start, it runs
the learned policy, the same policy behind the safety filter (``satenv.safety.shield``) and the
controller of the scenario (``--controller``), and checks the targets: success >= 90 % and >= the
controller's minus 5 points, 0 collision episodes, 0 hard-constraint violations, RMSE and delta-v
<= 1.5x the controller's on *matched, completed* episodes (seeds where neither episode ended early
nor collided), a decision <= 1 ms per agent.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from satenv.metrics import matched_ratios  # the one home of the matched-episode rule
from training.recipes.dagger import SYSTEMS

__all__ = ["evaluate_policies", "targets", "main"]

CONTROLLERS = {"platoon-pereira2022": "dmpc", "cluster-case1": "tube_rdmpc",
               "formation-kannan2022-collision": "cgmres", "platoon-tplf30": "dmpc",
               "servicing-pereira2022": "nmpc"}
"""The scenario's controller (the comparator of issue 27) per system."""


def episodes(env, policy, seeds) -> list[dict[str, Any]]:
    from satenv import metrics
    from satenv.rollout import rollout

    out = []
    for s in seeds:
        e = metrics.summary(rollout(env, policy, seed=int(s)))
        e["seed"] = int(s)
        e["compute_ms_per_agent"] = e["compute_ms_per_decision"] / len(env.possible_agents)
        info = getattr(policy, "info", {}) or {}
        for key in ("safety_interventions", "safety_infeasible", "safety_steps"):
            if key in info:
                e[key] = int(info[key])
        out.append(e)
    return out


def aggregate(eps: list[dict[str, Any]]) -> dict[str, Any]:
    def mean(k):
        return float(np.mean([e[k] for e in eps]))

    agg = {"episodes": len(eps), "success_rate": mean("success"),
           "collision_episodes": int(sum(e["collisions"] > 0 for e in eps)),
           "violation_episodes": int(sum(e["violations"] > 0 for e in eps)),
           "violations": mean("violations"), "terminated": int(sum(e["terminated"] for e in eps)),
           "rmse": mean("rmse"), "delta_v": mean("delta_v"), "final_error_m": mean("final_error_m"),
           "min_separation_m": float(min(e["min_separation_m"] for e in eps)),
           "compute_ms_per_agent": mean("compute_ms_per_agent")}
    if "safety_interventions" in eps[0]:
        agg["safety_interventions"] = int(sum(e["safety_interventions"] for e in eps))
        agg["safety_infeasible"] = int(sum(e.get("safety_infeasible", 0) for e in eps))
    return agg


def targets(agg: dict[str, Any], ref: dict[str, Any], ratios: dict[str, Any]) -> dict[str, bool]:
    from training.card import ISSUE27_SUCCESS_MARGIN, RATIO_LIMIT, SUCCESS_MIN

    return {"success": agg["success_rate"] >= SUCCESS_MIN
            and agg["success_rate"] >= ref["success_rate"] - ISSUE27_SUCCESS_MARGIN - 1e-12,
            "no_collisions": agg["collision_episodes"] == 0,
            "no_violations": agg["violation_episodes"] == 0,
            "rmse": ratios.get("rmse_ratio", np.inf) <= RATIO_LIMIT,
            "delta_v": ratios.get("delta_v_ratio", np.inf) <= RATIO_LIMIT,
            "decision_1ms": agg["compute_ms_per_agent"] <= 1.0}


def evaluate_policies(system: str, folder: Path, seeds: list[int], paper_seeds: list[int],
                      controller: str | None, shield: bool = True,
                      controller_seeds: list[int] | None = None,
                      controller_episodes: dict[str, list[dict[str, Any]]] | None = None) -> dict[str, Any]:
    import baselines
    import satenv
    import training
    from satenv.safety import Shield
    from satenv.safety import shield as make_shield

    sysdef = SYSTEMS[system]
    result: dict[str, Any] = {"system": system, "policy": str(folder), "seeds": [seeds[0], seeds[-1]],
                              "paper_seeds": paper_seeds, "controller": controller,
                              "controller_seeds": controller_seeds}
    for label, kwargs, ss in (("random", sysdef.scenario, seeds), ("paper", sysdef.paper, paper_seeds)):
        env = satenv.make(sysdef.env_id, **kwargs)
        net = training.load(folder, env=env, shielded=False)
        runs = {"learned": net}
        if shield:   # as training.load ships a filtered folder (its own options), else the default filter
            shipped = training.load(folder, env=env)
            runs["learned+shield"] = shipped if isinstance(shipped, Shield) else make_shield(shipped, env)
        if controller:
            runs[controller] = baselines.make(controller, env)
        block: dict[str, Any] = {"env_kwargs": dict(kwargs)}
        eps = {}
        for name, pol in runs.items():
            t0 = time.perf_counter()
            if name == controller and controller_episodes and label in controller_episodes:
                eps[name] = [e for e in controller_episodes[label] if e["seed"] in ss]   # run before
            elif name == controller and controller_seeds is not None and label == "random":
                eps[name] = episodes(env, pol, [x for x in ss if x in controller_seeds])
            else:
                eps[name] = episodes(env, pol, ss)
            block[name] = {"aggregate": aggregate(eps[name]), "wall_s": round(time.perf_counter() - t0, 1),
                           "episodes": eps[name]}
            print(label, name, json.dumps(block[name]["aggregate"]), flush=True)
        if controller:
            ref = block[controller]["aggregate"]
            for name in runs:
                if name == controller:
                    continue
                r = matched_ratios(eps[name], eps[controller])
                block[name]["ratios"] = r
                block[name]["targets"] = targets(block[name]["aggregate"], ref, r)
        result[label] = block
    return result


def card_fields(result: dict[str, Any], shipped: str = "learned") -> dict[str, Any]:
    """The keys ``training.card`` reads (``aggregate``, ``vs_<REF>``, ``test_seeds``) for the
    randomised scenario. ``learned`` is the network alone (``training.load(folder, shielded=False)``),
    ``learned+shield`` the network behind the filter (what a folder shipped with it loads as); ratios on matched
    completed episodes. ``shipped`` names the variant the folder ships."""
    block, ref = result["random"], result["controller"]
    agg = {"learned": block["learned"]["aggregate"]}
    ratios = {"reference": ref, "all": block["learned"]["ratios"], "shipped": shipped}
    if "learned+shield" in block:
        agg["learned+shield"] = block["learned+shield"]["aggregate"]
        ratios["learned+shield"] = block["learned+shield"]["ratios"]
    agg[ref] = block[ref]["aggregate"]
    seeds = [e["seed"] for e in block["learned"]["episodes"]]
    return {"test_seeds": seeds, "aggregate": agg, f"vs_{ref.upper()}": ratios}


def table(result: dict[str, Any]) -> str:
    cols = ["episodes", "success_rate", "collision_episodes", "violation_episodes", "terminated", "rmse",
            "delta_v", "final_error_m", "min_separation_m", "compute_ms_per_agent"]
    lines = []
    for label in ("random", "paper"):
        block = result[label]
        lines += [f"\n**{label} start** (`{json.dumps(block['env_kwargs'])}`)\n",
                  "| policy | " + " | ".join(cols) + " | RMSE ratio | Δv ratio (matched) |",
                  "|" + "---|" * (len(cols) + 3)]
        for name, res in block.items():
            if name == "env_kwargs":
                continue
            a, r = res["aggregate"], res.get("ratios", {})
            cells = [f"{a[c]:.3g}" if isinstance(a[c], float) else str(a[c]) for c in cols]
            rr = (f"{r['rmse_ratio']:.2f} | {r['delta_v_ratio']:.2f} ({r['matched_seeds']})"
                  if r.get("matched_seeds") else " | ")
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {rr} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--system", choices=sorted(SYSTEMS), required=True)
    p.add_argument("--policy", type=Path, required=True)
    p.add_argument("--seeds", default="900000-900049", help="first-last (inclusive)")
    p.add_argument("--paper-seeds", default="0-2")
    p.add_argument("--controller", default=None, help="default: the system's (CONTROLLERS); 'none' to skip")
    p.add_argument("--controller-seeds", default=None,
                   help="first-last: run the controller on these of --seeds only (a slow one, e.g. the NMPC); "
                        "ratios are then on the matched subset")
    p.add_argument("--controller-episodes", type=Path, default=None,
                   help="JSON {\"random\": [episode, ...], \"paper\": [...]}: the controller's episodes "
                        "(this module's episodes() records) run before on these seeds, used instead of "
                        "running it again (a slow controller, run once in the background)")
    p.add_argument("--no-shield", action="store_true")
    p.add_argument("--shipped", default="learned", choices=["learned", "learned+shield"],
                   help="which variant the folder ships (the card's 'learned' row)")
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args(argv)

    def span(text):
        a, _, b = text.partition("-")
        return list(range(int(a), int(b or a) + 1))

    import torch

    torch.set_num_threads(1)
    ctrl = ns.controller or CONTROLLERS[ns.system]
    res = evaluate_policies(ns.system, ns.policy, span(ns.seeds), span(ns.paper_seeds),
                            None if ctrl == "none" else ctrl, shield=not ns.no_shield,
                            controller_seeds=span(ns.controller_seeds) if ns.controller_seeds else None,
                            controller_episodes=(json.loads(ns.controller_episodes.read_text())
                                                 if ns.controller_episodes else None))
    res["table"] = table(res)
    if res["controller"]:
        res.update(card_fields(res, ns.shipped))
    ns.out.write_text(json.dumps(res, indent=1) + "\n")
    print(res["table"])


if __name__ == "__main__":
    main()
