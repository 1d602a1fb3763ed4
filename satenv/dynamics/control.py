"""Thrust saturation and delta-v accounting (batched over leading axes)."""

from __future__ import annotations

import numpy as np


def saturate_box(u: np.ndarray, u_max) -> np.ndarray:
    """Clip each axis to ``[-u_max, u_max]`` (``u_max`` scalar or per-axis (3,))."""
    return np.clip(u, -np.asarray(u_max), np.asarray(u_max))


def saturate_norm(u: np.ndarray, u_max: float) -> np.ndarray:
    """Scale vectors whose Euclidean norm exceeds ``u_max`` back onto the ball (direction kept)."""
    norm = np.linalg.norm(u, axis=-1, keepdims=True)
    scale = np.minimum(1.0, u_max / np.maximum(norm, np.finfo(float).tiny))
    return u * scale


def delta_v(u: np.ndarray, dt: float) -> np.ndarray:
    """Delta-v [m/s] spent by accelerations ``u`` (..., 3) held for ``dt``: ``|u| dt``."""
    return np.sqrt((u * u).sum(axis=-1)) * dt


def unit_box_to_accel(action: np.ndarray, u_max, mode: str = "box") -> np.ndarray:
    """Map normalised actions to accelerations.

    ``mode="box"``: each axis of ``[-1, 1]^3`` scales to ``[-u_max, u_max]``;
    ``mode="norm"``: the same scaling, then the vector is clipped to the ``u_max`` ball.
    """
    u = np.minimum(np.maximum(action, -1.0), 1.0) * np.asarray(u_max)  # np.clip, minus its overhead
    if mode == "norm":
        return saturate_norm(u, float(np.max(u_max)))
    if mode != "box":
        raise ValueError(f"unknown saturation mode {mode!r}; expected 'box' or 'norm'")
    return u
