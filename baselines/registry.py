"""The one table of scripted baselines: name -> ``"module:Class"`` (imported lazily).

``baselines.make(name, env, **options)`` builds one, ``baselines.get(name)`` returns its class,
``baselines.supporting(env)`` lists the names whose class can control ``env`` (each class's
``supports(env)``: by ``env.metadata["name"]`` and scenario properties). The scoreboard
(``benchmarks.registry``) and the training evaluation (``training.evaluate``) ask this table.
"""

from __future__ import annotations

import importlib
from typing import Any

from baselines.base import BaselineError, is_satenv_env

__all__ = ["BASELINES", "WRAPPERS", "get", "make", "supporting"]

BASELINES: dict[str, str] = {
    "zero": "baselines.base:ZeroPolicy",
    "random": "baselines.base:RandomPolicy",
    "dmpc": "baselines.dmpc:DMPC",
    "tube_rdmpc": "baselines.tube_rdmpc:TubeRDMPC",
    "apf": "baselines.apf:APF",
    "nmpc": "baselines.nmpc:NMPC",
    "cgmres": "baselines.cgmres:CGMRES",
}
"""Every scripted baseline by name."""

WRAPPERS: dict[str, str] = {"shield": "baselines.shield:Shield"}
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

    ``cheap=True`` keeps only those whose class sets ``cheap = True`` (no per-decision NLP:
    ``zero``, ``random``, ``dmpc``, ``apf``), for quick evaluations.
    """
    if not is_satenv_env(env):
        return [n for n in ("zero", "random") if get(n).supports(env)]
    out = []
    for name in BASELINES:
        cls = get(name)
        if cls.supports(env) and (cls.cheap or not cheap):
            out.append(name)
    return out
