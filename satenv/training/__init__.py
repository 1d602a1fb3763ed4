"""Training learned policies for satenv scenarios (stable-baselines3, BenchMARL, Ray RLlib).

* :func:`load` — a trained policy folder (or a run folder: its ``final/``) -> a policy with the
  baseline interface (``reset(seed=None)``, ``act(observations) -> actions``); never unpickles
  (:mod:`satenv.training.policy`: what is safe to load); a folder shipped behind its safety filter needs
  ``env=`` (or ``shielded=False`` for the network alone), else :class:`ShippedFilterError`.
* :class:`satenv.training.vec_env.SatVecEnv` — parameter-shared SB3 ``VecEnv`` over ``satenv.make_vec``.
* ``python -m satenv.training.train`` — SB3 PPO/SAC training (:class:`satenv.training.config.TrainConfig`).
* ``python -m satenv.training.benchmarl_train`` — BenchMARL (MAPPO, ...) on the native TorchRL env.
* ``python -m satenv.training.rllib_train`` — the same scenarios with Ray RLlib (optional extra).
* ``satenv/training/policies/<name>/`` — shipped trained policies (:data:`SHIPPED`).
"""

from __future__ import annotations

from pathlib import Path

from .config import TrainConfig
from .policy import LearnedPolicy, PolicyLoadError, ShippedFilterError, load

POLICIES_DIR = Path(__file__).parent / "policies"
"""Folder of the shipped trained policies (one artefact folder per policy)."""

__all__ = ["LearnedPolicy", "PolicyLoadError", "POLICIES_DIR", "ShippedFilterError", "TrainConfig", "load",
           "SatVecEnv"]


def __getattr__(name: str):
    if name == "SatVecEnv":  # imports stable-baselines3: only on demand
        from .vec_env import SatVecEnv

        return SatVecEnv
    raise AttributeError(f"module 'training' has no attribute {name!r}")
