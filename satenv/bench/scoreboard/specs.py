"""What a scoreboard entry is: a task (an env id + kwargs, :mod:`satenv.tasks`) and a named policy.

A task spec builds its env with ``satenv.make(env_id, **kwargs)``; a policy spec builds a
policy with ``factory(env, **kwargs)`` (``factory`` given as ``"module:attribute"``,
:func:`satenv.baselines.registry.resolve`) or, for a trained policy folder, one of its two ways
(:func:`satenv.training.both_ways.policy`). One rule lives here: :func:`policy_fits` (which
policy runs on which env); an episode is scored by :func:`satenv.scoring.episode_record`.
"""

from __future__ import annotations

import fnmatch
import hashlib
import importlib.util
import inspect
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from satenv.training.both_ways import NETWORK_ALONE

__all__ = ["LEARNED_TARGET", "SHIELD_SUFFIX", "PolicySpec", "ScoreboardError", "TaskSpec", "Unavailable",
           "checkpoint_policy", "policy_fits", "resolve", "shielded"]

SHIELD_SUFFIX = "+shield"
"""A policy name ending in this is the policy filtered by :mod:`satenv.safety` (:func:`shielded`)."""
LEARNED_TARGET = "satenv.training.both_ways:policy"
"""How the board builds a policy folder: one of its two ways (``variant`` in its kwargs)."""
NETWORK_SUFFIX = ":network"
"""A shipped policy that ships behind its safety filter, named with this suffix, is its network alone
(``satenv.training.both_ways.policy(folder, env, "network alone")``): the unfiltered numbers beside the
shipped ones."""


class ScoreboardError(ValueError):
    """Bad scoreboard input (unknown name, unreadable checkpoint, incompatible policy, ...)."""


class Unavailable(Exception):
    """An entry whose optional third-party dependency is not installed; ``str`` says which."""


def _check_requires(requires: tuple[str, ...]) -> None:
    for dep in requires:
        if importlib.util.find_spec(dep) is None:
            raise Unavailable(f"optional dependency {dep!r} is not installed")


def resolve(target: str, requires: tuple[str, ...] = ()) -> Callable[..., Any]:
    """The object named by ``"module:attribute"`` (:func:`satenv.baselines.registry.resolve`);
    :class:`Unavailable` if a ``requires`` module (optional third-party dependency) is missing, a
    :class:`ScoreboardError` if the module has no such attribute. Any other import error propagates."""
    from satenv.baselines.registry import ResolveError
    from satenv.baselines.registry import resolve as resolve_target

    _check_requires(requires)
    try:
        return resolve_target(target)
    except ResolveError as err:
        raise ScoreboardError(str(err)) from None


