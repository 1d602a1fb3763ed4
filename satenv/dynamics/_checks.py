"""Input validation shared by the dynamics functions (clear ``ValueError`` messages)."""

from __future__ import annotations

import numpy as np


def as_array(value, name: str, last_dims: tuple[int, ...], *, min_ndim: int | None = None) -> np.ndarray:
    """Return ``value`` as a finite float64 array whose trailing shape is ``last_dims``.

    Raises ``ValueError`` naming the received shape / values and the expected form.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array, got {type(value).__name__}: {exc}") from None
    need = len(last_dims) if min_ndim is None else min_ndim
    if arr.ndim < need or arr.shape[arr.ndim - len(last_dims):] != last_dims:
        dims = ", ".join(["..."] + [str(d) for d in last_dims])
        raise ValueError(f"{name} must have shape ({dims}), got shape {arr.shape}; "
                         f"reshape it so the last axes are {last_dims}")
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].ravel()[:3]
        raise ValueError(f"{name} must be finite, got non-finite values {bad.tolist()}; "
                         "check for NaN/inf upstream")
    return arr


def positive(value: float, name: str) -> float:
    """Return ``value`` as a float, requiring it to be finite and > 0."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v
