"""The one table of scripted baselines: name -> ``"module:Class"`` (imported lazily).

``satenv.baselines.make(name, env, **options)`` builds one, ``satenv.baselines.get(name)`` returns its class,
``satenv.baselines.supporting(env)`` lists the names whose class can control ``env`` (each class's
``supports(env)``: by ``env.metadata["name"]`` and scenario properties). The scoreboard
(``benchmarks.registry``) and the training evaluation (``satenv.training.evaluate``) ask this table.

A module is imported only when its class is needed: ``supporting(env, cheap=True)`` imports the
cheap baselines alone (:data:`CHEAP`), so it works without the ``mpc`` extra's solvers (casadi,
daqp, osqp), as the ``rllib`` and ``marl`` extras install it.
"""

from __future__ import annotations

import importlib
from typing import Any

from satenv.baselines.base import BaselineError, is_satenv_env

__all__ = ["BASELINES", "CHEAP", "WRAPPERS", "get", "make", "supporting"]

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


def get(name: str) -> type:
    """The class registered as ``name`` (imports its module on first use)."""
    table = {**BASELINES, **WRAPPERS}
    if not isinstance(name, str) or name not in table:
        raise BaselineError(f"unknown baseline {name!r}; expected one of {sorted(BASELINES)} "
                            f"(or a wrapper: {sorted(WRAPPERS)})")
    module, _, attr = table[name].partition(":")
    return getattr(importlib.import_module(module), attr)


def make(name: str, env: Any, **options: Any) -> Any:
    """``get(name)(env, **options)``: a baseline policy for ``env``."""
    return get(name)(env, **options)


def supporting(env: Any, *, cheap: bool = False) -> list[str]:
    """Names of the baselines that can control ``env`` (registry order).

    ``cheap=True`` keeps only those of :data:`CHEAP` (no per-decision NLP: ``zero``, ``random``,
    ``dmpc``, ``apf``), for quick evaluations, and imports no other baseline module.
    """
    if not is_satenv_env(env):
        return [n for n in ("zero", "random") if get(n).supports(env)]
    names = [n for n in BASELINES if n in CHEAP or not cheap]
    return [n for n in names if get(n).supports(env)]
