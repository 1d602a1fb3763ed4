"""Scripted baseline controllers, acting through the same policy interface as learned ones.

``policy = baselines.DMPC(env)``; ``policy.reset(seed)``; ``actions = policy.act(observations)``.
Heavy solver dependencies (daqp, casadi) are imported only when a baseline is used.
"""

from __future__ import annotations

import importlib
from typing import Any

from baselines.base import Policy, RandomPolicy, ZeroPolicy

_LAZY = {
    "DMPC": "baselines.dmpc",
    "TubeRDMPC": "baselines.tube_rdmpc",
    "APF": "baselines.apf",
    "NMPC": "baselines.nmpc",
    "CGMRES": "baselines.cgmres",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'baselines' has no attribute {name!r}")


__all__ = ["APF", "CGMRES", "DMPC", "NMPC", "Policy", "RandomPolicy", "TubeRDMPC", "ZeroPolicy"]
