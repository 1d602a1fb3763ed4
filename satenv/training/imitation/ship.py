"""Choosing a round on validation seeds and shipping it as a policy folder.

:func:`choose` ranks a run's rounds on what ``history.json`` (or :func:`validate_round`) recorded
on validation seeds, safety first (:func:`selection_key`); test seeds are never used to choose.
:func:`ship` copies one round to a new policy folder with the run's history and a fresh
manifest, reading the round as untrusted data (regular files of the policy format only, sizes
capped before reading, nothing behind a link) and swapping the folder in whole.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from satenv.training.imitation.folder import (
    MAX_HISTORY_BYTES,
    MAX_PICTURE_BYTES,
    check_folder,
    read_history,
    read_run_json,
    round_folder,
)
from satenv.training.runfolder import RunFolderError

__all__ = ["choose", "selection_key", "ship", "validate_round"]

def _scores(entry: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A history entry's validation of the network alone and behind the filter."""
    val = entry.get("val")
    if not isinstance(val, dict):
        raise RunFolderError(f"round {entry.get('round')!r:.20}: no validation ('val') recorded")
    shielded = entry.get("shield", {}).get("val", {}) if isinstance(entry.get("shield"), dict) else {}
    return val, shielded


def selection_key(entry: dict[str, Any]) -> tuple[float, ...]:
    """How rounds rank on validation (ascending): collision episodes, violation episodes and
    failures of the network alone, then the filter's interventions per agent-step."""
    alone, shielded = _scores(entry)
    values = (alone.get("collision_episodes"), alone.get("violation_episodes"), alone.get("success_rate"),
              shielded.get("interventions_per_agent_step") if isinstance(shielded, dict) else None)
    if any(v is not None and (isinstance(v, bool) or not isinstance(v, int | float)) for v in values):
        raise RunFolderError(f"round {entry.get('round')!r:.20}: its validation holds a value that is not a number")
    coll, viol, success, rate = (v or 0 for v in values)
    return (coll, viol, -success, rate)


def choose(entries: list[dict[str, Any]]) -> int:
    """The round to ship: the lowest :func:`selection_key` (a later round on a tie)."""
    if not entries:
        raise RunFolderError("choose: the run records no round")
    return min(entries, key=lambda h: (*selection_key(h), -h["round"]))["round"]


def ship(run_dir: Path, k: int, dest: Path, *, with_filter: bool = False) -> Path:
    """Round ``k`` of the run as the new policy folder ``dest`` (an existing one is an error),
    with ``history.json``, the learning curve, ``shipped_round`` in its ``config.json`` and, with
    ``with_filter``, the default safety filter named in its ``env.json``; returns ``dest``."""
    from satenv.training import runfolder
    from satenv.training.policy import (
        MANIFEST,
        POLICY_FILES,
        WEIGHTS,
        load,
        max_weights_bytes,
        write_manifest,
    )
    from satenv.training.trust import MAX_JSON_BYTES, read_member

    check_folder(check_folder(Path(run_dir)) / "rounds", "rounds folder")
    src = check_folder(round_folder(Path(run_dir), k), "round folder")
    if not src.is_dir():
        raise RunFolderError(f"ship: {src} is not a round folder of the run")
    if os.path.lexists(dest):
        raise RunFolderError(f"ship: {dest} exists; a shipped folder is never overwritten")
    history = read_history(Path(run_dir))
    staged = runfolder.staging(dest)
    try:
        for name in (*POLICY_FILES, "eval.json"):
            if name == "eval.json" and not os.path.lexists(src / name):
                continue
            cap = max_weights_bytes() if name == WEIGHTS else MAX_JSON_BYTES
            (staged / name).write_bytes(bytes(read_member(src, name, cap)))
        config = read_run_json(staged, "config.json", "the round's config", MAX_JSON_BYTES)
        runfolder.write_json(staged / "config.json", {**config, "shipped_round": k}, indent=2)
        if with_filter:
            meta = read_run_json(staged, "env.json", "the round's env.json", MAX_JSON_BYTES)
            meta["safety_filter"] = {"wrapper": "satenv.safety.shield", "options": {},
                                     "note": "ships behind the safety filter: load, then shield(policy, env)"}
            runfolder.write_json(staged / "env.json", meta, indent=2)
        runfolder.write_json(staged / "history.json", history)
        curve = Path(run_dir) / "learning_curve.png"
        if os.path.lexists(curve):
            (staged / curve.name).write_bytes(bytes(read_member(run_dir, curve.name, MAX_PICTURE_BYTES)))
        (staged / MANIFEST).unlink(missing_ok=True)
        write_manifest(staged)
        load(staged, shielded=False)                    # whole and consistent before it is swapped in
    except Exception:
        import shutil

        shutil.rmtree(staged, ignore_errors=True)
        raise
    return runfolder.replace_folder(staged, dest)


def validate_round(run_dir: Path, k: int, env: Any, warm_start: str | None, seeds: tuple[int, ...],
                   shield_seeds: tuple[int, ...], filter_config: Any = None) -> Path:
    """Round ``k`` (``-1``: the warm start) on validation ``seeds`` alone and ``shield_seeds``
    behind the filter, written to ``<run>/validation/round_NNNN_<alone>_<filtered>.json``."""
    from satenv.safety import shield
    from satenv.training import runfolder
    from satenv.training.imitation.setup import score
    from satenv.training.policy import load

    run_dir = check_folder(Path(run_dir))
    if k == -1 and warm_start is None:
        raise RunFolderError("validate_round: round -1 is the warm start, and the run has none")
    check_folder(run_dir / "rounds", "rounds folder")
    folder = check_folder(Path(warm_start) if k == -1 else round_folder(run_dir, k), "round folder")
    if not folder.is_dir():
        raise RunFolderError(f"validate_round: round {k} has no folder {folder}")
    policy = load(folder, shielded=False)
    val = score(env, policy, seeds)
    out = {"round": k, "val": val, "shield": {"val": score(env, shield(policy, env, filter_config), shield_seeds)}}
    validation = check_folder(run_dir / "validation", "validation folder")
    path = validation / f"round_{k:04d}_{len(seeds)}_{len(shield_seeds)}.json"
    return runfolder.write_json(path, out, default=float)


def recorded(run_dir: Path) -> list[dict[str, Any]]:
    """The validations of a run's rounds: ``history.json``'s, each replaced by the largest
    :func:`validate_round` of that round (more seeds) when there is one."""
    entries = {h["round"]: h for h in read_history(Path(run_dir))}
    folder = check_folder(Path(run_dir) / "validation", "validation folder")
    if folder.is_dir():
        for name in sorted(os.listdir(folder),
                           key=lambda n: [int(p) for p in n[6:-5].split("_") if p.lstrip("-").isdigit()]):
            if name.startswith("round_") and name.endswith(".json"):
                entry = read_run_json(folder, name, "a round's validation", MAX_HISTORY_BYTES)
                if isinstance(entry, dict) and isinstance(entry.get("round"), int):
                    entries[entry["round"]] = entry
    return list(entries.values())
