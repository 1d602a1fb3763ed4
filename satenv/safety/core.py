"""The batched filter: one QP per agent whose proposal breaks a row, the backup, :class:`SafetyFilter`."""

from __future__ import annotations

import math
import warnings
from typing import Any, NamedTuple

import numpy as np

from satenv.dynamics import quat_to_matrix
from satenv.dynamics._checks import all_finite
from satenv.perturbations import UncertaintyBounds
from satenv.safety.config import (
    _BIG,
    _QP_TOL,
    _ROW_TOL,
    SafetyConfig,
    SafetyError,
    SafetyRecord,
    SafetyTypeError,
    SafetyWarning,
)
from satenv.safety.margins import tighten_lower
from satenv.safety.model import SafetyModel, _core_of, _has_position_rows, safety_model
from satenv.safety.rows import _omega_rows, constraint_rows


# ---------------------------------------------------------------------------------------------
# the filter
# ---------------------------------------------------------------------------------------------
def solve_qp(u_ref: np.ndarray, rows: np.ndarray, lower: np.ndarray, box: float) -> tuple[np.ndarray, int]:
    """``min ||u - u_ref||^2  s.t.  rows u >= lower,  |u| <= box`` with daqp: ``(u, exitflag)``."""
    import daqp

    d = u_ref.shape[0]
    bu = np.concatenate([np.full(d, box), np.full(len(lower), _BIG)])
    bl = np.concatenate([np.full(d, -box), lower])
    x, _, flag, _ = daqp.solve(np.eye(d), -u_ref, np.ascontiguousarray(rows), bu, bl,
                               np.zeros(d + len(lower), dtype=np.int32))
    return np.asarray(x, dtype=float), int(flag)


class ActionRows(NamedTuple):
    """The filter's constraints on the normalised actions, ``rows @ eff(u) >= lower``."""

    rows: np.ndarray
    """``(B, M, K, d)``: the state rows through the action-to-acceleration map (and the
    angular-rate rows of an attitude model)."""
    lower: np.ndarray
    """``(B, M, K)``: the bounds, tightened for the thrust loss (:func:`tighten_lower`); a chaser's
    :func:`chain_slots` still lack its target's acceleration term."""
    w: np.ndarray
    """``(B, M, K', 6)``: the state rows (the chain's target-acceleration term is ``w @ acc``)."""
    s: np.ndarray
    """The action-to-acceleration map: ``(3, d)``, or ``(B, M, 3, d)`` in a body frame."""


def action_rows(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray, t: np.ndarray) -> ActionRows:
    """The filter's constraint rows at states ``x (B, M, >= 6)`` and times ``t (B,)`` [s], as
    :func:`filter_actions` solves against them (one home: the barrier of imitation reads them too)."""
    s = m.S if not m.body_frame else np.einsum("bmij,jk->bmik", quat_to_matrix(x[..., 6:10]), m.S)
    w, lo = constraint_rows(m, cfg, x, t)
    rows = np.einsum("bmki,ij->bmkj", w, s) if s.ndim == 2 else np.einsum("bmki,bmij->bmkj", w, s)
    if m.attitude is not None:
        w_om, lo_om = _omega_rows(m, cfg, x)
        rows, lo = np.concatenate([rows, w_om], axis=2), np.concatenate([lo, lo_om], axis=2)
    return ActionRows(rows, tighten_lower(m, lo), w, s)


def chain_slots(m: SafetyModel) -> np.ndarray:
    """The row slots of a chaser that hold its target's acceleration (a chain model's)."""
    slots = m.budget[0].shape[1]
    return np.r_[slots - m.n_chain:slots, 2 * slots - m.n_chain:2 * slots]


def filter_actions(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray, t: np.ndarray,
                   actions: np.ndarray) -> tuple[np.ndarray, SafetyRecord]:
    """Safe actions ``(B, M, d)`` and the :class:`SafetyRecord` for states ``x (B, M, >= 6)``
    at times ``t (B,)`` [s] and proposed normalised actions ``(B, M, d)`` (module docstring).

    Pure: reads only its arguments. Inputs are validated (:class:`SafetyError` names the field).
    """
    x, t, a = _check_inputs(m, x, t, actions)
    rows, lo, w, s = action_rows(m, cfg, x, t)
    kinds = np.asarray(m.kinds, dtype=np.int64)
    bsz, na, d = a.shape
    if not m.n_chain:
        res = _solve_rows(m, rows.reshape(bsz * na, -1, d), lo.reshape(bsz * na, -1), a.reshape(bsz * na, d), kinds)
        out, safe, infeasible, active = (v.reshape(bsz, na, *v.shape[1:]) for v in res)
    else:   # down the chain: a chaser's rows hold its target's filtered acceleration
        idx = chain_slots(m)
        out, safe = np.empty_like(a), np.empty((bsz, na), dtype=bool)
        infeasible, active = np.empty((bsz, na), dtype=bool), np.empty((bsz, na), dtype=np.int64)
        acc_prev = np.zeros((bsz, 3))                      # the passive leader's
        for f in range(na):
            lo_f = lo[:, f].copy()
            lo_f[:, idx] += np.einsum("bki,bi->bk", w[:, f, idx], acc_prev)
            out[:, f], safe[:, f], infeasible[:, f], active[:, f] = _solve_rows(m, rows[:, f], lo_f, a[:, f], kinds)
            eff = _effective(m, out[:, f])
            acc_prev = eff @ s.T if s.ndim == 2 else np.einsum("bij,bj->bi", s[:, f], eff)
    delta = np.linalg.norm(_effective(m, out) - _effective(m, a), axis=-1)   # of the applied actions
    return out, SafetyRecord(~safe, delta, infeasible, active)


