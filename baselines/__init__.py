"""Scripted baseline controllers, acting through the same policy interface as learned ones.

``policy = baselines.make("dmpc", env)`` (or ``baselines.DMPC(env, config=None, **options)``);
``policy.reset(seed)``; ``actions = policy.act(observations)``. ``baselines.supporting(env)``
lists the baselines that can control an env. Heavy solver dependencies (daqp, casadi) are
imported only when a baseline is used.
"""

from __future__ import annotations

import importlib
from typing import Any

from baselines.base import BaselineError, BaselineTypeError, Policy, RandomPolicy, ZeroPolicy
from baselines.registry import BASELINES, get, make, supporting

_LAZY = {
    "DMPC": "baselines.dmpc", "DMPCConfig": "baselines.dmpc",
    "TubeRDMPC": "baselines.tube_rdmpc", "TubeRDMPCConfig": "baselines.tube_rdmpc",
    "APF": "baselines.apf", "APFConfig": "baselines.apf",
    "NMPC": "baselines.nmpc", "NMPCConfig": "baselines.nmpc",
    "CGMRES": "baselines.cgmres", "CGMRESConfig": "baselines.cgmres",
    "Shield": "baselines.shield",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'baselines' has no attribute {name!r}")


__all__ = ["APF", "APFConfig", "BASELINES", "BaselineError", "BaselineTypeError", "CGMRES",
           "CGMRESConfig", "DMPC", "DMPCConfig", "NMPC", "NMPCConfig", "Policy", "RandomPolicy",
           "Shield", "TubeRDMPC", "TubeRDMPCConfig", "ZeroPolicy", "get", "make", "supporting"]
