"""Training-only reward shaping, and the policy's input/output maps (recorded in the run's config).

All act on the batched arrays of :class:`satenv.training.vec_env.SatVecEnv`; the observation features
and the action map are part of the policy and are re-applied by
:class:`satenv.training.policy.LearnedPolicy` at inference, so a policy sees the same inputs and
produces the same env actions in training and in the PettingZoo env. Evaluation metrics never
see the reward shaping.

Reward shaping (per agent; info arrays ``(B, M, ...)``)::

    r  = env_weight * r_env
    r -= tracking * ||e|| / tracking_scale                     (e: the 6-d tracking error)
    r += precision * max(0, 1 - log1p(||e_pos|| / precision_scale) / log1p(100))
    r -= proximity * clip((proximity_distance - min_separation) / proximity_width, 0, 1)^2
    r -= collision * collision_flag + effort * delta_v + violation * violations
    r -= anticipation * sum_j clip((anticipation_distance - d_cpa_ij) / anticipation_width, 0, 1)^2

``e`` = ``info["tracking_error"]``, ``e_pos`` its first 3 entries [m]. Why: the env's quadratic
stage cost spans orders of magnitude over an episode (hundreds of metres at the start, metres at
the end), so after PPO's advantage normalisation the end of the episode carries almost no signal;
the linear ``tracking`` term and the logarithmic ``precision`` bonus keep the slope near the
target. ``proximity`` is a smooth penalty before contact (the env's collision penalty is a step;
``collision`` re-adds one when ``env_weight = 0``; ``violation`` likewise re-adds a penalty per hard
constraint violated this step, ``info["violations"]``: keep-out sphere, line-of-sight cone, speed
bound). ``anticipation`` looks ahead: ``d_cpa_ij`` is
the closest-approach distance of agents i and j over the next ``anticipation_horizon`` seconds
if both keep their velocity (positions and velocities from ``info["state"][..., :6]``), so fast
crossings are penalised before the contact. With ``anticipation_speed > 0`` the pair's penalty is
multiplied by ``clip(closing_speed / anticipation_speed, 0, 1)`` (closing speed = rate at which
the distance shrinks), so slow neighbours holding a tight formation are not penalised while a
fast crossing is, even with a large ``anticipation_distance``.

Observation features: ``symlog_scale > 0`` appends ``sign(x) log1p(|x| symlog_scale)`` of the
first ``symlog_dims`` observation entries (for platoon_v0, entries 0-5 are the tracking error in
units of 50 m / 10 m/s, so ``symlog_scale=50`` resolves metres near the target).

Action map: ``power > 1`` sends the network's action ``y`` in ``[-1, 1]`` to the env action
``sign(y) |y|^power`` (still in ``[-1, 1]``; the env then scales it to ``u_max`` as always). With
a large ``u_max`` (platoon: 6 m/s^2 per axis) this gives fine resolution and small exploration
noise near zero thrust while keeping full authority.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

__all__ = ["RewardShaping", "ObsFeatures", "ActionMap", "TerminalFeedback"]

BEYOND_FLOAT_RANGE = {"over": "ignore", "invalid": "ignore", "divide": "ignore"}
"""``np.errstate`` of the shaping arithmetic: an observation or state near the float range gives
inf/NaN quietly, and that value is what is checked (the policy's non-finite check flags the
action, the env's guard the state), instead of a numpy ``RuntimeWarning`` per call."""


@dataclass(frozen=True)
class RewardShaping:
    """Shaping weights (0 disables a term); see the module docstring."""

    env_weight: float = 1.0
    tracking: float = 0.0
    tracking_scale: float = 50.0
    precision: float = 0.0
    precision_scale: float = 1.0
    proximity: float = 0.0
    proximity_distance: float = 8.0
    proximity_width: float = 2.0
    collision: float = 0.0
    effort: float = 0.0
    violation: float = 0.0
    anticipation: float = 0.0
    anticipation_distance: float = 8.0
    anticipation_width: float = 2.0
    anticipation_horizon: float = 2.0
    anticipation_speed: float = 0.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"reward_shaping[{name!r}] must be a finite number >= 0, got {value!r}")
        if self.precision_scale <= 0 or self.proximity_width <= 0 or self.tracking_scale <= 0 \
                or self.anticipation_width <= 0:
            raise ValueError("reward_shaping precision_scale, proximity_width and tracking_scale must be "
                             f"> 0, got {self.precision_scale}, {self.proximity_width}, {self.tracking_scale}")

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RewardShaping:
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown reward_shaping key(s) {unknown}; known: {sorted(known)}")
        return cls(**d)

    @property
    def active(self) -> bool:
        return (self.env_weight != 1.0 or self.tracking > 0 or self.precision > 0 or self.proximity > 0
                or self.collision > 0 or self.effort > 0 or self.violation > 0 or self.anticipation > 0)

    def __call__(self, rewards: np.ndarray, info: dict[str, np.ndarray]) -> np.ndarray:
        with np.errstate(**BEYOND_FLOAT_RANGE):
            return self._shaped(rewards, info)

    def _shaped(self, rewards: np.ndarray, info: dict[str, np.ndarray]) -> np.ndarray:
        out = self.env_weight * np.asarray(rewards, dtype=np.float64)
        if self.tracking > 0:
            e = info["tracking_error"]
            out -= self.tracking * np.linalg.norm(e.reshape(*e.shape[:2], -1), axis=-1) / self.tracking_scale
        if self.precision > 0:
            e = np.linalg.norm(info["tracking_error"][..., :3], axis=-1)
            out += self.precision * np.maximum(0.0, 1.0 - np.log1p(e / self.precision_scale) / math.log1p(100.0))
        if self.proximity > 0:
            gap = (self.proximity_distance - info["min_separation"]) / self.proximity_width
            out -= self.proximity * np.clip(gap, 0.0, 1.0) ** 2
        if self.collision > 0:
            out -= self.collision * info["collision"]
        if self.effort > 0:
            out -= self.effort * info["delta_v"]
        if self.violation > 0:
            out -= self.violation * info["violations"]
        if self.anticipation > 0:
            out -= self.anticipation * self.closest_approach_penalty(info["state"])
        return out

    def closest_approach_penalty(self, state: np.ndarray) -> np.ndarray:
        """Per agent ``(B, M)``: sum over the other agents of the look-ahead penalty."""
        p = state[..., None, :, :3] - state[..., :, None, :3]      # (B, M, M, 3): x_j - x_i
        v = state[..., None, :, 3:6] - state[..., :, None, 3:6]
        vv = np.sum(v * v, axis=-1)
        t = np.clip(-np.sum(p * v, axis=-1) / np.maximum(vv, 1e-12), 0.0, self.anticipation_horizon)
        d = np.linalg.norm(p + v * t[..., None], axis=-1)
        pen = np.clip((self.anticipation_distance - d) / self.anticipation_width, 0.0, 1.0) ** 2
        if self.anticipation_speed > 0:
            dist = np.maximum(np.linalg.norm(p, axis=-1), 1e-9)
            closing = -np.sum(p * v, axis=-1) / dist
            pen = pen * np.clip(closing / self.anticipation_speed, 0.0, 1.0)
        m = state.shape[-2]
        pen[..., np.arange(m), np.arange(m)] = 0.0
        return pen.sum(axis=-1)


