"""The scoreboard's tables: every task and scripted policy by name, the ``--quick`` and full
boards, shipped trained policies (``satenv/training/policies/*``) and user checkpoints (``--policy``).

The board's tasks are those of :mod:`satenv.tasks` (add a task there); adding a baseline is one
entry here::

    POLICIES["apf"] = PolicySpec("apf", "satenv.baselines:APF", baseline="apf")  # where: APF.supports(env)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from satenv import tasks
from satenv.bench.scoreboard.specs import (
    LEARNED_TARGET,
    NETWORK_SUFFIX,
    PolicySpec,
    ScoreboardError,
    TaskSpec,
)
from satenv.training.both_ways import AS_SHIPPED, NETWORK_ALONE

__all__ = ["DETERMINISTIC_SEEDS", "FULL", "POLICIES", "QUICK", "TASKS", "discover_trained_policies",
           "user_policy", "user_policy_name"]

SHIPPED_POLICY_DIR = Path(__file__).resolve().parents[2] / "training" / "policies"

TASKS: dict[str, TaskSpec] = {t.name: TaskSpec(t.name, t.env_id, dict(t.paper_env_kwargs), t.description)
                              for t in tasks.TASKS.values()}
"""Every task of the scoreboard by name: the tasks of :mod:`satenv.tasks` (one registry), each with
the paper's cost (``Task.paper_env_kwargs``: a training task's training reward left out)."""

POLICIES: dict[str, PolicySpec] = {p.name: p for p in [
    PolicySpec("zero", "satenv.baselines.base:ZeroPolicy", baseline="zero", description="no thrust (coasting)"),
    PolicySpec("random", "satenv.baselines.base:RandomPolicy", baseline="random",
               description="uniform random thrust"),
    PolicySpec("dmpc", "satenv.baselines:DMPC", baseline="dmpc", requires=("daqp",),
               description="1-hop distributed MPC (pereira2023/2022)"),
    PolicySpec("tube_rdmpc", "satenv.baselines:TubeRDMPC", baseline="tube_rdmpc", requires=("casadi",),
               dry_run=False, description="tube-based robust DMPC (li2022)"),
    PolicySpec("apf", "satenv.baselines:APF", baseline="apf",
               description="artificial potential field (li2022)"),
    PolicySpec("nmpc", "satenv.baselines:NMPC", baseline="nmpc", requires=("casadi",),
               dry_run=False, description="cooperative NMPC (pereira2022 §4)"),
    PolicySpec("tube_rdmpc_rti", "satenv.baselines:TubeRDMPC", {"solver": "rti"}, baseline="tube_rdmpc",
               requires=("casadi", "daqp"), dry_run=False,
               description="tube-based robust DMPC (li2022) by sequential convexification: QPs, not the NLP"),
    PolicySpec("nmpc_rti", "satenv.baselines:NMPC", {"solver": "rti"}, baseline="nmpc", requires=("casadi", "daqp"),
               dry_run=False, description="cooperative NMPC (pereira2022 §4) by real-time iteration: a QP a decision"),
    PolicySpec("cgmres", "satenv.baselines:CGMRES", baseline="cgmres", requires=("casadi",),
               dry_run=False, description="centralised C/GMRES NMPC (kannan2022)"),
]}
"""Every scripted policy by name; shipped trained policies are added by
:func:`discover_trained_policies`."""

QUICK: dict[str, Any] = {
    "scenarios": ["platoon-PLF-cw", "platoon-BDL-j2", "platoon-chain-cw", "platoon-tplf30-random-cw",
                  "platoon-pereira2022", "formation-kannan2022-position", "cluster-case1",
                  "servicing-pereira2022"],
    "policies": ["zero", "random", "dmpc", "apf", "cgmres", "trained:*"],   # no NMPC: minutes an episode
    "seeds": tasks.show_seeds(tasks.SEED_SPLITS["test"][:3]),
    "scenario_seeds": {},
}
"""The ``--quick`` board (the README's first command): a few minutes on 2 cores at most. Seeds are
the first test seeds of :data:`satenv.tasks.SEED_SPLITS`; a deterministic task runs one."""

FULL: dict[str, Any] = {
    "seeds": tasks.show_seeds(tasks.SEED_SPLITS["test"][:10]),
    # the costliest pairs: tube-RDMPC ~0.6 s x 400 decisions per cluster episode, NMPC ~0.8 s x
    # 1200 decisions per servicing episode (measured on 2 shared cores); 256 agents: the DMPC
    # takes ~0.5 s per decision of the whole swarm
    "scenario_seeds": {name: list(tasks.get(name).seeds("test", n)) for name, n in (
        ("platoon-swarm256-ring-cw", 3), ("cluster-swarm64-cw", 3), ("cluster-case1-random", 5),
        ("cluster-swarm10", 3), ("cluster-swarm20", 3), ("cluster-swarm40", 3),
        ("servicing-pereira2022-random", 3))},
}
"""The full (published) board: every task x fitting policy x these test seeds (a deterministic
task runs one)."""

DETERMINISTIC_SEEDS = {name: [t.seeds("test")[0]] for name, t in tasks.TASKS.items() if not t.randomized}
"""A task that does not randomise its start runs one seed (every seed gives the same episode)."""


def _folder_env(path: Path) -> dict[str, Any]:
    """A policy folder's ``env.json`` (``{}`` when it has none or it is unreadable)."""
    from satenv.training.trust import (
        read_json,  # a folder's files are untrusted: no links, sizes capped
    )

    try:
        meta = read_json(path, "env.json")
    except (OSError, ValueError):
        return {}
    return meta if isinstance(meta, dict) else {}


def _env_ids(meta: dict[str, Any]) -> tuple[str, ...] | None:
    """The env id of a folder's ``env.json`` (``None`` when it has none)."""
    env_id = meta.get("env_id")
    return (env_id,) if isinstance(env_id, str) and env_id else None


def _folder_tasks(path: Path) -> tuple[str, ...] | None:
    """The task patterns of a policy folder's optional ``scoreboard.json`` (its key ``"scenarios"``)."""
    from satenv.training.trust import (
        read_json,  # a folder's files are untrusted: no links, sizes capped
    )

    meta = path / "scoreboard.json"
    if not meta.is_file():
        return None
    try:
        return tuple(read_json(path, "scoreboard.json")["scenarios"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ScoreboardError(f"{meta}: expected JSON {{\"scenarios\": [patterns]}}, got an "
                              f"unreadable file ({exc})") from None


def _learned(name: str, path: Path, description: str, ranked: tuple[str, ...] | None,
             meta: dict[str, Any] | None = None, variant: str = AS_SHIPPED) -> PolicySpec:
    """A policy folder, one of its two ways (:func:`satenv.training.both_ways.policy`)."""
    return PolicySpec(name, LEARNED_TARGET, {"variant": variant},
                      env_ids=_env_ids(_folder_env(path) if meta is None else meta), tasks=ranked,
                      checkpoint=str(path), learned=True, requires=("torch",), description=description)


def discover_trained_policies(root: Path = SHIPPED_POLICY_DIR) -> dict[str, PolicySpec]:
    """One ``trained:<name>`` entry per shipped artefact folder under ``satenv/training/policies/``; it
    fits the env it was trained on (``env.json``'s ``env_id``) and is ranked on the tasks of
    its optional ``scoreboard.json``. A folder that ships behind the safety filter also gets
    ``trained:<name>:network``, its network alone (:data:`~satenv.bench.scoreboard.specs.NETWORK_SUFFIX`)."""
    if not root.is_dir():
        return {}
    folders = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith((".", "_")))
    out = {}
    for p in folders:
        name, ranked, meta = f"trained:{p.name}", _folder_tasks(p), _folder_env(p)
        out[name] = _learned(name, p, f"shipped trained policy {p.name}", ranked, meta)
        if meta.get("safety_filter") is not None:    # ships behind the filter: its network alone too
            out[name + NETWORK_SUFFIX] = _learned(name + NETWORK_SUFFIX, p, f"the network of {p.name} alone, "
                                                  "without the safety filter it ships with", ranked, meta,
                                                  variant=NETWORK_ALONE)
    return out


GENERIC_FOLDER_NAMES = ("final", "best", "last", "latest", "model", "policy")
"""Folder names that say which checkpoint of a run, not which run: ``--policy`` names them by
their parent (``runs/a/final`` -> ``user:a``); so are ``checkpoint*`` / ``ckpt*`` / ``step*``."""


def user_policy_name(path: str | Path) -> str:
    """``user:<run>`` for a ``--policy`` folder: its own name, or its parent's when the folder's
    name is generic (``runs/a/final`` -> ``user:a``, ``runs/b/checkpoint-4096`` -> ``user:b``)."""
    p = Path(path).resolve()
    generic = (p.name.lower() in GENERIC_FOLDER_NAMES
               or p.name.lower().startswith(("checkpoint", "ckpt", "step")))
    return f"user:{p.parent.name if generic and p.parent.name else p.name}"


def _load_or_raise(path: str) -> None:
    try:
        from satenv import training
    except ModuleNotFoundError as exc:
        raise ScoreboardError(f"--policy needs the training package ({exc})") from None
    try:
        training.load(path, shielded=False)
    except Exception as exc:
        raise ScoreboardError(f"--policy {path}: cannot load this checkpoint: {type(exc).__name__}: "
                              f"{exc}") from None


def user_policy(path: str) -> PolicySpec:
    """The spec of a ``--policy`` folder, after checking that it exists and loads; it runs on
    every selected task of its env (``--scenarios`` chooses; its ``scoreboard.json`` does not)."""
    p = Path(path)
    if not p.exists():
        raise ScoreboardError(f"--policy {path}: no such file or directory; pass the path of a "
                              "checkpoint saved by training (e.g. runs/<run>/final)")
    if not os.access(p, os.R_OK):
        raise ScoreboardError(f"--policy {path}: not readable (check its permissions)")
    _load_or_raise(str(p))
    return _learned(user_policy_name(p), p, f"user checkpoint {path}", None)


def user_policies(paths: list[str], taken: dict[str, PolicySpec]) -> list[PolicySpec]:
    """Specs of the ``--policy`` folders; a name clash (with each other or ``taken``) is an error."""
    specs: dict[str, PolicySpec] = {}
    for path in paths:
        spec = user_policy(path)
        other = specs.get(spec.name) or taken.get(spec.name)
        if other is not None:
            raise ScoreboardError(f"--policy {path} and {other.checkpoint or other.name} are both named "
                                  f"{spec.name!r} (named after the run folder): rename one of the run "
                                  "folders or pass distinct runs")
        specs[spec.name] = spec
    return list(specs.values())
