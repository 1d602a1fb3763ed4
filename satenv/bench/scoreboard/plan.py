"""Which episodes a board runs: selection of tasks x policies (names or globs), seeds, and the
preflight that builds every (task, policy) pair once before any episode runs.

A name the user typed must exist and be runnable, and a pair the user named on both sides must
work (else :class:`ScoreboardError`); entries selected by default or by a glob that are not
available (optional dependency missing) or do not fit together are skipped with a note.
"""

from __future__ import annotations

import difflib
import fnmatch
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from satenv.bench.scoreboard.registry import DETERMINISTIC_SEEDS, FULL, QUICK
from satenv.bench.scoreboard.specs import (
    NETWORK_SUFFIX,
    SHIELD_SUFFIX,
    PolicySpec,
    ScoreboardError,
    TaskSpec,
    Unavailable,
    policy_fits,
    shielded,
)

__all__ = ["Plan", "Selection", "board_seeds", "parse_seeds", "preflight", "select", "split_names"]

Key = tuple[str, str, int]


def split_names(value: str | Iterable[str] | None) -> list[str] | None:
    """``"a, b"`` or ``["a", "b"]`` -> ``["a", "b"]``; ``None`` stays ``None`` (everything)."""
    if value is None:
        return None
    items = value.split(",") if isinstance(value, str) else list(value)
    return [s.strip() for s in items if s.strip()]


def parse_seeds(text: str) -> list[int]:
    """``"0-9"``, ``"0,3,7"`` or ``"0-4,10"`` -> sorted unique non-negative ints: the one seeds
    grammar of every CLI (:func:`satenv.tasks.parse_seeds`, capped at its ``MAX_SEEDS``)."""
    from satenv.tasks import parse_seeds as parse

    try:
        return sorted(parse(text))
    except ValueError as err:
        raise ScoreboardError(f"--{err}" if str(err).startswith("seeds") else str(err)) from None


def board_seeds(seeds: list[int] | str | None, quick: bool,
                scenario_seeds: Mapping[str, list[int]] | None) -> tuple[list[int], dict[str, list[int]]]:
    """The board's seeds and per-task seed caps ``scenario_seeds`` (the preset's unless ``seeds``
    are given)."""
    preset = QUICK if quick else FULL
    user_seeds = seeds is not None
    seeds = preset["seeds"] if seeds is None else seeds
    seeds = parse_seeds(seeds) if isinstance(seeds, str) else sorted(set(seeds))
    if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
        raise ScoreboardError(f"seeds must be non-negative integers, got {seeds!r}")
    seeds = [int(s) for s in seeds]
    if scenario_seeds is None:
        scenario_seeds = {} if user_seeds else dict(preset.get("scenario_seeds", {}))
    caps = {name: [s for s in seeds if s in set(lst)] or seeds[:1] for name, lst in scenario_seeds.items()}
    for name in DETERMINISTIC_SEEDS:      # one episode of a deterministic task: no interval on copies
        caps[name] = caps.get(name, seeds)[:1]
    return seeds, caps


@dataclass
class Selection:
    """Names chosen from one registry, and those the user named exactly."""

    names: list[str] = field(default_factory=list)
    explicit: set[str] = field(default_factory=set)


def _unknown(pat: str, registry: Mapping[str, Any], kind: str) -> ScoreboardError:
    close = difflib.get_close_matches(pat, list(registry), n=3)
    hint = f"; did you mean {close}?" if close else ""
    return ScoreboardError(f"unknown {kind} {pat!r}{hint} Registered {kind}s: {sorted(registry)} "
                           f"(see python -m satenv.bench.scoreboard --list)")


def _add(sel: Selection, name: str, spec, exact: bool, kind: str, notes: list[str]) -> None:
    try:
        spec.check_available()
    except Unavailable as why:
        if exact:
            raise ScoreboardError(f"{kind} {name!r} is registered but not available here: {why}. "
                                  "Install what it needs or leave it out.") from None
        notes.append(f"{kind} {name}: skipped ({why})")
        return
    sel.names.append(name)
    if exact:
        sel.explicit.add(name)