def _fingerprint(payload: Mapping[str, Any]) -> str:
    """Short stable hash of a JSON-able description (records which definition made an episode)."""
    text = json.dumps(payload, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _env_ids() -> tuple[str, ...]:
    import satenv

    return tuple(getattr(satenv, "ENV_IDS", None) or satenv._ENVS)


@dataclass(frozen=True)
class TaskSpec:
    """A task of the board: ``satenv.make(env_id, **kwargs)``, named.

    Args:
        name: the task's name, e.g. ``"platoon-PLF-cw"`` (:mod:`satenv.tasks`).
        env_id: a ``satenv.make`` id, e.g. ``"platoon_v0"``.
        kwargs: keyword arguments of the env.
        description: one line for the scoreboard header.
        requires: optional third-party modules the env needs.
        perturbation: a name of :data:`satenv.perturbations.PERTURBATIONS` the env runs under
            (``<task>@<perturbation>`` entries of the robustness table).

    Success is the env scenario's own rule (``success_tol``, ``collision_voids_success``;
    :func:`satenv.metrics.success`), set through ``kwargs`` like any scenario field.
    """

    name: str
    env_id: str
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    requires: tuple[str, ...] = ()
    perturbation: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ScoreboardError(f"task name must be a non-empty string, got {self.name!r}")
        if self.env_id not in _env_ids():
            raise ScoreboardError(f"task {self.name}: env_id must be one of {list(_env_ids())}, "
                                  f"got {self.env_id!r}")

    def check_available(self) -> None:
        """Raise :class:`Unavailable` if an optional dependency is missing."""
        _check_requires(self.requires)

    def make(self):
        """A fresh env."""
        import satenv

        self.check_available()
        if self.perturbation is None:
            return satenv.make(self.env_id, **dict(self.kwargs))
        from satenv.perturbations import perturbed

        return perturbed(lambda **truth: satenv.make(self.env_id, **{**self.kwargs, **truth}), self.perturbation)

    def success_rule(self) -> dict[str, Any]:
        """The env scenario's success rule, as the board's header and fingerprint record it."""
        scenario = self.make().scenario
        return {"success_tol_m": float(scenario.success_tol),
                "collision_free_success": bool(scenario.collision_voids_success)}

    def fingerprint(self) -> str:
        # the payload keeps the format of logs written before env ids and before the scenario
        # owned its success rule, so that those logs stay resumable: the same definition
        rule = self.success_rule()
        payload = {"targets": [f"satenv.envs.{self.env_id}:parallel_env"],
                   "kwargs": dict(self.kwargs), "success_tol": rule["success_tol_m"],
                   "collision_free_success": rule["collision_free_success"]}
        if self.perturbation is not None:
            from satenv.perturbations import get

            p = get(self.perturbation)
            payload["perturbation"] = {"name": p.name, "description": p.description,
                                       "sigma": [p.sigma_position, p.sigma_velocity]}
        return _fingerprint(payload)


@dataclass(frozen=True)
class PolicySpec:
    """A named policy: ``factory(env, **kwargs)``, or ``satenv.training.load(checkpoint)``.

    Args:
        name: scoreboard name, e.g. ``"dmpc"``.
        target: ``"module:attribute"`` of the policy class / factory
            (``"satenv.training.both_ways:policy"`` for a policy folder).
        kwargs: keyword arguments after ``env``.
        env_ids: the env ids the policy controls (``None``: any env); a learned policy's comes
            from its folder's ``env.json``.
        tasks: ``fnmatch`` patterns of the board's tasks the policy is ranked on (``None``: every
            task it fits); a policy folder may ask for this in its ``scoreboard.json``
            (``{"scenarios": [...]}``), e.g. only the task it was trained for.
        description: one line for the scoreboard header.
        checkpoint: path of a trained policy folder.
        requires: optional third-party modules (e.g. the QP solver).
        dry_run: act once on a reset env before the run to check compatibility (cheap policies).
        learned: a trained network (its observation space is checked against the env's).
        baseline: the ``satenv.baselines.BASELINES`` name of a scripted policy: where it applies is its
            class's ``supports(env)`` (then ``env_ids`` is not used).
        shield: the policy runs behind the safety filter (``satenv.baselines.make("shield", env,
            policy=...)``; :func:`shielded`).
    """

    name: str
    target: str
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    env_ids: tuple[str, ...] | None = None
    tasks: tuple[str, ...] | None = None
    description: str = ""
    checkpoint: str | None = None
    requires: tuple[str, ...] = ()
    dry_run: bool = True
    learned: bool = False
    baseline: str | None = None
    shield: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ScoreboardError(f"policy name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.target, str) or ":" not in self.target:
            raise ScoreboardError(f"policy {self.name}: target must be a 'module:attribute' string, "
                                  f"got {self.target!r}")
        for attr in ("env_ids", "tasks"):
            value = getattr(self, attr)
            if value is not None and (isinstance(value, str) or not value):
                raise ScoreboardError(f"policy {self.name}: {attr} must be a non-empty tuple of "
                                      f"strings or None, got {value!r}")

    def ranked_on(self, task: str) -> bool:
        """Whether the board runs this policy on the task named ``task`` (if it fits); a
        perturbed task ``<task>@<perturbation>`` counts as its task."""
        base = task.partition("@")[0]
        return self.tasks is None or any(fnmatch.fnmatchcase(base, p) for p in self.tasks)

    def factory(self) -> Callable[..., Any]:
        return resolve(self.target, self.requires)

    def check_available(self) -> None:
        """Raise :class:`Unavailable` if an optional dependency is missing."""
        _check_requires(self.requires)

    def make(self, env):
        """A fresh policy for ``env``."""
        fn = self.factory()
        if self.checkpoint is not None:
            policy = checkpoint_policy(fn, self.checkpoint, env, **dict(self.kwargs))
        else:
            policy = fn(env, **dict(self.kwargs))
        if self.shield:
            from satenv import baselines
            return baselines.make("shield", env, policy=policy)
        return policy

    def fingerprint(self) -> str:
        payload: dict[str, Any] = {"targets": [self.target], "kwargs": dict(self.kwargs)}
        if self.target == LEARNED_TARGET:  # the format of logs written when folders loaded through
            # satenv.training.load(folder, env=env, shielded=...) directly: the same definition, still resumable
            alone = self.kwargs.get("variant") == NETWORK_ALONE
            payload = {"targets": ["satenv.training:load"], "kwargs": {"shielded": False} if alone else {}}
        if self.checkpoint is not None:
            payload["checkpoint"] = _content_hash(Path(self.checkpoint))
        if self.shield:
            payload["shield"] = True
        return _fingerprint(payload)


def shielded(spec: PolicySpec) -> PolicySpec:
    """``spec`` behind the safety filter, named ``<name>+shield`` (ranked beside ``spec``)."""
    from dataclasses import replace

    if spec.shield:
        return spec
    return replace(spec, name=spec.name + SHIELD_SUFFIX, shield=True,
                   description=(spec.description + " " if spec.description else "") + "+ safety filter")


def policy_fits(spec: PolicySpec, env) -> bool:
    """Whether the policy ``spec`` can control ``env`` (THE applicability rule of the board).

    A scripted policy: its baseline class's ``supports(env)`` (the policy registry of
    ``baselines``); a learned one: the env's id (``env.metadata["name"]``) against the env ids of
    its folder's ``env.json``.
    """
    if spec.baseline is not None:
        from satenv import baselines
        return bool(baselines.get(spec.baseline).supports(env))
    return spec.env_ids is None or env.metadata.get("name") in spec.env_ids


def _content_hash(path: Path) -> str:
    """Hash of a checkpoint file, or of a checkpoint directory: its ``manifest.json`` (which
    lists the sha256 of every file ``satenv.training.load`` reads), else every regular file under it
    (symbolic links not followed, read in chunks)."""
    from satenv.training.trust import sha256_file

    h = hashlib.sha256()
    manifest = path / "manifest.json"
    files = [path] if not path.is_dir() else [manifest] if manifest.is_file() and not manifest.is_symlink() \
        else sorted(p for p in path.rglob("*") if p.is_file() and not p.is_symlink())
    for p in files:
        h.update(str(p.relative_to(path) if path.is_dir() else p.name).encode())
        try:
            h.update(sha256_file(p).encode())
        except OSError:
            h.update(b"<unreadable>")
    return h.hexdigest()[:16]


def checkpoint_policy(load: Callable[..., Any], path: str, env, **kwargs: Any) -> Any:
    """``load(path, **kwargs)`` (passing ``env=env`` when the loader accepts it) as a policy for ``env``."""
    try:
        params = inspect.signature(load).parameters
    except (TypeError, ValueError):
        params = {}
    policy = load(path, env=env, **kwargs) if "env" in params else load(path, **kwargs)
    for method in ("reset", "act"):
        if not callable(getattr(policy, method, None)):
            raise ScoreboardError(f"satenv.training.load({path!r}) returned {type(policy).__name__}, which has "
                                  f"no {method}() method; expected a policy with reset(seed) and "
                                  f"act(observations)")
    if not hasattr(policy, "info"):
        try:
            policy.info = {}
        except AttributeError:
            pass
    return policy
