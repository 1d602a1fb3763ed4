"""Training-only reward shaping and observation features (recorded in the run's config).

Both act on the batched arrays of :class:`training.vec_env.SatVecEnv`; the observation features
are re-applied by :class:`training.policy.LearnedPolicy` at inference, so a policy sees the same
inputs in training and in the PettingZoo env. Evaluation metrics never see the shaping.

Reward shaping (per agent, added to the env's reward; info arrays ``(B, M, ...)``)::

    r += precision * (1 - log1p(||e_pos|| / precision_scale) / log1p(100))  [clipped at 0 below]
    r -= proximity * clip((proximity_distance - min_separation) / proximity_width, 0, 1)^2

``e_pos`` = ``info["tracking_error"][..., :3]`` [m]. The precision term gives a signal whose slope
grows near the target (the quadratic stage cost of the env vanishes there); the proximity term
is a smooth penalty before contact (the env's collision penalty is a step).

Observation features: ``symlog_scale > 0`` appends ``sign(x) log1p(|x| symlog_scale)`` of the
first ``symlog_dims`` observation entries (for platoon_v0, entries 0-5 are the tracking error in
units of 50 m / 10 m/s, so ``symlog_scale=50`` resolves metres near the target).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["RewardShaping", "ObsFeatures"]


@dataclass(frozen=True)
class RewardShaping:
    """Shaping weights (0 disables a term); see the module docstring."""

    precision: float = 0.0
    precision_scale: float = 1.0
    proximity: float = 0.0
    proximity_distance: float = 8.0
    proximity_width: float = 2.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"reward_shaping[{name!r}] must be a finite number >= 0, got {value!r}")
        if self.precision_scale <= 0 or self.proximity_width <= 0:
            raise ValueError("reward_shaping precision_scale and proximity_width must be > 0, got "
                             f"{self.precision_scale}, {self.proximity_width}")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RewardShaping:
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown reward_shaping key(s) {unknown}; known: {sorted(known)}")
        return cls(**d)

    @property
    def active(self) -> bool:
        return self.precision > 0 or self.proximity > 0

    def __call__(self, rewards: np.ndarray, info: dict[str, np.ndarray]) -> np.ndarray:
        out = np.asarray(rewards, dtype=np.float64).copy()
        if self.precision > 0:
            e = np.linalg.norm(info["tracking_error"][..., :3], axis=-1)
            out += self.precision * np.maximum(0.0, 1.0 - np.log1p(e / self.precision_scale) / math.log1p(100.0))
        if self.proximity > 0:
            gap = (self.proximity_distance - info["min_separation"]) / self.proximity_width
            out -= self.proximity * np.clip(gap, 0.0, 1.0) ** 2
        return out


@dataclass(frozen=True)
class ObsFeatures:
    """Appended symlog features of the first ``symlog_dims`` observation entries (0: identity)."""

    symlog_scale: float = 0.0
    symlog_dims: int = 6

    def __post_init__(self) -> None:
        if isinstance(self.symlog_scale, bool) or not isinstance(self.symlog_scale, (int, float)) \
                or not math.isfinite(self.symlog_scale) or self.symlog_scale < 0:
            raise ValueError(f"obs_symlog_scale must be a finite number >= 0, got {self.symlog_scale!r}")
        if isinstance(self.symlog_dims, bool) or not isinstance(self.symlog_dims, int) or self.symlog_dims < 1:
            raise ValueError(f"obs_symlog_dims must be a positive int, got {self.symlog_dims!r}")

    @property
    def active(self) -> bool:
        return self.symlog_scale > 0

    def out_dim(self, obs_dim: int) -> int:
        return obs_dim + min(self.symlog_dims, obs_dim) if self.active else obs_dim

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if not self.active:
            return obs
        x = obs[..., : self.symlog_dims]
        extra = np.sign(x) * np.log1p(np.abs(x) * self.symlog_scale)
        return np.concatenate([obs, extra.astype(obs.dtype)], axis=-1)
