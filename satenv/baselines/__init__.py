"""Scripted baseline controllers, acting through the same policy interface as learned ones.

``policy = satenv.baselines.make("dmpc", env)`` (or ``satenv.baselines.DMPC(env, config=None, **options)``);
``policy.reset(seed)``; ``actions = policy.act(observations)``. ``satenv.baselines.supporting(env)``
lists the baselines that can control an env. Heavy solver dependencies (daqp, casadi) are
imported only when a baseline is used.
"""

from __future__ import annotations

import importlib
from typing import Any

from satenv.baselines.base import BaselineError, BaselineTypeError, Policy, RandomPolicy, ZeroPolicy
from satenv.baselines.registry import BASELINES, get, make, supporting

_LAZY = {
    "DMPC": "satenv.baselines.dmpc", "DMPCConfig": "satenv.baselines.dmpc",
    "TubeRDMPC": "satenv.baselines.tube_rdmpc", "TubeRDMPCConfig": "satenv.baselines.tube_rdmpc",
    "APF": "satenv.baselines.apf", "APFConfig": "satenv.baselines.apf",
    "NMPC": "satenv.baselines.nmpc", "NMPCConfig": "satenv.baselines.nmpc",
    "CGMRES": "satenv.baselines.cgmres", "CGMRESConfig": "satenv.baselines.cgmres",
    "Shield": "satenv.baselines.shield",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'baselines' has no attribute {name!r}")


__all__ = ["APF", "APFConfig", "BASELINES", "BaselineError", "BaselineTypeError", "CGMRES",
           "CGMRESConfig", "DMPC", "DMPCConfig", "NMPC", "NMPCConfig", "Policy", "RandomPolicy",
           "Shield", "TubeRDMPC", "TubeRDMPCConfig", "ZeroPolicy", "get", "make", "supporting"]
