"""Are the learned policies safe on their own? The network alone and as shipped, on test seeds.

For each entry ``system=folder`` (a policy folder under ``satenv/training/policies``), on the system's
training task (:mod:`satenv.tasks`, test seeds 900000..), it runs the folder both ways
(:func:`satenv.training.both_ways.evaluate`):

* ``network alone`` — ``satenv.training.load(folder, env=env, shielded=False)``;
* ``network + filter`` — the folder as shipped, ``satenv.training.load(folder, env=env)``: behind
  ``satenv.safety.shield`` with the options of its ``env.json`` ``"safety_filter"`` (interventions
  and infeasible steps per agent-step); a folder shipped without the filter is the network alone;
* the system's controller (``satenv.tasks.CONTROLLERS``) on the first ``--controller-seeds`` of
  the seeds (the comparator of the success and ratio targets, :func:`satenv.scoring.targets`),

and writes ``<out>/safety_alone.json`` (aggregates, targets, matched ratios, every episode
record; with ``--perturbation-seeds``, the first entry (``--perturbation-entries``: the first n)
under every perturbation of its task) and
``<out>/safety_alone.png`` (collision-free and violation-free episodes of each variant,
interventions per agent-step); with ``--write-folders``, each entry's block without its episode
records into its policy folder (:func:`folder_evaluation`: what ``satenv.training.card`` reports both ways
from). Each entry's episodes are cached in ``<out>/cache/`` so an interrupted run resumes where it
stopped::

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 satenv safety-alone \\
        --entry platoon-pereira2022=satenv/training/policies/platoon_pereira2022_safe_dagger \\
        --entry platoon-pereira2022=satenv/training/policies/platoon_pereira2022_dagger_shield \\
        --seeds 1000 --controller-seeds 200 --out studies/published/safety_alone
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from satenv.training import both_ways, runfolder, trust
from satenv.training.both_ways import NETWORK_ALONE, VARIANTS
from satenv.training.card import BOTH_WAYS_FILE, INTERVENTIONS_LIMIT, both_ways_file

__all__ = ["VARIANTS", "evaluate_entry", "evaluate_perturbed", "folder_evaluation", "plot", "main"]


def _cached(cache_dir: Path, tag: str) -> both_ways.Episodes:
    """The both-ways episode runner of an entry: :func:`_episodes` into ``<cache_dir>/<tag>__<variant>.jsonl``."""
    def run(env: Any, policy: Any, seeds: list[int], variant: str) -> list[dict[str, Any]]:
        name = variant.replace(" ", "_").replace("+", "plus")
        return _episodes(env, policy, seeds, cache_dir / f"{tag}__{name}.jsonl")
    return run


def _episodes(env: Any, policy: Any, seeds: list[int], cache: Path) -> list[dict[str, Any]]:
    """:func:`satenv.scoring.run_episodes`, resumable: records already in ``cache`` (the scoreboard's
    append-only JSON-lines log, :class:`satenv.bench.scoreboard.runner.EpisodeLog`, one line per seed)
    are reused, new ones appended as they finish (a line cut by a kill is moved aside and runs again)."""
    from satenv.bench.scoreboard.report import jsonable
    from satenv.bench.scoreboard.runner import EpisodeLog, read_episodes
    from satenv.rollout import rollout
    from satenv.scoring import episode_record

    done = {int(r["seed"]): r for r in read_episodes(cache, repair=True, key=("seed",))}
    cache.parent.mkdir(parents=True, exist_ok=True)
    log = EpisodeLog(cache)
    try:
        for s in seeds:
            if s in done:
                continue
            t0 = time.perf_counter()
            rec = episode_record(rollout(env, policy, seed=int(s)), int(s), len(env.possible_agents))
            rec["wall_s"] = round(time.perf_counter() - t0, 3)
            done[s] = jsonable(rec)   # as the log holds it (non-finite values as None, as on the scoreboard)
            log.append(done[s])
    finally:
        log.close()
    return [done[s] for s in seeds]


def _wall_s(records: list[dict[str, Any]]) -> float | None:
    """A variant's wall time [s]: the sum of its episodes' own times (an interrupted, resumed run
    counts each episode once); ``None`` when a record has no time (a cache of an earlier version)."""
    if records and all("wall_s" in r for r in records):
        return round(sum(r["wall_s"] for r in records), 3)
    return None


def evaluate_perturbed(system: str, folder: Path, n_seeds: int, n_controller: int, cache_dir: Path) -> dict[str, Any]:
    """Every perturbation of the system's training task (:mod:`satenv.perturbations`; a navigation
    error is read by the filter too): the network alone and behind the filter on the first
    ``n_seeds`` test seeds, the controller on the first ``n_controller``; aggregates only."""
    from satenv import baselines, perturbations, tasks
    from satenv.scoring import aggregate

    task = tasks.training_task(system)
    seeds = list(task.seeds("test", n_seeds))
    out: dict[str, Any] = {"seeds": [seeds[0], seeds[-1]]}
    for name in task.perturbations:
        env = perturbations.make_env(task, name)
        eps = both_ways.evaluate(folder, env, seeds, episodes=_cached(cache_dir, f"{system}__{folder.name}__{name}"))
        row: dict[str, Any] = {variant: aggregate(eps[variant]) for variant in VARIANTS}
        if n_controller:
            try:
                ctrl = baselines.make(task.controller, env)
            except (baselines.BaselineError, baselines.BaselineTypeError) as exc:   # refuses the wrapped env
                row["controller"] = {"error": f"{type(exc).__name__}: {exc}"}
            else:
                cache = cache_dir / f"{system}__controller_{task.controller}__{name}.jsonl"
                row["controller"] = aggregate(_episodes(env, ctrl, seeds[:n_controller], cache))
        print(system, folder.name, name, json.dumps({k: {m: v.get(m) for m in ("success_rate", "collision_episodes",
              "violation_episodes", "delta_v", "interventions_per_agent_step")} for k, v in row.items()}), flush=True)
        out[name] = row
    return out


def evaluate_entry(system: str, folder: Path, n_seeds: int, n_controller: int, cache_dir: Path,
                   n_filter: int | None = None) -> dict[str, Any]:
    """One entry's block of the JSON (module docstring); the filtered variant on the first
    ``n_filter`` seeds only when given (a slow system)."""
    from satenv import baselines, tasks
    from satenv.scoring import aggregate, matched_ratios, targets

    task = tasks.training_task(system)
    env = task.make_env()
    seeds = list(task.seeds("test", n_seeds))
    block: dict[str, Any] = {"system": system, "task": task.name, "policy": str(folder), "seeds": [seeds[0], seeds[-1]],
                             "controller": task.controller}
    eps = both_ways.evaluate(folder, env, seeds, shipped_seeds=n_filter or None,
                             episodes=_cached(cache_dir, f"{system}__{folder.name}"))
    for name in VARIANTS:
        block[name] = {"aggregate": aggregate(eps[name]), "wall_s": _wall_s(eps[name])}
        print(system, folder.name, name, json.dumps(block[name]["aggregate"], default=float), flush=True)
    if n_controller:
        cseeds = seeds[:n_controller]
        ctrl = _episodes(env, baselines.make(task.controller, env), cseeds,
                         cache_dir / f"{system}__controller_{task.controller}.jsonl")
        ref = aggregate(ctrl)
        block["controller_aggregate"] = ref
        block["controller_seeds"] = [cseeds[0], cseeds[-1]]
        for name in VARIANTS:
            sub = [e for e in eps[name] if e["seed"] in set(cseeds)]
            r = matched_ratios(sub, ctrl)
            block[name]["ratios_vs_controller"] = r
            block[name]["targets"] = targets(block[name]["aggregate"], ref, r)
    for name in VARIANTS:
        block[name]["episodes"] = eps[name]
    return block


def folder_evaluation(block: dict[str, Any], source: str, command: str) -> dict[str, Any]:
    """An entry's block as its policy folder keeps it (``satenv.training.card.BOTH_WAYS_FILE``): the
    test seeds of the network alone first, where it came from, then the block with each variant's
    seeds in place of its episode records."""
    out: dict[str, Any] = {"test_seeds": [e["seed"] for e in block[NETWORK_ALONE]["episodes"]],
                           "source": source, "command": command}
    for key, value in block.items():
        if key in VARIANTS:
            value = {**{k: v for k, v in value.items() if k != "episodes"},
                     "test_seeds": [e["seed"] for e in value["episodes"]]}
        out[key] = value
    return out


def write_folders(result: dict[str, Any], source: Path) -> list[Path]:
    """Each entry's :func:`folder_evaluation` into its policy folder: the folder's both-ways
    evaluation file when it has one (``satenv.training.card.both_ways_file``), else
    ``satenv.training.card.BOTH_WAYS_FILE``; the paths written (a file that already holds the same
    evaluation is left as it is)."""
    written = []
    for block in result["entries"]:
        folder = Path(block["policy"])
        path = both_ways_file(folder) or folder / BOTH_WAYS_FILE
        evaluation = json.loads(json.dumps(folder_evaluation(block, str(source), result["command"]), default=float))
        try:
            if trust.read_json(path.parent, path.name) == evaluation:
                continue
        except trust.UntrustedDataError:   # none yet or unreadable: written anew
            pass
        runfolder.write_json(path, evaluation, default=float)
        written.append(path)
    return written


def plot(result: dict[str, Any], path: Path) -> None:
    """Collision-free and violation-free episodes [%] of each variant, and interventions per
    agent-step behind the filter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    entries = result["entries"]
    labels = [f"{e['system']}\n{Path(e['policy']).name}" for e in entries]
    x = np.arange(len(entries))
    fig, ax = plt.subplots(1, 2, figsize=(max(8, 2.6 * len(entries) + 3), 4.6))
    width = 0.2
    bars = [(v, key) for v in VARIANTS for key in ("collision_episodes", "violation_episodes")]
    for k, (name, key) in enumerate(bars):
        vals = [100.0 * (1 - e[name]["aggregate"][key] / e[name]["aggregate"]["episodes"]) for e in entries]
        ax[0].bar(x + (k - 1.5) * width, vals, width, label=f"{name}: {key.split('_')[0]}-free")
    ax[0].axhline(99, color="k", ls="--", lw=0.8, label="target 99 %")
    ax[0].set_ylabel("episodes [%]")
    ax[0].set_ylim(min(50, ax[0].get_ylim()[0]), 100.5)
    ax[0].set_xticks(x, labels, fontsize=7)
    ax[0].legend(fontsize=7, loc="lower left")
    rate = [e[VARIANTS[1]]["aggregate"].get("interventions_per_agent_step") or 0.0 for e in entries]
    ax[1].bar(x, [100 * r for r in rate], 0.5)
    ax[1].axhline(100 * INTERVENTIONS_LIMIT, color="k", ls="--", lw=0.8,
                  label=f"target {100 * INTERVENTIONS_LIMIT:g} %")
    ax[1].set_ylabel("filter interventions [% of agent-steps]")
    ax[1].set_xticks(x, labels, fontsize=7)
    ax[1].legend(fontsize=7)
    counts = sorted({e[VARIANTS[0]]["aggregate"]["episodes"] for e in entries})
    fig.suptitle(f"learned policies alone and behind the filter (test seeds; {'/'.join(map(str, counts))} episodes)")
    fig.tight_layout()
    runfolder.save_with(path, lambda tmp: fig.savefig(tmp, dpi=100))
    plt.close(fig)


