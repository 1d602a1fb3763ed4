"""Tuned configurations of the lean learner: candidates trained on a train seed, chosen on validation seeds.

    satenv ppo-tune --task platoon-pereira2022-random --budget 3000000 \\
        --candidate lr1e-3='{"lr": 0.001}' --candidate epochs5='{"n_epochs": 5}'

trains the defaults (``A_default``) and each candidate with ``satenv ppo`` at the same budget and
training seed, evaluates each final policy on the task's first validation seeds (never a test seed),
and keeps the one :data:`RULE` ranks first. It writes the choice with every candidate's numbers to
``results/tuned/<task>.json`` (``--update-published``: ``satenv/training/rl/tuned/<task>.json``,
which ``satenv ppo --tuned`` reads). Every candidate trains in its own folder under ``--work-dir``:
the same command skips the candidates that have finished and resumes the others.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any

from satenv.cliargs import int_at_least, new_parser, out_file, out_folder, parse_json_object, published_or_user
from satenv.training import runfolder
from satenv.training.rl.ppo import LeanConfig, train, tuned_path

__all__ = ["DEFAULT", "RULE", "choose", "main", "tune"]

DEFAULT = "A_default"
"""The name of the candidate with the learner's defaults (always trained)."""
RULE = "highest validation success, then fewest collision episodes, then lowest mean final error"
"""How the candidates are ranked (:func:`choose`)."""
FIXED = ("task", "seed", "budget", "test_seeds", "out_dir", "eval_baselines", "progress")
"""Fields a candidate may not set: they are the comparison's (the same for every candidate)."""


def choose(scores: dict[str, dict[str, Any]]) -> str:
    """The candidate :data:`RULE` ranks first among ``name -> {success_rate, collision_episodes,
    final_error_m}``."""
    return min(scores, key=lambda k: (-scores[k]["success_rate"], scores[k]["collision_episodes"],
                                      scores[k]["final_error_m"]))


def check_candidate(name: str, config: dict[str, Any]) -> None:
    """A candidate sets known :class:`LeanConfig` fields other than :data:`FIXED` (else ValueError)."""
    known = {f.name for f in fields(LeanConfig)} - set(FIXED)
    bad = sorted(set(config) - known)
    if bad:
        raise ValueError(f"candidate {name!r}: {bad} are not tunable LeanConfig fields; expected some of "
                         f"{sorted(known)}")


def _score(cfg: LeanConfig) -> dict[str, Any]:
    """Train ``cfg`` (a stopped candidate continues, a finished one is read back) and return its
    validation numbers."""
    out = Path(cfg.out_dir)
    final = out / "final" / "eval.json"
    wanted = json.loads(json.dumps(cfg.to_json()))   # as config.json holds it (lists for tuples)
    saved = runfolder.read_json(out / "config.json", "the run's config") if (out / "config.json").is_file() else None
    if saved is not None:
        other = sorted(k for k in wanted if k not in ("progress", "budget") and saved.get(k) != wanted[k])
        if other or saved.get("budget", 0) > cfg.budget:
            raise ValueError(f"{out} holds a run of another configuration ({other or 'a larger budget'}); "
                             "remove it or give another --work-dir")
    if saved is None or saved.get("budget") != cfg.budget or not final.is_file():
        train(cfg, resume=saved is not None)
    summary = runfolder.read_json(final, "the candidate's evaluation")
    agg = summary["aggregate"]["learned"]
    return {"success_rate": agg["success_rate"], "final_error_m": agg["final_error_m"], "rmse": agg["rmse"],
            "collision_episodes": agg["collision_episodes"], "wall_s": round(summary["train_wall_s_this_session"])}


def tune(task: str, candidates: dict[str, dict[str, Any]], *, budget: int, seed: int = 0,
         validation_seeds: int = 20, work_dir: Path, progress: bool = True) -> dict[str, Any]:
    """Train the defaults and ``candidates`` (name -> config fields) on ``task``; the tuned record."""
    from satenv import tasks

    seeds = tasks.get(task).seeds("validation", validation_seeds)
    runs = {DEFAULT: {}, **candidates}
    configs = {}
    for name, config in runs.items():   # every candidate checked before any trains
        check_candidate(name, config)
        configs[name] = LeanConfig(task=task, seed=seed, budget=budget, test_seeds=seeds, eval_baselines=(),
                                   out_dir=str(work_dir / name), progress=progress, **config)
    scores = {}
    for k, (name, config) in enumerate(runs.items(), start=1):
        print(f"[{k}/{len(runs)}] {name} {json.dumps(config)}", flush=True)
        scores[name] = {"config": config, **_score(configs[name])}
    chosen = choose(scores)
    return {"task": task, "stack": f"satenv.training.rl.ppo (lean PPO, variant {LeanConfig().variant})",
            "chosen_on": {"split": "validation", "seeds": f"{seeds[0]}-{seeds[-1]}", "training_seed": seed,
                          "budget_agent_steps": budget, "rule": RULE},
            "candidates": scores, "chosen": chosen, "config": scores[chosen]["config"]}


def _candidate(text: str) -> tuple[str, dict[str, Any]]:
    name, sep, config = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME='{{\"field\": value}}', got {text!r}")
    try:
        return name.strip(), parse_json_object(config)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def parser() -> argparse.ArgumentParser:
    p = new_parser("satenv ppo-tune", __doc__)
    p.add_argument("--task", required=True, help="a registered task (satenv.tasks)")
    p.add_argument("--candidate", type=_candidate, action="append", default=[], metavar="NAME=JSON",
                   help="a candidate: a name and the LeanConfig fields it changes (repeat for more)")
    p.add_argument("--budget", type=int_at_least(1), default=3_000_000, help="agent-steps per candidate")
    p.add_argument("--seed", type=int_at_least(0), default=0, help="the training seed of every candidate")
    p.add_argument("--validation-seeds", type=int_at_least(1), default=20, help="how many validation seeds")
    p.add_argument("--work-dir", type=out_folder, help="the candidates' run folders (default results/tune/<task>)")
    p.add_argument("--out", type=out_file, help="the tuned record (default results/tuned/<task>.json)")
    p.add_argument("--update-published", action="store_true",
                   help="write the record to satenv/training/rl/tuned/<task>.json, which satenv ppo --tuned reads")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    """``satenv ppo-tune``: 0 on success, 2 on a bad input."""
    p = parser()
    args = p.parse_args(argv)
    names = [name for name, _ in args.candidate]
    if len(set(names)) != len(names) or DEFAULT in names:
        p.error(f"argument --candidate: names must be distinct and not {DEFAULT!r}, got {names}")
    out = published_or_user(p, "--out", args.out, args.update_published, tuned_path(args.task),
                            Path("results/tuned") / f"{args.task}.json")
    work = args.work_dir or Path("results/tune") / args.task
    print(f"{len(names) + 1} candidates x {args.budget:,} agent-steps = {(len(names) + 1) * args.budget:,} "
          f"agent-steps on {args.task}, each scored on {args.validation_seeds} validation seeds; folders in {work}")
    try:
        record = tune(args.task, dict(args.candidate), budget=args.budget, seed=args.seed,
                      validation_seeds=args.validation_seeds, work_dir=work, progress=not args.no_progress)
    except ValueError as err:   # satenv's input errors are ValueErrors
        print(f"error: {err}", file=sys.stderr)
        return 2
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"chosen {record['chosen']} {json.dumps(record['config'])} ({RULE}); wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
