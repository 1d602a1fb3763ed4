"""Select a DAgger round on validation seeds and ship it as a policy folder.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.training.recipes.ship select \\
        --run-dir /work/runs/p22/dagger_shield --rounds 3-9 --out select.json
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.training.recipes.ship ship \\
        --run-dir /work/runs/p22/dagger_shield --round 7 --name platoon_pereira2022_dagger_shield \\
        --heldout eval_heldout.json [--shield]

``select`` rolls every listed round out on validation seeds (the first 50 of the system's training
task by default: :data:`satenv.tasks.SEED_SPLITS`, disjoint from the train and test seeds), with
and without the safety filter, and ranks them (success, then collision episodes, then final error) — the held-out
seeds are never used to choose. ``ship`` writes ``satenv/training/policies/<name>/`` with
:func:`satenv.training.policy.save_artifacts` (``env.json`` gains ``"safety_filter"`` when the policy
ships behind ``satenv.safety.shield``), the held-out ``eval.json`` and the run's learning curve.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from satenv import tasks
from satenv.scoring import aggregate
from satenv.scoring import run_episodes as episodes
from satenv.training.recipes import system_name

__all__ = ["select", "ship", "main"]


def select(run_dir: Path, rounds: list[int], seeds: list[int]) -> list[dict[str, Any]]:
    from satenv import training
    from satenv.safety import shield

    cfg = json.loads((run_dir / "config.json").read_text())
    env = (tasks.get(cfg["task"]) if cfg.get("task") else   # a run folder of satenv.training.imitate, or an earlier one's
           tasks.training_task(system_name(cfg.get("system", "platoon-pereira2022")))).make_env()
    rows = []
    for k in rounds:
        folder = run_dir / "rounds" / f"{k:04d}"
        net = aggregate(episodes(env, training.load(folder, env=env, shielded=False), seeds))
        shielded = aggregate(episodes(env, shield(training.load(folder, env=env, shielded=False), env), seeds))
        rows.append({"round": k, "net": net, "shield": shielded})
        print(k, "net", net["success_rate"], net["collision_episodes"], round(net["final_error_m"], 3),
              "| shield", shielded["success_rate"], shielded["collision_episodes"],
              round(shielded["final_error_m"], 3), flush=True)
    return rows


def ship(run_dir: Path, k: int, name: str, heldout: Path, with_shield: bool) -> Path:
    from satenv import training
    from satenv.training.policy import save_artifacts

    src = run_dir / "rounds" / f"{k:04d}"
    policy = training.load(src, shielded=False)
    meta = dict(policy.meta)
    if with_shield:
        meta["safety_filter"] = {"wrapper": "satenv.safety.shield", "options": {},
                                 "note": "ships behind the safety filter: load, then shield(policy, env)"}
    config = json.loads((src / "config.json").read_text())
    config["shipped_round"] = k
    evaluation = json.loads(heldout.read_text())
    dest = save_artifacts(training.POLICIES_DIR / name, policy, env_meta=meta, config=config,
                          evaluation=evaluation,
                          source=f"DAgger of {config.get('expert', '?')} (satenv.training.recipes.dagger round {k})"
                          + (", ships behind satenv.safety.shield" if with_shield else ""))
    curve = run_dir / "learning_curve.png"
    if curve.is_file():
        (dest / "learning_curve.png").write_bytes(curve.read_bytes())
    hist = json.loads((run_dir / "history.json").read_text())
    (dest / "history.json").write_text(json.dumps(hist, indent=1) + "\n")
    return dest


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("select")
    s.add_argument("--run-dir", type=Path, required=True)
    s.add_argument("--rounds", required=True, help="first-last")
    s.add_argument("--seeds", default=None, help="validation seeds (default: the first 50 of the split)")
    s.add_argument("--out", type=Path, required=True)
    h = sub.add_parser("ship")
    h.add_argument("--run-dir", type=Path, required=True)
    h.add_argument("--round", type=int, required=True)
    h.add_argument("--name", required=True)
    h.add_argument("--heldout", type=Path, required=True)
    h.add_argument("--shield", action="store_true")
    ns = p.parse_args(argv)

    def span(text):
        try:
            return list(tasks.parse_seeds(text))
        except ValueError as exc:
            p.error(str(exc))

    import torch

    torch.set_num_threads(1)
    if ns.cmd == "select":
        ns.out.write_text(json.dumps(select(ns.run_dir, span(ns.rounds),
                                             span(ns.seeds) if ns.seeds else list(tasks.SEED_SPLITS["validation"][:50])), indent=1) + "\n")
    else:
        print(ship(ns.run_dir, ns.round, ns.name, ns.heldout, ns.shield))


if __name__ == "__main__":
    main()