@dataclass(frozen=True)
class ObsFeatures:
    """Appended symlog features of the first ``symlog_dims`` observation entries (0: identity),
    after zeroing the entries ``drop_dims`` (inputs the policy must not use; shape unchanged)."""

    symlog_scale: float = 0.0
    symlog_dims: int = 6
    drop_dims: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        drop = self.drop_dims
        if isinstance(drop, str | bytes) or not isinstance(drop, tuple | list) or any(
                isinstance(d, bool) or not isinstance(d, int) or d < 0 for d in drop):
            raise ValueError(f"obs_drop_dims must be a tuple of observation indices >= 0, got {drop!r}")
        object.__setattr__(self, "drop_dims", tuple(sorted(set(drop))))
        if isinstance(self.symlog_scale, bool) or not isinstance(self.symlog_scale, (int, float)) \
                or not math.isfinite(self.symlog_scale) or self.symlog_scale < 0:
            raise ValueError(f"obs_symlog_scale must be a finite number >= 0, got {self.symlog_scale!r}")
        if isinstance(self.symlog_dims, bool) or not isinstance(self.symlog_dims, int) or self.symlog_dims < 1:
            raise ValueError(f"obs_symlog_dims must be a positive int, got {self.symlog_dims!r}")

    @property
    def active(self) -> bool:
        return self.symlog_scale > 0 or bool(self.drop_dims)

    def out_dim(self, obs_dim: int) -> int:
        if self.drop_dims and self.drop_dims[-1] >= obs_dim:
            raise ValueError(f"obs_drop_dims {list(self.drop_dims)} must index the {obs_dim}-d observation")
        return obs_dim + min(self.symlog_dims, obs_dim) if self.symlog_scale > 0 else obs_dim

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if self.drop_dims:
            self.out_dim(obs.shape[-1])
            obs = obs.copy()
            obs[..., list(self.drop_dims)] = 0
        if not self.symlog_scale > 0:
            return obs
        x = obs[..., : self.symlog_dims]
        with np.errstate(**BEYOND_FLOAT_RANGE):
            extra = np.sign(x) * np.log1p(np.abs(x) * self.symlog_scale)
        return np.concatenate([obs, extra.astype(obs.dtype)], axis=-1)


