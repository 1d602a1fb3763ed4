"""Input validation shared by satenv (the one home of its number/array rules and work caps).

Every check returns the cleaned value or raises :class:`satenv.errors.SatenvError` (a
``ValueError``) naming the field, the value received and what is expected; a value of the wrong
kind — a string, a bool or a complex number where a real number is meant, a masked array
(``numpy.ma``) — raises :class:`satenv.errors.SatenvTypeError` (a ``TypeError``). Overflow in the
check's own arithmetic (``float(10**400)``) is reported the same way, never as ``OverflowError``.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from satenv.errors import SatenvError, SatenvTypeError

MAX_SUBSTEPS: int = 1000
"""Cap on internal integration steps per step (env step or ``simulate`` output step): above it a
single call would take seconds to hours (a 5e6 s step at 5 s substeps is 10^6 RK4 steps)."""

MAX_STEPS: int = 1_000_000
"""Cap on step counts (episode length, ``simulate(steps=...)``): at 10^6 a ``simulate`` output is
48 MB per deputy and a rollout takes about a minute, so a larger count is a typo, not a plan."""

MAX_COPIES: int = 1 << 20
"""Cap on the number of batched env copies (``satenv.make_vec(env_id, num_envs)``): a million
copies of a 4-agent platoon already hold ~0.2 GB of state and take seconds per step; beyond it
the allocation, not the physics, decides whether the call returns."""

MAX_WORK: int = 2_000_000
"""Cap on ``steps * substeps`` of one ``simulate`` call with a truth model (about a minute of
RK4 steps on one core)."""


def show(value: Any, limit: int = 60) -> str:
    """A short ``repr`` for error messages (never fails, even for a 10^5000 int)."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - e.g. int too large to print
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[:limit] + "..."


def _wrong_kind(value: Any) -> str | None:
    """Why ``value`` is not a real number or real array (``None`` if it may be one)."""
    if isinstance(value, np.ma.MaskedArray):
        return "a masked array (numpy.ma; pass value.filled(...) or the data without the mask)"
    if isinstance(value, bool | np.bool_):
        return "a bool"
    if isinstance(value, complex | np.complexfloating):
        return "a complex number"
    if isinstance(value, str | bytes):
        return "a string"
    return None