def select(requested: list[str] | None, registry: Mapping[str, Any], kind: str, notes: list[str],
           strict: bool) -> Selection:
    """Available registry names matching ``requested`` (names or globs; all when ``None``).

    With ``strict`` (the user typed the selection) an unknown name, or an unavailable one named
    exactly, is an error; otherwise it is skipped with a note. A policy pattern ending in
    ``+shield`` selects the matching policies behind the safety filter (added to ``registry``).
    """
    sel = Selection()
    for pat in requested if requested is not None else ["*"]:
        if pat.endswith(SHIELD_SUFFIX) and kind == "policy":
            _add_shielded(pat[:-len(SHIELD_SUFFIX)], registry)
        if PERTURBATION_SEP in pat and kind == "task":
            _add_perturbed(pat, registry)
        matches = [n for n in registry if fnmatch.fnmatchcase(n, pat)]
        if not matches and kind == "policy" and pat.endswith(SHIELD_SUFFIX) \
                and pat[:-len(SHIELD_SUFFIX)] + NETWORK_SUFFIX in registry:
            notes.append(f"policy {pat!r}: {pat[:-len(SHIELD_SUFFIX)]!r} ships behind the safety filter "
                         f"already (its network alone: {pat[:-len(SHIELD_SUFFIX)] + NETWORK_SUFFIX!r}); skipped")
            continue
        if not matches and strict:
            raise _unknown(pat, registry, kind)
        if not matches:
            notes.append(f"{kind} {pat!r}: not registered (skipped)")
        for name in (n for n in matches if n not in sel.names):
            _add(sel, name, registry[name], strict and pat == name, kind, notes)
    return sel


PERTURBATION_SEP = "@"
"""``<task>@<perturbation>``: a task under a named perturbation (:mod:`satenv.perturbations`)."""


def _add_perturbed(pattern: str, registry: Any) -> None:
    """Register ``<task>@<perturbation>`` for every task matching the part before ``@`` and every
    perturbation matching the part after it that the task lists (``satenv.tasks.Task.perturbations``;
    a board entry that is no registered task takes none)."""
    from satenv import tasks

    base, _, pert = pattern.partition(PERTURBATION_SEP)
    for name in [n for n in registry if fnmatch.fnmatchcase(n, base) and PERTURBATION_SEP not in n]:
        spec = registry[name]
        for p in tasks.TASKS[name].perturbations if name in tasks.TASKS else ():
            if fnmatch.fnmatchcase(p, pert):
                registry.setdefault(f"{name}{PERTURBATION_SEP}{p}", replace(
                    spec, name=f"{name}{PERTURBATION_SEP}{p}", perturbation=p,
                    description=f"{spec.description}; under {p}"))


def _add_shielded(base: str, registry: Any) -> None:
    """Register ``<name>+shield`` (:func:`~satenv.bench.scoreboard.specs.shielded`) for every policy
    matching ``base`` (a name or glob), in ``registry`` (the board's dict of policies); not for a
    shipped policy that ships behind its filter already (it has a ``<name>:network`` twin), nor for
    that twin (behind the filter it is the shipped policy)."""
    for name in [n for n in registry if fnmatch.fnmatchcase(n, base) and not n.endswith(SHIELD_SUFFIX)]:
        if name.endswith(NETWORK_SUFFIX) or name + NETWORK_SUFFIX in registry:
            continue
        registry.setdefault(name + SHIELD_SUFFIX, shielded(registry[name]))


def _check_actions(actions: Any, env) -> None:
    if not isinstance(actions, dict):
        raise ValueError(f"act() returned {type(actions).__name__}, expected a dict keyed by agent")
    if set(actions) != set(env.agents):
        raise ValueError(f"act() returned actions for {sorted(actions)}, expected {sorted(env.agents)}")
    for agent, a in actions.items():
        shape = env.action_space(agent).shape
        arr = np.asarray(a, dtype=float)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            raise ValueError(f"act() returned {arr.tolist()} for {agent}; expected finite shape {shape}")


def _observation_mismatch(policy, env) -> str | None:
    shape = getattr(policy, "obs_shape", None)
    if shape is None:
        shape = getattr(getattr(policy, "observation_space", None), "shape", None)
    if shape is None:
        return None
    want = env.observation_space(env.possible_agents[0]).shape
    if tuple(shape) != tuple(want):
        return f"the policy expects observations of shape {tuple(shape)}, the env gives {tuple(want)}"
    return None


def _try_pair(pol: PolicySpec, env, seed: int) -> str | None:
    """Why ``pol`` cannot run on ``env`` (``None``: it can): build it, check its observation
    space (learned) and act once on a reset env (``dry_run``)."""
    try:
        policy = pol.make(env)
        why = _observation_mismatch(policy, env) if pol.learned else None
        if why is None and pol.dry_run:
            obs, _ = env.reset(seed=seed)
            policy.reset(seed=seed)
            _check_actions(policy.act(obs), env)
        return why
    except ScoreboardError:
        raise
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"