@dataclass(frozen=True)
class ActionMap:
    """``y -> sign(y) |y|^power`` on actions clipped to ``[-1, 1]`` (``power = 1``: identity)."""

    power: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.power, bool) or not isinstance(self.power, (int, float)) \
                or not math.isfinite(self.power) or self.power <= 0:
            raise ValueError(f"action_power must be a finite number > 0, got {self.power!r}")

    @property
    def active(self) -> bool:
        return self.power != 1.0

    def __call__(self, action: np.ndarray) -> np.ndarray:
        y = np.clip(action, -1.0, 1.0)
        if not self.active:
            return y
        return np.sign(y) * np.abs(y) ** self.power


@dataclass(frozen=True)
class TerminalFeedback:
    """A feedback law the policy blends in near its target (``radius > 0``; 0: off).

    With ``e`` the position error [m] and ``v`` the velocity (error) [m/s] read from the raw
    observation (``error_at`` / ``velocity_at``: first index of each 3-vector; ``error_scale`` /
    ``velocity_scale``: the env's normalisation), the feedback is a velocity-command loop::

        v_ref = -bandwidth e, limited to ||v_ref|| <= speed
        a_fb  = clip(gain (v_ref - v), -1, 1)            (normalised action, ``gain`` = k_v / u_max)
        a     = (1 - w) a_net + w a_fb,  w = exp(-||e|| / radius)

    on the action entries ``action_at .. action_at + 2``. Why: a regression of the expert's
    action leaves an error of a few per cent of the thrust, which near the target is a bias of
    metres against the 1 m success tolerance; the feedback removes it where the network is only
    asked to fly the approach. It is part of the policy (``config.json`` ``"terminal"``)
    and is applied at training (DAgger's learner) and at inference alike.
    """

    radius: float = 0.0
    gain: float = 7.0
    bandwidth: float = 0.07
    speed: float = 0.5
    error_at: int = 0
    velocity_at: int = 3
    action_at: int = 0
    error_scale: float = 1.0
    velocity_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("radius", "gain", "bandwidth", "speed", "error_scale", "velocity_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 \
                    or (v == 0 and name != "radius"):
                raise ValueError(f"terminal {name} must be a finite number {'>= 0' if name == 'radius' else '> 0'}, "
                                 f"got {v!r}")
        for name in ("error_at", "velocity_at", "action_at"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"terminal {name} must be an int >= 0, got {v!r}")

    @property
    def active(self) -> bool:
        return self.radius > 0

    def __call__(self, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        """Blend the feedback into ``action`` (n, act_dim) for raw observations ``obs`` (n, obs_dim)."""
        if not self.active:
            return action
        with np.errstate(**BEYOND_FLOAT_RANGE):
            return self._blend(obs, action)

    def _blend(self, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        if max(self.error_at, self.velocity_at) + 3 > obs.shape[-1] or self.action_at + 3 > action.shape[-1]:
            raise ValueError(f"terminal feedback indices (error_at={self.error_at}, velocity_at="
                             f"{self.velocity_at}, action_at={self.action_at}) do not fit observations "
                             f"{obs.shape[-1]}-d and actions {action.shape[-1]}-d")
        e = obs[..., self.error_at:self.error_at + 3] * self.error_scale
        v = obs[..., self.velocity_at:self.velocity_at + 3] * self.velocity_scale
        dist = np.linalg.norm(e, axis=-1, keepdims=True)
        v_ref = -self.bandwidth * e
        v_ref *= np.minimum(1.0, self.speed / np.maximum(np.linalg.norm(v_ref, axis=-1, keepdims=True), 1e-12))
        fb = np.clip(self.gain * (v_ref - v), -1.0, 1.0)
        w = np.exp(-dist / self.radius)
        out = np.array(action, dtype=np.float64, copy=True)
        sl = slice(self.action_at, self.action_at + 3)
        out[..., sl] = (1 - w) * out[..., sl] + w * fb
        return out.astype(action.dtype)

    @classmethod
    def from_config(cls, config: dict) -> TerminalFeedback:
        """The feedback of a run config (its ``"terminal"`` object of these fields; absent: off)."""
        entry = config.get("terminal")
        entry = {} if entry is None else entry
        if not isinstance(entry, dict):
            raise ValueError(f"terminal must be an object of TerminalFeedback fields, got {type(entry).__name__}")
        unknown = set(entry) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"terminal: unknown field(s) {sorted(unknown)}; expected {[f.name for f in fields(cls)]}")
        return cls(**entry)