def _entry(spec: str) -> tuple[str, Path, int | None, int | None]:
    """An ``--entry`` value: ``(system, folder, episodes or None, filtered or None)``."""
    from satenv import tasks

    system, sep, folder = spec.partition("=")
    folder, at, count = folder.partition("@")
    count, colon, nf = count.partition(":")
    if not sep or not folder or (at and not count.isdigit()) or (colon and not nf.isdigit()):
        raise argparse.ArgumentTypeError(f"expected system=policy-folder[@episodes[:filtered]], got {spec!r}")
    if system not in tasks.SYSTEMS:
        raise argparse.ArgumentTypeError(f"{spec!r}: system {system!r} is not one of {sorted(tasks.SYSTEMS)}")
    if Path(folder).is_symlink():
        raise argparse.ArgumentTypeError(f"{spec!r}: {folder!r} is a symbolic link; pass the policy folder itself")
    if not (Path(folder) / "manifest.json").is_file():
        raise argparse.ArgumentTypeError(f"{spec!r}: {folder!r} is not a policy folder (no manifest.json)")
    return system, Path(folder), int(count) if at else None, int(nf) if colon else None


def build_parser() -> argparse.ArgumentParser:
    from satenv.cliargs import int_at_least, new_parser, out_folder

    p = new_parser("satenv safety-alone", __doc__)
    p.add_argument("--entry", action="append", default=[], type=_entry,
                   help="system=policy-folder[@episodes[:filtered]] (repeatable; @n: this entry on the first n "
                        "test seeds; :f: behind the filter on the first f of them)")
    p.add_argument("--seeds", type=int_at_least(1), default=1000,
                   help="test seeds per entry (the first n of the test split; default 1000)")
    p.add_argument("--controller-seeds", type=int_at_least(0), default=200,
                   help="the controller on the first n (0: none; default 200)")
    p.add_argument("--filter-seeds", type=int_at_least(1), default=None,
                   help="the network behind the filter on the first n of each entry's seeds only (default: all)")
    p.add_argument("--perturbation-seeds", type=int_at_least(0), default=0,
                   help="the first entry (more: --perturbation-entries) also under every perturbation of "
                        "its task, on the first n test seeds (0: none)")
    p.add_argument("--perturbation-entries", type=int_at_least(1), default=1,
                   help="with --perturbation-seeds: the first n entries under the perturbations (default: the first)")
    p.add_argument("--perturbation-controller-seeds", type=int_at_least(0), default=None,
                   help="the controller under each perturbation on the first n (default: min of the two counts above)")
    p.add_argument("--out", type=out_folder, default=None,
                   help="the output folder: safety_alone.json, safety_alone.png, cache/ (resumes from it)")
    p.add_argument("--write-folders", action="store_true",
                   help="also write each entry's evaluation (no episode records) into its policy folder")
    p.add_argument("--folders-from", type=Path, default=None, metavar="SAFETY_ALONE_JSON",
                   help="only write the policy folders' evaluations from this earlier run's JSON (runs nothing)")
    return p


