"""Validation of scenario fields (shared by every scenario dataclass's ``__post_init__``).

Each function returns the cleaned value or raises ``ValueError`` naming the field, what was
received and what is expected.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def number(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """A finite float ``> 0`` (``>= 0`` with ``allow_zero``); booleans are rejected."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        need = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {need}, got {value!r}")
    return v


def array(value: Any, name: str, shape: tuple[int, ...] | None = None, ndim: int | None = None) -> np.ndarray:
    """A finite float array, optionally of an exact ``shape`` or number of dimensions."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {value!r}") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}: {value!r}")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be a {ndim}-d array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return arr


def vector(value: Any, name: str, length: int | None = None) -> tuple[float, ...]:
    """A flat tuple of finite floats (of ``length`` entries when given)."""
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a numeric sequence, got {value!r}") from None
    if length is not None and arr.shape != (length,):
        raise ValueError(f"{name} must have {length} entries, got {arr.size}: {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return tuple(float(v) for v in arr)


def nested(arr: np.ndarray):
    """An array as nested tuples of floats (hashable, for frozen dataclasses)."""
    return tuple(nested(a) for a in arr) if arr.ndim > 1 else tuple(float(v) for v in arr)


def from_preset(presets: dict[str, Any], preset: str, kind: str, overrides: dict[str, Any]) -> Any:
    """``presets[preset]`` with ``overrides`` applied through its ``with_overrides`` (validated)."""
    if preset not in presets:
        raise ValueError(f"unknown {kind} preset {preset!r}; expected one of {sorted(presets)}")
    base = presets[preset]
    return base.with_overrides(**overrides) if overrides else base
