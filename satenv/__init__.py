"""satenv: multi-agent spacecraft formation-flying environments and baselines.

Environments (PettingZoo ``ParallelEnv``s; ``preset="<paper>"`` selects a paper's scenario)::

    import satenv
    env = satenv.platoon_v0()            # leader-follower platooning on V-bar (pereira2023)
    env = satenv.make("cluster_v0", randomize=True)

``satenv.make`` and the four factories are the one table of envs (``ENV_IDS``). ``import satenv``
also registers the centralised single-agent Gymnasium view (:mod:`satenv.gym_env`) under the ids
of ``GYM_IDS``, e.g. ``gymnasium.make("satenv/Platoon-v0", max_steps=100)``.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

_MODULES = {
    "platoon_v0": "satenv.envs.platoon_v0",
    "cluster_v0": "satenv.envs.cluster_v0",
    "servicing_v0": "satenv.envs.servicing_v0",
    "formation_v0": "satenv.envs.formation_v0",
}

ENV_IDS: tuple[str, ...] = tuple(_MODULES)
"""Every satenv env id, for :func:`make`."""

GYM_IDS: dict[str, str] = {
    "satenv/Platoon-v0": "platoon_v0",
    "satenv/Cluster-v0": "cluster_v0",
    "satenv/Servicing-v0": "servicing_v0",
    "satenv/Formation-v0": "formation_v0",
}
"""Gymnasium id -> satenv env id of the centralised single-agent view (registered on import)."""


def make(env_id: str, *, safety_filter: Any = False, **kwargs: Any):
    """Build an environment by id, e.g. ``satenv.make("platoon_v0", topology="BDL")``.

    ``safety_filter=True`` (or a ``satenv.safety.SafetyConfig``) filters every step's actions
    (:func:`satenv.safety.filtered_env`)."""
    if not isinstance(env_id, str) or env_id not in _MODULES:
        from satenv.errors import SatenvError, SatenvTypeError

        err = SatenvError if isinstance(env_id, str) else SatenvTypeError
        raise err(f"unknown env id {env_id!r:.80}; expected one of {list(ENV_IDS)}")
    import importlib

    env = importlib.import_module(_MODULES[env_id]).parallel_env(**kwargs)
    if safety_filter is False:
        return env
    from satenv.safety import filtered_env, safety_config

    return filtered_env(env, safety_config(safety_filter))


class EnvModule:
    """``satenv.platoon_v0`` and its siblings: callable (``satenv.platoon_v0(**kwargs)`` is
    ``satenv.make("platoon_v0", **kwargs)``) and usable as PettingZoo's env module
    (``from satenv import platoon_v0; platoon_v0.parallel_env()``, ``platoon_v0.env()`` for the
    AEC view; every other name comes from ``satenv.envs.platoon_v0``)."""

    def __init__(self, env_id: str, doc: str) -> None:
        self.env_id = env_id
        self.__doc__ = doc

    def __call__(self, **kwargs: Any):
        return make(self.env_id, **kwargs)

    def parallel_env(self, **kwargs: Any):
        """The PettingZoo ``ParallelEnv`` (``satenv.make(env_id, **kwargs)``)."""
        return make(self.env_id, **kwargs)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        import importlib

        return getattr(importlib.import_module(_MODULES[self.env_id]), name)

    def __repr__(self) -> str:
        return f"<satenv env module {self.env_id!r} ({_MODULES[self.env_id]})>"


platoon_v0 = EnvModule("platoon_v0", "Leader-follower platooning on V-bar (pereira2023 / pereira2022 §5.1); "
                                     "see ``satenv.envs.platoon_v0``.")
cluster_v0 = EnvModule("cluster_v0", "10-satellite cluster reconfiguration with a moving obstacle (li2022); "
                                     "see ``satenv.envs.cluster_v0``.")
servicing_v0 = EnvModule("servicing_v0", "6-DOF cooperative on-orbit servicing (pereira2022 §4); "
                                         "see ``satenv.envs.servicing_v0``.")
formation_v0 = EnvModule("formation_v0", "Connected in-plane network formations (kannan2022); "
                                         "see ``satenv.envs.formation_v0``.")


def make_vec(env_id: str, num_envs: int, *, seed: int | None = None, safety_filter: Any = False, **kwargs: Any):
    """``num_envs`` batched copies of ``make(env_id, **kwargs)`` (numpy); see ``satenv.vector``.
    ``safety_filter``: as in :func:`make` (:func:`satenv.vector.filtered_vec`)."""
    if safety_filter is not False:
        from satenv.safety import safety_config
        from satenv.vector import filtered_vec

        return filtered_vec(make(env_id, **kwargs), num_envs, seed=seed, config=safety_config(safety_filter))
    from satenv.vector import make_vec as _make_vec

    return _make_vec(env_id, num_envs, seed=seed, **kwargs)


GYM_MAX_EPISODE_STEPS: dict[str, int] = {"platoon_v0": 300, "cluster_v0": 400, "servicing_v0": 1200,
                                          "formation_v0": 2000}
"""The longest ``max_steps`` of each env's presets (tests/test_env_surface.py checks it). The
registered Gymnasium ids add no ``TimeLimit``: the env truncates at its own ``max_steps`` (a
``max_steps=`` above this runs to its end) and ``spec.max_episode_steps`` reports it."""


def _register_gymnasium() -> None:
    """Register ``GYM_IDS`` (entry points as strings: nothing of satenv is imported here): the
    centralised env (:mod:`satenv.gym_env`) and, for ``gymnasium.make_vec``, its batched
    ``VectorEnv`` (:mod:`satenv.gym_vector`)."""
    from gymnasium.envs.registration import register, registry

    for gym_id, env_id in GYM_IDS.items():
        if gym_id not in registry:
            register(id=gym_id, entry_point="satenv.gym_env:make_centralised",
                     vector_entry_point="satenv.gym_vector:CentralisedVectorEnv", kwargs={"env": env_id})


_register_gymnasium()

__all__ = ["ENV_IDS", "EnvModule", "GYM_IDS", "GYM_MAX_EPISODE_STEPS", "__version__", "cluster_v0", "formation_v0",
           "make", "make_vec", "platoon_v0", "servicing_v0"]

_SUBMODULES = frozenset({"allocation", "dynamics", "envs", "errors", "metrics", "perturbations", "rollout", "safety",
                         "scenarios", "scoring", "tasks", "vector", "baselines", "training", "bench"})
"""Submodules reachable as attributes after a bare ``import satenv`` (``satenv.tasks.names()``);
each is imported on first use, so ``import satenv`` stays light."""


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        import importlib

        return importlib.import_module(f"satenv.{name}")
    raise AttributeError(f"module 'satenv' has no attribute {name!r}")
