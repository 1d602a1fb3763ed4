"""The one controller registry: scripted baselines and imitation experts, name -> ``"module:Class"``
(imported lazily), and the one resolver of ``"module:attribute"`` strings (:func:`resolve`).

``satenv.baselines.make(name, env, **options)`` builds a baseline, ``satenv.baselines.get(name)``
returns its class, ``satenv.baselines.supporting(env)`` lists the names whose class can control
``env`` (each class's ``supports(env)``: by ``env.metadata["name"]`` and scenario properties).
:func:`make_expert` builds an expert for imitation: a stateless one of :data:`EXPERTS`, else a
baseline. Every controller and expert name of :mod:`satenv.tasks` is a name of this registry. The
scoreboard (``satenv.bench.scoreboard.registry``), the training evaluation
(``satenv.training.evaluate``) and imitation ask this table.

A module is imported only when its class is needed: ``supporting(env, cheap=True)`` imports the
cheap baselines alone (:data:`CHEAP`), so it works without the ``mpc`` extra's solvers (casadi,
daqp, osqp), as the ``rllib`` and ``marl`` extras install it.
"""

from __future__ import annotations

import importlib
from typing import Any

from satenv.baselines.base import BaselineError, is_satenv_env

__all__ = ["BASELINES", "CHEAP", "EXPERTS", "EXPERT_OPTIONS", "WRAPPERS", "ResolveError", "get", "get_expert", "make",
           "make_expert", "resolve", "supporting"]

BASELINES: dict[str, str] = {
    "zero": "satenv.baselines.base:ZeroPolicy",
    "random": "satenv.baselines.base:RandomPolicy",
    "dmpc": "satenv.baselines.dmpc:DMPC",
    "tube_rdmpc": "satenv.baselines.tube_rdmpc:TubeRDMPC",
    "apf": "satenv.baselines.apf:APF",
    "nmpc": "satenv.baselines.nmpc:NMPC",
    "cgmres": "satenv.baselines.cgmres:CGMRES",
}
"""Every scripted baseline by name."""

CHEAP: frozenset[str] = frozenset({"zero", "random", "dmpc", "apf"})
"""The baselines without a per-decision NLP (their class sets ``cheap = True``; a test checks the
two agree): :func:`supporting` with ``cheap=True`` imports these modules only."""

WRAPPERS: dict[str, str] = {"shield": "satenv.baselines.shield:Shield"}
"""Policy wrappers by name: ``make(name, env, policy=...)`` wraps another policy (not baselines on
their own: :func:`supporting` never lists them)."""

EXPERTS: dict[str, str] = {"joint_platoon_mpc": "satenv.baselines.experts:JointPlatoonMPC",
                           "replanning_tube_rdmpc": "satenv.baselines.experts:ReplanningTubeRDMPC"}
"""The stateless experts for imitation (:mod:`satenv.baselines.experts`) by name; every other
expert name is a baseline of :data:`BASELINES`. :data:`satenv.tasks.SYSTEMS` names each system's expert."""


EXPERT_OPTIONS: dict[str, dict[str, Any]] = {"nmpc": {"solver": "rti"}, "replanning_tube_rdmpc": {"solver": "rti"}}
"""Default options of an expert built by :func:`make_expert` (the call's options replace them): the
NMPC labels with its real-time iteration and the cluster's re-planning tube-RDMPC by sequential
convexification, one QP per decision each, whose closed loops are within 2 % of ipopt's on the
reproduction's problems (``python -m satenv.bench.perf.experts``)."""


class ResolveError(BaselineError):
    """A ``"module:attribute"`` string that names nothing."""


def resolve(target: str) -> Any:
    """The object named by ``"module:attribute"`` (the one resolver of such strings: the registries
    here, the scoreboard's policy targets, the training envs' ids). A malformed string or a module
    without that attribute is a :class:`ResolveError`; an import error of the module propagates
    (a missing optional dependency stays a ``ModuleNotFoundError``)."""
    module, sep, attr = target.partition(":") if isinstance(target, str) else ("", "", "")
    if not (module and sep and attr):
        raise ResolveError(f"expected a 'module:attribute' string, got {target!r}")
    obj = getattr(importlib.import_module(module), attr, None)
    if obj is None:
        raise ResolveError(f"{target!r}: module {module} has no attribute {attr!r}")
    return obj


def get(name: str) -> type:
    """The class registered as ``name`` (imports its module on first use)."""
    table = {**BASELINES, **WRAPPERS}
    if not isinstance(name, str) or name not in table:
        raise BaselineError(f"unknown baseline {name!r}; expected one of {sorted(BASELINES)} "
                            f"(or a wrapper: {sorted(WRAPPERS)})")
    return resolve(table[name])


def make(name: str, env: Any, **options: Any) -> Any:
    """``get(name)(env, **options)``: a baseline policy for ``env``."""
    return get(name)(env, **options)


def get_expert(name: str) -> type:
    """The class of the expert called ``name``: a stateless expert of :data:`EXPERTS`, else the
    baseline (:func:`get`)."""
    if isinstance(name, str) and name in EXPERTS:
        return resolve(EXPERTS[name])
    if not isinstance(name, str) or name not in BASELINES:
        raise BaselineError(f"unknown expert {name!r}; expected one of {sorted(EXPERTS)} or a baseline "
                            f"{sorted(BASELINES)}")
    return get(name)


def make_expert(name: str, env: Any, **options: Any) -> Any:
    """``get_expert(name)(env, **options)``: the expert called ``name`` for ``env``, with the
    defaults of :data:`EXPERT_OPTIONS` under ``options``."""
    return get_expert(name)(env, **{**EXPERT_OPTIONS.get(name, {}), **options})


def supporting(env: Any, *, cheap: bool = False) -> list[str]:
    """Names of the baselines that can control ``env`` (registry order).

    ``cheap=True`` keeps only those of :data:`CHEAP` (no per-decision NLP: ``zero``, ``random``,
    ``dmpc``, ``apf``), for quick evaluations, and imports no other baseline module.
    """
    if not is_satenv_env(env):
        return [n for n in ("zero", "random") if get(n).supports(env)]
    names = [n for n in BASELINES if n in CHEAP or not cheap]
    return [n for n in names if get(n).supports(env)]
