"""Satellite-to-target allocation with the Hungarian algorithm (li2022 §3.3).

The cost of giving target ``j`` to satellite ``i`` is ``C_ij = alpha_i ||q_i - q_jd||^2`` (the
tracking term of the DMPC cost, li2022 §3.3); the allocation minimises ``sum_i C_{i, a(i)}`` over
one-to-one assignments. The optimisation is scipy's maintained ``linear_sum_assignment`` (a
Jonker-Volgenant / Hungarian-type solver), not a hand-written one.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

__all__ = ["allocation_cost", "assignment_cost", "hungarian_assignment"]


def _points(value, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a numeric array of shape (..., K, 3), got "
                         f"{type(value).__name__}") from None
    if arr.ndim < 2 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., K, 3) (one row per point), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got NaN/inf entries")
    return arr


def allocation_cost(positions, targets, alpha=1.0) -> np.ndarray:
    """Cost matrices ``C_ij = alpha_i ||q_i - q_jd||^2``.

    Args:
        positions: satellite positions ``(..., M, 3)`` [m].
        targets: target positions ``(T, 3)`` or ``(..., T, 3)`` [m].
        alpha: positive weight, scalar or per satellite ``(M,)``.

    Returns:
        ``(..., M, T)`` costs [m^2].
    """
    q = _points(positions, "positions")
    tg = _points(targets, "targets")
    a = np.asarray(alpha, dtype=np.float64)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] != q.shape[-2]):
        raise ValueError(f"alpha must be a scalar or have one entry per satellite "
                         f"({q.shape[-2]},), got shape {a.shape}")
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"alpha must be finite and > 0, got {a.tolist()}")
    diff = q[..., :, None, :] - tg[..., None, :, :]
    cost = np.einsum("...ijk,...ijk->...ij", diff, diff)
    return cost * (a[:, None] if a.ndim == 1 else a)


def hungarian_assignment(positions, targets, alpha=1.0) -> np.ndarray:
    """Optimal one-to-one allocation of targets to satellites.

    Args:
        positions: ``(..., M, 3)`` satellite positions [m].
        targets: ``(T, 3)`` (or batched ``(..., T, 3)``) target positions with ``T >= M``.
        alpha: the cost weight of :func:`allocation_cost`.

    Returns:
        ``(..., M)`` int array: ``a[..., i]`` is the index of the target given to satellite ``i``.

    Example:
        >>> hungarian_assignment([[0, 0, 0], [10, 0, 0]], [[9, 0, 0], [1, 0, 0]]).tolist()
        [1, 0]
    """
    cost = allocation_cost(positions, targets, alpha)
    m, t = cost.shape[-2:]
    if t < m:
        raise ValueError(f"need at least as many targets as satellites, got {t} targets for {m} "
                         "satellites; add targets or remove satellites")
    flat = cost.reshape(-1, m, t)
    out = np.empty((flat.shape[0], m), dtype=np.int64)
    for b, c in enumerate(flat):
        rows, cols = linear_sum_assignment(c)
        out[b, rows] = cols
    return out.reshape(cost.shape[:-2] + (m,))


def assignment_cost(cost: np.ndarray, assignment: np.ndarray) -> np.ndarray:
    """Total cost ``sum_i C[..., i, a_i]`` of an assignment ``(..., M)``."""
    cost = np.asarray(cost, dtype=np.float64)
    a = np.asarray(assignment, dtype=np.int64)
    return np.take_along_axis(cost, a[..., None], axis=-1)[..., 0].sum(axis=-1)
