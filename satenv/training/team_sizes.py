"""One policy folder at several team sizes: the network alone and as shipped, on test seeds.

A policy on a fixed observation layout (``obs_neighbours``, :mod:`satenv.training.set_policy`) flies a
team of any size without retraining; this evaluates it on a ladder of tasks (by default the cluster
swarms of 10, 20 and 40 satellites, ``satenv.tasks`` ``cluster-swarm*``) both ways:

* ``network alone`` — ``satenv.training.load(folder, env=env, shielded=False)``;
* ``network + filter`` — behind ``satenv.safety.shield`` with the options of the folder's
  ``env.json`` ``"safety_filter"`` (its defaults for a folder shipped without one, e.g. a DAgger
  round's checkpoint): interventions and infeasible filter steps per agent-step,

and writes a JSON of the aggregates (:func:`satenv.scoring.aggregate`) and every episode record,
rewritten after every (task, variant) so an interrupted run keeps what it finished::

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.training.team_sizes \\
        --policy satenv/training/policies/cluster_swarm_set_dagger_shield --seeds 900000-900019 \\
        --out satenv/training/policies/cluster_swarm_set_dagger_shield/team_sizes.json
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path
from typing import Any

from satenv.training.both_ways import VARIANTS, policy

__all__ = ["DEFAULT_TASKS", "evaluate", "main", "table"]

DEFAULT_TASKS = ("cluster-swarm10", "cluster-swarm20", "cluster-swarm40")
"""The team-size ladder evaluated by default."""


def _policy(folder: Path, env: Any, variant: str) -> Any:
    with warnings.catch_warnings():   # another team size than trained on is the point here
        warnings.filterwarnings("ignore", message="env scenario differs")
        return policy(folder, env, variant, filter_defaults=True)


def evaluate(folder: str | Path, tasks: tuple[str, ...], seeds: tuple[int, ...], env_kwargs: dict[str, Any],
             out: Path | None = None) -> dict[str, Any]:
    """The aggregates and episode records of ``folder`` on every task of ``tasks`` (with
    ``env_kwargs`` on top of the task's, e.g. the folder's ``obs_neighbours``), both ways."""
    from satenv import scoring
    from satenv import tasks as registry

    result: dict[str, Any] = {"policy": str(folder), "seeds": list(seeds), "env_kwargs": env_kwargs, "tasks": {}}
    for name in tasks:
        task = registry.get(name)
        env = task.make_env(**env_kwargs)
        entry = result["tasks"].setdefault(name, {"agents": len(env.possible_agents)})
        for variant in VARIANTS:
            t0 = time.perf_counter()
            records = scoring.run_episodes(env, _policy(Path(folder), env, variant), seeds)
            entry[variant] = {"aggregate": scoring.aggregate(records), "episodes": records,
                              "wall_s": round(time.perf_counter() - t0, 1)}
            print(f"{name} {variant}: {_row(entry[variant]['aggregate'])}", flush=True)
            if out is not None:
                out.write_text(json.dumps(result, indent=1, default=float) + "\n")
    return result


def _row(agg: dict[str, Any]) -> str:
    ips = agg.get("interventions_per_agent_step")
    return (f"success {agg['successes']}/{agg['episodes']}, collision episodes {agg['collision_episodes']}, "
            f"violation episodes {agg['violation_episodes']}"
            + ("" if ips is None else f", interventions {100 * ips:.2f} % of agent-steps, infeasible "
               f"{agg.get('safety_infeasible', 0)}"))


def table(result: dict[str, Any]) -> str:
    """A markdown table of :func:`evaluate`'s result."""
    lines = ["| task | N | variant | success | collision ep. | violation ep. | final error [m] | "
             "convergence [s] | Δv [m/s] | interventions / agent-step | infeasible |",
             "|---|--:|---|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for name, entry in result["tasks"].items():
        for variant in VARIANTS:
            if variant not in entry:
                continue
            a = entry[variant]["aggregate"]
            ips = a.get("interventions_per_agent_step")
            conv = a.get("time_to_converge_s")
            lines.append(f"| {name} | {entry['agents']} | {variant} | {a['successes']}/{a['episodes']} | "
                         f"{a['collision_episodes']} | {a['violation_episodes']} | {a['final_error_m']:.3g} | "
                         f"{'–' if conv is None else f'{conv:.0f}'} | {a['delta_v']:.1f} | "
                         f"{'–' if ips is None else f'{100 * ips:.2f} %'} | {a.get('safety_infeasible', '–')} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    from satenv.cliargs import new_parser
    from satenv.tasks import parse_seeds

    parser = new_parser(prog="satenv team-sizes", description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", required=True, help="policy folder")
    parser.add_argument("--tasks", default=",".join(DEFAULT_TASKS), help="comma-separated satenv.tasks names")
    parser.add_argument("--seeds", default="900000-900019", help="test seeds, A-B or a list")
    parser.add_argument("--env-kwargs", default=None,
                        help="JSON object on top of each task's kwargs (default: the folder's obs_neighbours)")
    parser.add_argument("--out", default=None, help="JSON file written after every (task, variant)")
    args = parser.parse_args(argv)
    folder = Path(args.policy)
    if args.env_kwargs is None:
        trained = json.loads((folder / "env.json").read_text()).get("env_kwargs", {})
        env_kwargs = {k: trained[k] for k in ("obs_neighbours",) if k in trained}
    else:
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise SystemExit(f"error: --env-kwargs must be a JSON object, got {args.env_kwargs!r:.80}")
    tasks = tuple(t.strip() for t in args.tasks.split(",") if t.strip())
    result = evaluate(folder, tasks, parse_seeds(args.seeds), env_kwargs, Path(args.out) if args.out else None)
    print(table(result))
    return result


if __name__ == "__main__":
    main()
