"""Held-out evaluation of a policy folder beside its system's controller, on the task registry's
test seeds.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.training.recipes.heldout \\
        --system platoon-pereira2022 --policy satenv/training/policies/<name> --out eval_heldout.json

On the system's training task (:func:`satenv.tasks.training_task`; ``--seeds``, default its first
50 test seeds, which no training run, validation or selection touches) and on its paper task (the
paper's start: one test seed, deterministic), it runs the learned policy, the same policy behind
the safety filter (``satenv.safety.shield``) and the system's controller, and checks the targets
of :func:`satenv.scoring.targets` (success, no collision or violation episode, RMSE and delta-v
ratios on *matched, completed* episodes, decision time).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from satenv import scoring, tasks
from satenv.metrics import matched_ratios  # the one home of the matched-episode rule
from satenv.scoring import aggregate
from satenv.scoring import run_episodes as episodes
from satenv.training.recipes import system_name

__all__ = ["evaluate_policies", "targets", "main"]

targets = scoring.targets
"""The target rule (:func:`satenv.scoring.targets`)."""


def evaluate_policies(system: str, folder: Path, seeds: list[int], paper_seeds: list[int],
                      controller: str | None, shield: bool = True,
                      controller_seeds: list[int] | None = None,
                      controller_episodes: dict[str, list[dict[str, Any]]] | None = None) -> dict[str, Any]:
    from satenv import baselines, training
    from satenv.safety import Shield
    from satenv.safety import shield as make_shield

    sysdef = tasks.system(system)
    result: dict[str, Any] = {"system": system, "policy": str(folder), "seeds": [seeds[0], seeds[-1]],
                              "paper_seeds": paper_seeds, "controller": controller,
                              "controller_seeds": controller_seeds}
    for label, task, ss in (("random", tasks.get(sysdef.training_task), seeds),
                            ("paper", tasks.get(sysdef.paper_task), paper_seeds)):
        env, kwargs = task.make_env(), dict(task.env_kwargs)
        net = training.load(folder, env=env, shielded=False)
        runs = {"learned": net}
        if shield:   # as satenv.training.load ships a filtered folder (its own options), else the default filter
            shipped = training.load(folder, env=env)
            runs["learned+shield"] = shipped if isinstance(shipped, Shield) else make_shield(shipped, env)
        if controller:
            runs[controller] = baselines.make(controller, env)
        block: dict[str, Any] = {"task": task.name, "env_kwargs": kwargs}
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
    """The keys ``satenv.training.card`` reads (``aggregate``, ``vs_<REF>``, ``test_seeds``) for the
    randomised scenario. ``learned`` is the network alone (``satenv.training.load(folder, shielded=False)``),
    ``learned+shield`` the network behind the filter (what a folder shipped with it loads as); ratios on matched
    completed episodes. ``shipped`` names the variant the folder ships."""
    block, ref = result["random"], result["controller"]
    agg = {"learned": block["learned"]["aggregate"]}
    ratios = {"reference": ref, "matched": block["learned"]["ratios"], "shipped": shipped}
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
            if name in ("env_kwargs", "task"):
                continue
            a, r = res["aggregate"], res.get("ratios", {})
            cells = [f"{a[c]:.3g}" if isinstance(a[c], float) else str(a[c]) for c in cols]
            rr = (f"{r['rmse_ratio']:.2f} | {r['delta_v_ratio']:.2f} ({r['matched_seeds']})"
                  if r.get("matched_seeds") else " | ")
            lines.append(f"| {name} | " + " | ".join(cells) + f" | {rr} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from satenv.cliargs import new_parser

    p = new_parser(prog="satenv heldout", description=__doc__.split("\n\n")[0])
    p.add_argument("--system", required=True, help=f"a paper system: {', '.join(tasks.SYSTEMS)}")
    p.add_argument("--policy", type=Path, required=True)
    p.add_argument("--seeds", default=None, help="seeds of the training task (default: its first 50 test seeds)")
    p.add_argument("--paper-seeds", default=None, help="seeds of the paper task (default: its test seed)")
    p.add_argument("--controller", default=None, help="default: the system's; 'none' to skip")
    p.add_argument("--controller-seeds", default=None,
                   help="run the controller on these of --seeds only (a slow one, e.g. the NMPC); "
                        "ratios are then on the matched subset")
    p.add_argument("--controller-episodes", type=Path, default=None,
                   help="JSON {\"random\": [episode, ...], \"paper\": [...]}: the controller's episodes "
                        "(satenv.scoring.run_episodes records) run before on these seeds, used instead of "
                        "running it again (a slow controller, run once in the background)")
    p.add_argument("--no-shield", action="store_true")
    p.add_argument("--shipped", default="learned", choices=["learned", "learned+shield"],
                   help="which variant the folder ships (the card's 'learned' row)")
    p.add_argument("--out", type=Path, required=True)
    ns = p.parse_args(argv)
    try:
        system = tasks.system(system_name(ns.system))
        seeds = (list(tasks.parse_seeds(ns.seeds)) if ns.seeds
                 else list(tasks.get(system.training_task).seeds("test", 50)))
        paper_seeds = (list(tasks.parse_seeds(ns.paper_seeds)) if ns.paper_seeds
                       else list(tasks.get(system.paper_task).seeds("test")))
        ctrl_seeds = list(tasks.parse_seeds(ns.controller_seeds)) if ns.controller_seeds else None
    except ValueError as exc:
        p.error(str(exc))

    import torch

    torch.set_num_threads(1)
    ctrl = ns.controller or system.controller
    res = evaluate_policies(system.name, ns.policy, seeds, paper_seeds,
                            None if ctrl == "none" else ctrl, shield=not ns.no_shield,
                            controller_seeds=ctrl_seeds,
                            controller_episodes=(json.loads(ns.controller_episodes.read_text())
                                                 if ns.controller_episodes else None))
    res["table"] = table(res)
    if res["controller"]:
        res.update(card_fields(res, ns.shipped))
    ns.out.write_text(json.dumps(res, indent=1) + "\n")
    print(res["table"])


if __name__ == "__main__":
    main()