def _build_env(task: TaskSpec):
    try:
        return task.make()
    except Exception as exc:
        raise ScoreboardError(f"task {task.name}: building the env satenv.make({task.env_id!r}, "
                              f"**{dict(task.kwargs)}) failed: {type(exc).__name__}: {exc}") from exc


def preflight(tasks: list[TaskSpec], policies: list[PolicySpec], seed: int,
              strict: Callable[[str, str], bool], notes: list[str]
              ) -> tuple[list[tuple[str, str]], dict[str, str]]:
    """Build every fitting (task, policy) pair once, before any episode runs.

    A failing pair raises :class:`ScoreboardError` when ``strict(task, policy)`` (the user
    named both), else it is skipped with a note. Returns the runnable pairs and each task's
    env id.
    """
    pairs, env_ids = [], {}
    for task in tasks:
        env = _build_env(task)
        env_ids[task.name] = env.metadata.get("name", type(env).__name__)
        for pol in (p for p in policies if p.ranked_on(task.name) and policy_fits(p, env)):
            why = _try_pair(pol, env, seed)
            if why is None:
                pairs.append((task.name, pol.name))
            elif strict(task.name, pol.name):
                raise ScoreboardError(f"policy {pol.name} cannot run on task {task.name}: {why}. "
                                      "Choose compatible tasks with --scenarios.")
            else:
                notes.append(f"policy {pol.name} on {task.name}: skipped ({why})")
        env.close()
    return pairs, env_ids


@dataclass
class Plan:
    """The episodes of a board: runnable pairs, in registry order, times their seeds."""

    pairs: list[tuple[str, str]]
    env_ids: dict[str, str]
    seeds: list[int]
    caps: dict[str, list[int]]

    def seeds_of(self, task: str) -> list[int]:
        return self.caps.get(task, self.seeds)

    @property
    def keys(self) -> list[Key]:
        return [(s, p, seed) for s, p in self.pairs for seed in self.seeds_of(s)]

    def is_example(self, key: Key) -> bool:
        """The first seed of a pair: its trajectory is saved and plotted."""
        return self.seeds_of(key[0])[0] == key[2]


def _supported_envs(spec: PolicySpec) -> tuple[str, ...]:
    """Where a policy spec applies: a baseline's class says (``supported()``), else any env."""
    if spec.baseline is None:
        return ("any env",)
    from satenv.baselines.registry import get

    return (get(spec.baseline).supported(),)


def _unpaired_notes(plan: Plan, policies: Mapping[str, PolicySpec], names: list[str],
                    notes: list[str]) -> None:
    for name in names:
        if not any(p == name for _, p in plan.pairs) and not any(f"policy {name} on" in n for n in notes):
            fits = ", ".join(policies[name].env_ids or _supported_envs(policies[name]))
            notes.append(f"policy {name}: fits none of the selected tasks (it controls {fits})")


def check_explicit(plan: Plan, tasks: Selection, policies: Selection, notes: list[str]) -> None:
    """A task or policy the user named must have something to run with."""
    for kind, sel, idx in (("policy", policies, 1), ("task", tasks, 0)):
        for name in sorted(sel.explicit):
            if not any(pair[idx] == name for pair in plan.pairs):
                raise ScoreboardError(f"{kind} {name} has nothing to run with the selected "
                                      f"{'tasks' if idx else 'policies'}: "
                                      + "; ".join(n for n in notes if name in n)
                                      + " (see --list for which policy fits where)")


def make_plan(task_reg: Mapping[str, TaskSpec], pol_reg: Mapping[str, PolicySpec],
              tasks: Selection, policies: Selection, seeds: list[int],
              caps: dict[str, list[int]], notes: list[str]) -> Plan:
    """Preflight the selection and return the plan (errors as :func:`preflight`)."""
    pairs, env_ids = preflight([task_reg[n] for n in tasks.names], [pol_reg[n] for n in policies.names],
                               seeds[0], lambda s, p: s in tasks.explicit and p in policies.explicit,
                               notes)
    if not pairs:
        raise ScoreboardError("no (task, policy) pair applies: " + "; ".join(notes))
    plan = Plan(pairs, env_ids, seeds, {n: v for n, v in caps.items() if n in env_ids})
    _unpaired_notes(plan, pol_reg, policies.names, notes)
    check_explicit(plan, tasks, policies, notes)
    return plan