def real(value: Any, name: str, expected: str = "a finite real number") -> float:
    """``value`` as a finite float (ints, floats, numpy real scalars and 0-d real arrays)."""
    why = _wrong_kind(value)
    ok_type = isinstance(value, numbers.Real) or (
        isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf")
    if why or not ok_type:
        raise SatenvTypeError(f"{name} must be {expected}, got {why or type(value).__name__}: "
                              f"{show(value)}")
    try:
        if isinstance(value, np.generic | np.ndarray) and value.dtype.itemsize > 8:
            with np.errstate(over="ignore"):  # a long double beyond float64 is inf: rejected below
                v = float(value)
        else:
            v = float(value)
    except (OverflowError, ValueError, TypeError):
        raise SatenvError(f"{name} must be {expected}, got {show(value)} "
                          "(too large for a float)") from None
    if not math.isfinite(v):
        raise SatenvError(f"{name} must be {expected}, got {show(value)}")
    return v


def positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """``value`` as a finite float ``> 0`` (``>= 0`` with ``allow_zero``)."""
    need = "a finite number >= 0" if allow_zero else "a finite number > 0"
    v = real(value, name, need)
    if v < 0 or (v == 0 and not allow_zero):
        raise SatenvError(f"{name} must be {need}, got {show(value)}")
    return v


def integer(value: Any, name: str, *, minimum: int = 1, maximum: int | None = None,
            why: str = "", allow_float: bool = False) -> int:
    """``value`` as an int in ``[minimum, maximum]`` (``why`` says why there is a maximum).

    Integral floats (``10.0``) are accepted only with ``allow_float``; bools never are.
    """
    bound = f"an int >= {minimum}" + ("" if maximum is None else f" and <= {maximum}")
    if isinstance(value, bool | np.bool_) or not (
            isinstance(value, int | np.integer) or (allow_float and isinstance(value, float | np.floating))):
        raise SatenvTypeError(f"{name} must be {bound}, got {type(value).__name__}: {show(value)}")
    if not isinstance(value, int | np.integer) and not (math.isfinite(value) and float(value).is_integer()):
        raise SatenvError(f"{name} must be {bound}, got {show(value)}")
    v = int(value)
    if v < minimum:
        raise SatenvError(f"{name} must be {bound}, got {show(value)}")
    if maximum is not None and v > maximum:
        raise SatenvError(f"{name} must be <= {maximum}{f' ({why})' if why else ''}, got {show(value)}")
    return v


def numeric(value: Any, name: str) -> np.ndarray:
    """``value`` as a finite float64 array (any shape); rejects bool, complex, text, masked."""
    why = _wrong_kind(value)
    if why:
        raise SatenvTypeError(f"{name} must be a real numeric array, got {why}: {show(value)}")
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise SatenvError(f"{name} must be a real numeric array, got {show(value)}: {exc}") from None
    kind = raw.dtype.kind
    if kind == "O":  # python ints beyond int64, mixed objects: check every entry
        arr = np.array([real(v, f"{name} entry") for v in raw.ravel()], dtype=np.float64)
        arr = arr.reshape(raw.shape)
    elif kind in "iuf":
        if raw.dtype.itemsize > 8:    # long double: beyond the float64 range is inf, reported below
            with np.errstate(over="ignore"):
                arr = raw.astype(np.float64)
        else:
            arr = raw.astype(np.float64)
    else:
        what = {"b": "bools", "c": "complex numbers", "U": "strings", "S": "bytes"}.get(kind, raw.dtype)
        raise SatenvTypeError(f"{name} must be a real numeric array, got an array of {what}: {show(value)}")
    if not np.isfinite(arr).all():
        bad = arr[~np.isfinite(arr)].ravel()[:3]
        raise SatenvError(f"{name} must be finite, got non-finite values {bad.tolist()}; "
                          "check for NaN/inf (or values beyond the float range) upstream")
    return arr


def as_array(value, name: str, last_dims: tuple[int, ...], *, min_ndim: int | None = None) -> np.ndarray:
    """``value`` as a finite float64 array whose trailing shape is ``last_dims``."""
    arr = numeric(value, name)
    need = len(last_dims) if min_ndim is None else min_ndim
    if arr.ndim < need or arr.shape[arr.ndim - len(last_dims):] != last_dims:
        dims = ", ".join(["..."] + [str(d) for d in last_dims])
        raise SatenvError(f"{name} must have shape ({dims}), got shape {arr.shape}; "
                          f"reshape it so the last axes are {last_dims}")
    return arr


def derived(compute, name: str, inputs: str) -> float:
    """A derived quantity ``compute()`` as a finite float ``> 0``; overflow, underflow to 0 or
    division by zero in it is reported against the ``inputs`` it comes from."""
    try:
        with np.errstate(over="raise", divide="raise", invalid="raise"):
            v = float(compute())
    except (ArithmeticError, FloatingPointError, ValueError) as exc:
        raise SatenvError(f"{name} of {inputs} is out of the float range ({exc}); "
                          "use physically sized values (SI units)") from None
    if not math.isfinite(v) or v <= 0.0:
        raise SatenvError(f"{name} of {inputs} must be finite and > 0, got {v!r}; "
                          "use physically sized values (SI units)")
    return v


_ZEROS: dict[tuple[int, str], np.ndarray] = {}


def all_finite(*arrays: np.ndarray) -> bool:
    """True iff every entry of every (float) array is finite (the hot-path guard).

    One dot product per array with a cached zero vector: ``0 * inf`` and ``0 * nan`` are NaN and
    finite entries give exactly 0, so the result is exact (no overflow of large finite entries,
    unlike a plain sum) and costs well under a microsecond per small array.
    """
    total = 0.0
    for a in arrays:
        flat = a.reshape(-1)
        key = (flat.size, flat.dtype.char)
        zeros = _ZEROS.get(key)
        if zeros is None:
            zeros = _ZEROS[key] = np.zeros(flat.size, flat.dtype)
        total += float(np.vdot(flat, zeros))   # vdot: no "invalid value" RuntimeWarning for 0 * inf
    return total == 0.0


class StepGuard:
    """The hot-path check of one env step: observation and state arrays of fixed sizes (two
    ``np.vdot`` with zero vectors made once, as in :func:`all_finite`) and the sum of the rewards
    (already Python floats: ``s - s`` is 0 iff ``s`` is finite). A sum of huge finite rewards can
    overflow, so ``False`` means "look closer", not "non-finite"."""

    __slots__ = ("_zo", "_zs")

    def __init__(self, obs_size: int, state_size: int) -> None:
        self._zo, self._zs = np.zeros(obs_size, np.float32), np.zeros(state_size)

    def __call__(self, obs: np.ndarray, state: np.ndarray, reward_sum: float) -> bool:
        return np.vdot(obs, self._zo) + np.vdot(state, self._zs) + (reward_sum - reward_sum) == 0.0


def first_nonfinite(quantities: dict[str, np.ndarray], labels: list[str]) -> str:
    """Describe the non-finite entries of ``quantities`` (arrays ``(M, ...)``, row i = ``labels[i]``)."""
    parts = []
    for key, arr in quantities.items():
        with np.errstate(over="ignore"):      # a long double beyond float64 is inf: reported as such
            arr = np.asarray(arr, dtype=float)
        rows = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1) if arr.ndim else [True]
        bad = [labels[i] if i < len(labels) else str(i) for i in np.flatnonzero(rows)]
        if bad:
            parts.append(f"{key} of {', '.join(bad)}")
    return "; ".join(parts) or "a non-finite value"
