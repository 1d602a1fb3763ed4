"""Re-export of :class:`satenv.gym_env.CentralisedEnv` (its home since it needs no stable-baselines3)."""

from satenv.gym_env import CentralisedEnv

__all__ = ["CentralisedEnv"]
