"""satenv: multi-agent spacecraft formation-flying environments and baselines.

Environments (PettingZoo ``ParallelEnv``s; ``preset="<paper>"`` selects a paper's scenario)::

    import satenv
    env = satenv.platoon_v0()            # leader-follower platooning on V-bar (pereira2023)
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

_ENVS = {
    "platoon_v0": "satenv.envs.platoon_v0",
    "cluster_v0": "satenv.envs.cluster_v0",
    "servicing_v0": "satenv.envs.servicing_v0",
    "formation_v0": "satenv.envs.formation_v0",
}
ENV_IDS: tuple[str, ...] = tuple(_ENVS)
"""The satenv env ids (``satenv.make(env_id)``)."""


def _make(name: str, **kwargs: Any):
    import importlib

    return importlib.import_module(_ENVS[name]).parallel_env(**kwargs)


def platoon_v0(**kwargs: Any):
    """Leader-follower platooning on V-bar (pereira2023 / pereira2022 §5.1); see ``satenv.envs.platoon_v0``."""
    return _make("platoon_v0", **kwargs)


def cluster_v0(**kwargs: Any):
    """10-satellite cluster reconfiguration with a moving obstacle (li2022); see ``satenv.envs.cluster_v0``."""
    return _make("cluster_v0", **kwargs)


def servicing_v0(**kwargs: Any):
    """6-DOF cooperative on-orbit servicing (pereira2022 §4); see ``satenv.envs.servicing_v0``."""
    return _make("servicing_v0", **kwargs)


def formation_v0(**kwargs: Any):
    """Connected in-plane network formations (kannan2022); see ``satenv.envs.formation_v0``."""
    return _make("formation_v0", **kwargs)


def make(env_id: str, **kwargs: Any):
    """Build an environment by id, e.g. ``satenv.make("platoon_v0", topology="BDL")``."""
    if env_id not in _ENVS:
        raise ValueError(f"unknown env id {env_id!r}; expected one of {sorted(_ENVS)}")
    return _make(env_id, **kwargs)


__all__ = ["ENV_IDS", "__version__", "cluster_v0", "formation_v0", "make", "platoon_v0", "servicing_v0"]