def main(argv: list[str] | None = None) -> None:
    import sys

    p = build_parser()
    ns = p.parse_args(argv)
    if ns.folders_from is not None:
        try:
            earlier = trust.read_json(ns.folders_from.parent, ns.folders_from.name)
        except trust.UntrustedDataError as err:
            p.error(f"--folders-from: {err}; expected a safety_alone.json file")
        if not (isinstance(earlier, dict) and isinstance(earlier.get("entries"), list)):
            p.error(f"--folders-from {str(ns.folders_from)!r}: expected a safety_alone.json file (its 'entries')")
        for path in write_folders(earlier, ns.folders_from):
            print("wrote", path)
        return
    if not ns.entry or ns.out is None:
        p.error("--entry system=policy-folder[@episodes[:filtered]] (one or more) and --out FOLDER are required")
    if not ns.perturbation_entries <= len(ns.entry):
        p.error(f"--perturbation-entries {ns.perturbation_entries}: expected between 1 and the {len(ns.entry)} "
                "--entry given")
    entries = [(s, f, ns.seeds if n is None else n, ns.filter_seeds if nf is None else nf) for s, f, n, nf in ns.entry]
    import torch

    torch.set_num_threads(1)
    alone = sum(n for _, _, n, _ in entries)
    print(f"planning {len(entries)} entries: {alone} episodes of the network alone, "
          f"{sum(n if nf is None else min(n, nf) for _, _, n, nf in entries)} behind the filter, "
          f"{ns.controller_seeds * len(entries)} of the controller"
          + (f", and the perturbations of the first {ns.perturbation_entries} on {ns.perturbation_seeds} seeds each"
             if ns.perturbation_seeds else "")
          + f"; episodes are cached in {ns.out / 'cache'} (a rerun resumes), the result goes to "
            f"{ns.out / 'safety_alone.json'}", file=sys.stderr, flush=True)
    ns.out.mkdir(parents=True, exist_ok=True)
    result = {"command": "satenv safety-alone " + " ".join(sys.argv[1:] if argv is None else argv),
              "entries": [evaluate_entry(s, f, n, ns.controller_seeds, ns.out / "cache", nf)
                          for s, f, n, nf in entries]}
    if ns.perturbation_seeds:   # the policies under study: the first entries
        n_controller = (min(ns.controller_seeds, ns.perturbation_seeds) if ns.perturbation_controller_seeds is None
                        else ns.perturbation_controller_seeds)
        k = ns.perturbation_entries
        for (s, f, _, _), block in zip(entries[:k], result["entries"][:k], strict=True):
            block["perturbations"] = evaluate_perturbed(s, f, ns.perturbation_seeds, n_controller, ns.out / "cache")
    runfolder.write_json(ns.out / "safety_alone.json", result, default=float)
    print(f"plotting {ns.out / 'safety_alone.png'}", file=sys.stderr, flush=True)
    plot(result, ns.out / "safety_alone.png")
    if ns.write_folders:
        for path in write_folders(result, ns.out / "safety_alone.json"):
            print("wrote", path)


if __name__ == "__main__":
    main()
