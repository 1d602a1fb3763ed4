"""Are the learned policies safe on their own? The network alone and as shipped, on test seeds.

For each entry ``system=folder`` (a policy folder under ``satenv/training/policies``), on the system's
training task (:mod:`satenv.tasks`, test seeds 900000..), it runs

* ``network alone`` — ``satenv.training.load(folder, env=env, shielded=False)``;
* ``network + filter`` — the same network behind ``satenv.safety.shield`` with the options of the
  folder's ``env.json`` ``"safety_filter"`` (what a folder that ships with the filter loads as,
  :func:`as_shipped`; the filter's defaults for a folder shipped without it): interventions and
  infeasible steps per agent-step;
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

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.bench.safety_alone \\
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

from satenv.training.card import (
    AS_SHIPPED,
    BOTH_WAYS_FILE,
    INTERVENTIONS_LIMIT,
    NETWORK_ALONE,
    both_ways_file,
)

__all__ = ["VARIANTS", "as_shipped", "evaluate_entry", "evaluate_perturbed", "folder_evaluation", "plot", "main"]

VARIANTS = (NETWORK_ALONE, AS_SHIPPED)
"""The two ways every policy is reported."""


def as_shipped(folder: Path, network: Any, env: Any) -> Any:
    """``network`` behind the safety filter as ``folder`` ships it: with the options of its
    ``env.json`` ``"safety_filter"`` (:func:`satenv.training.policy.shipped_filter`), the filter's
    defaults when the folder ships without it."""
    from satenv.safety import shield
    from satenv.training.policy import policy_folder, shipped_filter

    root = policy_folder(folder)
    config = shipped_filter(root, json.loads((root / "env.json").read_text()))
    return shield(network, env, config)


def _episodes(env: Any, policy: Any, seeds: list[int], cache: Path) -> list[dict[str, Any]]:
    """:func:`satenv.scoring.run_episodes`, resumable: records already in ``cache`` (JSON lines,
    one per seed) are reused, new ones appended as they finish."""
    from satenv.rollout import rollout
    from satenv.scoring import episode_record

    done: dict[int, dict[str, Any]] = {}
    if cache.is_file():
        for line in cache.read_text().splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:   # a line cut by an interrupted run: that episode runs again
                continue
            done[int(rec["seed"])] = rec
    cache.parent.mkdir(parents=True, exist_ok=True)
    with cache.open("a") as fh:
        for s in seeds:
            if s in done:
                continue
            t0 = time.perf_counter()
            rec = episode_record(rollout(env, policy, seed=int(s)), int(s), len(env.possible_agents))
            rec["wall_s"] = round(time.perf_counter() - t0, 3)
            done[s] = rec
            fh.write(json.dumps(rec, default=float) + "\n")
            fh.flush()
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
    from satenv import baselines, perturbations, tasks, training
    from satenv.scoring import aggregate

    task = tasks.training_task(system)
    seeds = list(task.seeds("test", n_seeds))
    out: dict[str, Any] = {"seeds": [seeds[0], seeds[-1]]}
    for name in task.perturbations:
        env = perturbations.make_env(task, name)
        net = training.load(folder, env=env, shielded=False)
        row: dict[str, Any] = {}
        for variant, pol in ((VARIANTS[0], net), (VARIANTS[1], as_shipped(folder, net, env))):
            cache = cache_dir / f"{system}__{folder.name}__{name}__{variant.replace(' ', '_').replace('+', 'plus')}.jsonl"
            row[variant] = aggregate(_episodes(env, pol, seeds, cache))
        if n_controller:
            try:
                ctrl = baselines.make(task.controller, env)
            except (baselines.BaselineError, baselines.BaselineTypeError) as exc:   # refuses the wrapped env
                row["controller"] = {"error": f"{type(exc).__name__}: {exc}"}
            else:
                row["controller"] = aggregate(_episodes(env, ctrl, seeds[:n_controller],
                                                        cache_dir / f"{system}__controller_{task.controller}__{name}.jsonl"))
        print(system, folder.name, name, json.dumps({k: {m: v.get(m) for m in ("success_rate", "collision_episodes",
              "violation_episodes", "delta_v", "interventions_per_agent_step")} for k, v in row.items()}), flush=True)
        out[name] = row
    return out


def evaluate_entry(system: str, folder: Path, n_seeds: int, n_controller: int, cache_dir: Path,
                   n_filter: int | None = None) -> dict[str, Any]:
    """One entry's block of the JSON (module docstring); the filtered variant on the first
    ``n_filter`` seeds only when given (a slow system)."""
    from satenv import baselines, tasks, training
    from satenv.scoring import aggregate, matched_ratios, targets

    task = tasks.training_task(system)
    env = task.make_env()
    seeds = list(task.seeds("test", n_seeds))
    net = training.load(folder, env=env, shielded=False)
    tag = f"{system}__{folder.name}"
    block: dict[str, Any] = {"system": system, "task": task.name, "policy": str(folder), "seeds": [seeds[0], seeds[-1]],
                             "controller": task.controller}
    eps = {}
    for name, pol in ((VARIANTS[0], net), (VARIANTS[1], as_shipped(folder, net, env))):
        ss = seeds if name == VARIANTS[0] or not n_filter else seeds[:n_filter]
        eps[name] = _episodes(env, pol, ss, cache_dir / f"{tag}__{name.replace(' ', '_').replace('+', 'plus')}.jsonl")
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
        text = json.dumps(folder_evaluation(block, str(source), result["command"]), indent=1, default=float) + "\n"
        if path.is_file() and json.loads(path.read_text()) == json.loads(text):
            continue
        path.write_text(text)
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
    for k, (name, key) in enumerate([(v, key) for v in VARIANTS for key in ("collision_episodes", "violation_episodes")]):
        vals = [100.0 * (1 - e[name]["aggregate"][key] / e[name]["aggregate"]["episodes"]) for e in entries]
        ax[0].bar(x + (k - 1.5) * width, vals, width, label=f"{name}: {key.split('_')[0]}-free")
    ax[0].axhline(99, color="k", ls="--", lw=0.8, label="target 99 %")
    ax[0].set_ylabel("episodes [%]")
    ax[0].set_ylim(min(50, ax[0].get_ylim()[0]), 100.5)
    ax[0].set_xticks(x, labels, fontsize=7)
    ax[0].legend(fontsize=7, loc="lower left")
    rate = [e[VARIANTS[1]]["aggregate"].get("interventions_per_agent_step") or 0.0 for e in entries]
    ax[1].bar(x, [100 * r for r in rate], 0.5)
    ax[1].axhline(100 * INTERVENTIONS_LIMIT, color="k", ls="--", lw=0.8, label=f"target {100 * INTERVENTIONS_LIMIT:g} %")
    ax[1].set_ylabel("filter interventions [% of agent-steps]")
    ax[1].set_xticks(x, labels, fontsize=7)
    ax[1].legend(fontsize=7)
    counts = sorted({e[VARIANTS[0]]["aggregate"]["episodes"] for e in entries})
    fig.suptitle(f"learned policies alone and behind the filter (test seeds; {'/'.join(map(str, counts))} episodes)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    import torch

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--entry", action="append", default=[],
                   help="system=policy-folder[@episodes[:filtered]] (repeatable; @n: this entry on the first n "
                        "test seeds; :f: behind the filter on the first f of them)")
    p.add_argument("--seeds", type=int, default=1000, help="test seeds per entry (the first n of the test split)")
    p.add_argument("--controller-seeds", type=int, default=200, help="the controller on the first n (0: none)")
    p.add_argument("--filter-seeds", type=int, default=None,
                   help="the network behind the filter on the first n of each entry's seeds only (default: all)")
    p.add_argument("--perturbation-seeds", type=int, default=0,
                   help="the first entry (more: --perturbation-entries) also under every perturbation of "
                        "its task, on the first n test seeds (0: none)")
    p.add_argument("--perturbation-entries", type=int, default=1,
                   help="with --perturbation-seeds: the first n entries under the perturbations (default: the first)")
    p.add_argument("--perturbation-controller-seeds", type=int, default=None,
                   help="the controller under each perturbation on the first n (default: min of the two counts above)")
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--write-folders", action="store_true",
                   help="also write each entry's evaluation (no episode records) into its policy folder")
    p.add_argument("--folders-from", type=Path, default=None, metavar="SAFETY_ALONE_JSON",
                   help="only write the policy folders' evaluations from this earlier run's JSON (runs nothing)")
    ns = p.parse_args(argv)
    if ns.folders_from is not None:
        if not ns.folders_from.is_file():
            raise SystemExit(f"error: --folders-from must be a safety_alone.json, got {str(ns.folders_from)!r}")
        for path in write_folders(json.loads(ns.folders_from.read_text()), ns.folders_from):
            print("wrote", path)
        return
    if not ns.entry or ns.out is None:
        raise SystemExit("error: --entry system=policy-folder[@episodes[:filtered]] (one or more) and --out are required")
    if not 1 <= ns.perturbation_entries <= len(ns.entry):
        raise SystemExit(f"error: --perturbation-entries must be between 1 and the {len(ns.entry)} --entry "
                         f"given, got {ns.perturbation_entries}")
    torch.set_num_threads(1)
    entries = []
    for spec in ns.entry:
        system, sep, folder = spec.partition("=")
        folder, at, count = folder.partition("@")
        count, colon, nf = count.partition(":")
        if not sep or not folder or (at and not count.isdigit()) or (colon and not nf.isdigit()):
            raise SystemExit(f"error: --entry must be system=policy-folder[@episodes[:filtered]], got {spec!r}")
        entries.append((system, Path(folder), int(count) if at else ns.seeds, int(nf) if colon else ns.filter_seeds))
    ns.out.mkdir(parents=True, exist_ok=True)
    result = {"command": "python -m satenv.bench.safety_alone " + " ".join(argv or __import__("sys").argv[1:]),
              "entries": [evaluate_entry(s, f, n, ns.controller_seeds, ns.out / "cache", nf)
                          for s, f, n, nf in entries]}
    if ns.perturbation_seeds:   # the policies under study: the first entries
        n_controller = (min(ns.controller_seeds, ns.perturbation_seeds) if ns.perturbation_controller_seeds is None
                        else ns.perturbation_controller_seeds)
        k = ns.perturbation_entries
        for (s, f, _, _), block in zip(entries[:k], result["entries"][:k], strict=True):
            block["perturbations"] = evaluate_perturbed(s, f, ns.perturbation_seeds, n_controller, ns.out / "cache")
    (ns.out / "safety_alone.json").write_text(json.dumps(result, indent=1, default=float) + "\n")
    plot(result, ns.out / "safety_alone.png")
    if ns.write_folders:
        for path in write_folders(result, ns.out / "safety_alone.json"):
            print("wrote", path)


if __name__ == "__main__":
    main()