def _solve_rows(m: SafetyModel, rows: np.ndarray, lo: np.ndarray, a: np.ndarray,
                kinds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Filter ``n`` agents' proposals ``a (n, d)`` against their rows ``rows u >= lo``
    ``(n, K, d)``, ``(n, K)``: ``(out, safe, infeasible, active)``; a safe proposal is returned
    as it is (clipped to the action box, as the env would: a filtered action never leaves it), an
    unsafe one is replaced by the QP's point or the backup action."""
    ref = _effective(m, a)
    safe = (np.einsum("nkj,nj->nk", rows, ref) - lo).min(axis=-1, initial=np.inf) >= -_ROW_TOL
    out = np.clip(a, -1.0, 1.0)
    infeasible = np.zeros(len(a), dtype=bool)
    active = np.full(len(a), -1, dtype=np.int64)
    reach = -m.u_box * math.sqrt(m.action_dim) - 1e-9      # (normalised) rows below this never bind
    for i in np.flatnonzero(~safe):
        scale = np.linalg.norm(rows[i], axis=-1)
        tiny = scale < 1e-12
        lo_i = np.where(tiny, np.where(lo[i] <= 0.0, -_BIG, _BIG), lo[i] / np.where(tiny, 1.0, scale))
        rows_i = np.where(tiny[:, None], 0.0, rows[i] / np.where(tiny, 1.0, scale)[:, None])
        keep = lo_i > reach
        u = _guarded_qp(ref[i], rows_i[keep], lo_i[keep], m.u_box)
        if u is None:
            u, k = _backup(m, rows_i[keep], lo_i[keep], rows_i[keep] @ ref[i] - lo_i[keep])
            infeasible[i] = True
            active[i] = kinds[keep][k]
        else:
            active[i] = kinds[int(np.argmin(rows_i @ u - lo_i))]
        out[i] = u
    return out, safe, infeasible, active


def _effective(m: SafetyModel, a: np.ndarray) -> np.ndarray:
    """The action the env applies: clipped to the box (``"norm"``: then into the unit ball)."""
    ref = np.clip(a, -1.0, 1.0)
    if m.norm_mode:
        ref = ref / np.maximum(1.0, np.linalg.norm(ref, axis=-1, keepdims=True))
    return ref


def _guarded_qp(ref: np.ndarray, rows: np.ndarray, lower: np.ndarray, box: float) -> np.ndarray | None:
    """The QP's point, or ``None`` when it must not be used (any failure of :func:`solve_qp`)."""
    try:
        u, flag = solve_qp(ref, rows, lower, box)
    except Exception:  # noqa: BLE001 - any solver fault gives the backup, never a crash
        return None
    if (flag not in (1, 2) or u.shape != ref.shape or not np.all(np.isfinite(u))
            or np.any(np.abs(u) > box + _QP_TOL) or (len(lower) and np.min(rows @ u - lower) < -_QP_TOL)):
        return None
    return np.clip(u, -box, box)


def _backup(m: SafetyModel, rows: np.ndarray, lower: np.ndarray, slack: np.ndarray) -> tuple[np.ndarray, int]:
    """Maximum braking when the QP fails: the action that maximises the smallest row slack,
    ``argmax_u min_k (rows_k u - lower_k)`` over the action box (a daqp QP in ``(u, t)``), or, if
    that fails too, full thrust along the row the proposal breaks most. Returns the action and
    the index of the row it brakes for (the least satisfied one)."""
    d = rows.shape[1]
    k = int(np.argmin(slack))
    try:
        import daqp

        a = np.hstack([rows, -np.ones((len(rows), 1))])
        bu = np.r_[np.full(d, m.u_box), _BIG, np.full(len(rows), _BIG)]
        bl = np.r_[np.full(d, -m.u_box), -_BIG, lower]
        h = np.eye(d + 1) * 1e-6
        z, _, flag, _ = daqp.solve(h, np.r_[np.zeros(d), -1.0], a, bu, bl, np.zeros(len(bu), dtype=np.int32))
        u = np.asarray(z, dtype=float)[:d]
        if flag in (1, 2) and np.all(np.isfinite(u)):
            u = np.clip(u, -m.u_box, m.u_box)
            if m.norm_mode:
                u = u / max(1.0, float(np.linalg.norm(u)))
            return u, int(np.argmin(rows @ u - lower))
    except Exception:  # noqa: BLE001 - the backup never raises
        pass
    row = rows[k]
    if m.norm_mode:
        nrm = float(np.linalg.norm(row))
        return (row / nrm if nrm > 0 else np.zeros_like(row)), k
    return np.sign(row) * m.u_box, k


def _real_array(name: str, value: Any) -> np.ndarray:
    """``value`` as a float array; text, masked, complex, bool and object input is a
    :class:`SafetyTypeError` naming ``name`` (never a silent cast that drops a mask or an imaginary
    part)."""
    if isinstance(value, (str, bytes)) or np.ma.isMaskedArray(value) or np.iscomplexobj(value):
        raise SafetyTypeError(f"safety filter: {name} must be a real array, got "
                              f"{type(value).__name__}{' (complex)' if np.iscomplexobj(value) else ''}")
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "fiu":
            raise TypeError
        return arr.astype(float, copy=False)
    except (TypeError, ValueError, OverflowError):
        kind = getattr(getattr(value, "dtype", None), "name", type(value).__name__)
        raise SafetyTypeError(f"safety filter: {name} must be a real array, got {kind}") from None


def _check_inputs(m: SafetyModel, x: Any, t: Any, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    arrays = []
    for name, value, ndim in (("state", x, 3), ("t", t, 1), ("actions", actions, 3)):
        arr = _real_array(name, value)
        if arr.ndim != ndim:
            raise SafetyError(f"safety filter: {name} must have {ndim} dimensions, got shape {arr.shape}")
        if not all_finite(arr):
            raise SafetyError(f"safety filter: {name} has non-finite entries (NaN or inf)")
        arrays.append(arr)
    x, t, a = arrays
    b, na = a.shape[:2]
    if a.shape != (b, m.n_agents, m.action_dim):
        raise SafetyError(f"safety filter: actions must have shape (copies, {m.n_agents}, {m.action_dim}), "
                          f"got {a.shape}")
    if x.shape[:2] != (b, m.n_agents) or not m.state_dim_ok(x.shape[2]):
        raise SafetyError(f"safety filter: state must have shape ({b}, {m.n_agents}, >= 6), got {x.shape}")
    if t.shape != (b,):
        raise SafetyError(f"safety filter: t must have shape ({b},), got {t.shape}")
    return x, t, a


class SafetyFilter:
    """The filter bound to an env, a ``make_vec`` batch or a batched core: :meth:`filter` reads
    its current state.

    Args:
        target: ``satenv.make(...)`` env, ``satenv.make_vec(...)`` batch or a ``BatchedCore``.
        config: a :class:`SafetyConfig`; ``options`` replace its fields (unknown ones raise).
        bounds: the :class:`satenv.perturbations.UncertaintyBounds` its rows are tightened by
            (:mod:`satenv.safety.margins`); default: the ones ``target`` declares.

    The model is the nominal env's (:func:`satenv.perturbations.nominal`), the state the one
    ``target`` holds: the navigation estimate between two steps of a perturbed env.
    """

    def __init__(self, target: Any, config: SafetyConfig | None = None, *,
                 bounds: UncertaintyBounds | None = None, **options: Any) -> None:
        self.config = SafetyConfig.from_options(config, **options)
        self.core = _core_of(target)
        self.model = safety_model(target, bounds)
        if not _has_position_rows(self.model):
            warnings.warn(f"safety filter on {self.model.env_id} ({getattr(self.core.scenario, 'name', '')}): the "
                          "scenario has no keep-out distance (collision_distance = 0), so the filter enforces "
                          "no separation, only the thrust box; give the env a collision_distance [m] "
                          "(e.g. satenv.make('formation_v0', collision_distance=5.0, ...))", SafetyWarning,
                          stacklevel=2)

    def filter(self, actions: Any) -> tuple[np.ndarray, SafetyRecord]:
        """Safe actions ``(B, M, d)`` (or ``(M, d)`` for ``(M, d)`` input) and the record."""
        a = _real_array("actions", actions)
        single = a.ndim == 2
        x = self.core.x
        copies = len(x)
        if a.ndim == 3 and len(a) != copies:
            raise SafetyError(f"safety filter: actions has {len(a)} copies (shape {a.shape}) but the env it "
                              f"filters for has {copies}; expected shape ({copies}, {self.model.n_agents}, "
                              f"{self.model.action_dim})" + (f" or ({self.model.n_agents}, {self.model.action_dim})"
                                                              if copies == 1 else ""))
        t = self.core.t * self.model.dt
        out, rec = filter_actions(self.model, self.config, x, t, a[None] if single else a)
        return (out[0], rec) if single else (out, rec)
