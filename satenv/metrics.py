"""Episode metrics: pure functions of a :class:`satenv.rollout.Trajectory`.

Per-agent metrics return arrays ``(M,)``. The paper definitions (pereira2023 §IV), with
``e(k)`` the tracking error (``info["tracking_error"]``) and ``n_k`` the number of steps::

    RMSE  = sqrt(1/n_k sum_{k=0}^{n_k-1} ||e(k)||^2)
    RMSEE = sqrt(1/n_k sum_{k=0}^{n_k-1} ||u(k)||^2)      (u in m/s^2)
    FOE   = ||e(n_k)||

Success (:func:`success`, the one rule the scoreboard and the training evaluation use): every
agent's final position error is within the scenario's ``success_tol`` and, where the scenario's
``collision_voids_success`` says so, no collision flag was raised (both are copied onto the
:class:`~satenv.rollout.Trajectory` by :func:`satenv.rollout.rollout`).

Every function validates what it reads and raises :class:`satenv.errors.SatenvError` (or its
``SatenvTypeError``) naming the field: ``info[key]`` a real array ``(T + 1, M, ...)`` of finite
values with at least one step (``T >= 1``: an empty or reset-only trajectory has no metric), as
many rows as ``t`` and columns as ``agents`` where the trajectory has them; ``dt`` and the
tolerances finite and > 0; ``t`` finite and non-decreasing; ``collision_voids_success`` a bool.
No metric returns NaN silently: the one documented ``nan`` is :func:`time_to_converge` of an
agent that has not converged.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np

from satenv.errors import SatenvError, SatenvTypeError


def _info(traj, key: str) -> np.ndarray:
    """``traj.info[key]`` as a finite real array ``(T + 1, M, ...)`` with ``T >= 1`` (validated)."""
    info = getattr(traj, "info", None)
    if not isinstance(info, Mapping):
        raise SatenvTypeError(f"trajectory.info must be a dict of arrays (a satenv.rollout.Trajectory), "
                              f"got {type(info).__name__}")
    if key not in info:
        raise SatenvError(f"trajectory.info[{key!r}] is missing; the metric needs it (recorded by "
                          "satenv.rollout.rollout from the env's infos)")
    field = f"trajectory.info[{key!r}]"
    try:
        a = np.asarray(info[key])
    except (TypeError, ValueError) as err:
        raise SatenvTypeError(f"{field} must be a numeric array, got {type(info[key]).__name__} ({err})") from None
    if a.dtype.kind not in "biuf" or np.ma.isMaskedArray(info[key]):
        raise SatenvTypeError(f"{field} must be a real numeric array, got dtype {a.dtype}")
    if a.ndim < 2:
        raise SatenvError(f"{field} must have shape (T + 1, M, ...), got {a.shape}")
    if a.shape[0] < 2:
        raise SatenvError(f"{field} has {a.shape[0]} entries: the trajectory has no step (an empty or "
                          "reset-only episode); the metrics need at least one step (T >= 1)")
    t = getattr(traj, "t", None)
    if t is not None and np.shape(t) != (a.shape[0],):
        raise SatenvError(f"{field} has {a.shape[0]} entries but trajectory.t has shape {np.shape(t)}; "
                          "expected T + 1 of each")
    agents = getattr(traj, "agents", None)
    if agents is not None and a.shape[1] != len(agents):
        raise SatenvError(f"{field} has {a.shape[1]} agent columns but trajectory.agents lists "
                          f"{len(agents)}")
    if a.dtype.kind == "f" and not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0]
        raise SatenvError(f"{field} holds NaN/inf (first at index {tuple(int(i) for i in bad)}); the "
                          "metrics of a corrupt trajectory would be NaN")
    if key in NONNEGATIVE_INFO and (a < 0).any():
        bad = np.argwhere(a < 0)[0]
        raise SatenvError(f"{field} holds a negative entry (first at index {tuple(int(i) for i in bad)}); "
                          f"it is a magnitude or a count (>= 0): the trajectory is corrupt")
    return a


NONNEGATIVE_INFO = frozenset({"delta_v", "min_separation", "violations", "cost"})
"""Info keys that are magnitudes or counts: a negative entry is a corrupt record, not a metric."""


def _positive(name: str, value: Any) -> float:
    """``value`` as a finite float > 0 (a real number, not a bool), else the typed error."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise SatenvTypeError(f"{name} must be a real number > 0, got {value!r:.60}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond the float range
        v = math.inf
    if not (math.isfinite(v) and v > 0):
        raise SatenvError(f"{name} must be finite and > 0, got {value!r:.60}")
    return v


def _times(traj) -> np.ndarray:
    """``traj.t`` validated: finite, non-decreasing (and ``traj.dt`` > 0 when present)."""
    if getattr(traj, "dt", None) is not None:
        _positive("trajectory.dt", traj.dt)
    try:
        t = np.asarray(traj.t, dtype=float)
    except (AttributeError, TypeError, ValueError):
        raise SatenvTypeError("trajectory.t must be a 1-D array of times [s]") from None
    if t.ndim != 1 or not np.isfinite(t).all() or (np.diff(t) < 0).any():
        raise SatenvError(f"trajectory.t must be a finite, non-decreasing 1-D array of times [s], got "
                          f"shape {t.shape}")
    return t


def _finite(value: Any, key: str) -> Any:
    """``value`` unless it overflowed to inf (finite inputs of magnitude near the float range)."""
    if not np.isfinite(value).all():
        raise SatenvError(f"trajectory.info[{key!r}] is too large: the metric overflows float64 "
                          "(entries near 1e154 or beyond); check the recorded episode")
    return value


def rmse(traj) -> np.ndarray:
    """Root-mean-square tracking error over ``k = 0 .. n_k - 1`` per agent."""
    e = _info(traj, "tracking_error")[:-1]
    return _finite(np.sqrt(np.mean(np.sum(e.reshape(e.shape[0], e.shape[1], -1) ** 2, axis=-1), axis=0)),
                   "tracking_error")


def rmsee(traj) -> np.ndarray:
    """Root-mean-square applied acceleration [m/s^2] per agent (the paper's 'energy expended')."""
    u = _info(traj, "accel")[1:]
    return _finite(np.sqrt(np.mean(np.sum(u.reshape(u.shape[0], u.shape[1], -1) ** 2, axis=-1), axis=0)), "accel")


def foe(traj) -> np.ndarray:
    """Final output error ``||e(n_k)||`` per agent."""
    e = _info(traj, "tracking_error")[-1]
    return _finite(np.linalg.norm(e.reshape(e.shape[0], -1), axis=-1), "tracking_error")


def final_position_error(traj) -> np.ndarray:
    """Norm of the position part (first 3 entries) of the final tracking error, per agent [m]."""
    e = _info(traj, "tracking_error")
    if e.ndim != 3:
        raise SatenvError(f"trajectory.info['tracking_error'] must have shape (T + 1, M, k), got {e.shape}")
    return _finite(np.linalg.norm(e[-1][..., :3], axis=-1), "tracking_error")


def delta_v_total(traj) -> np.ndarray:
    """Total delta-v spent per agent [m/s]."""
    return _finite(np.sum(_info(traj, "delta_v")[1:], axis=0), "delta_v")


def min_separation(traj) -> float:
    """Smallest distance between any agent and any other body over the episode [m]."""
    return float(np.min(_info(traj, "min_separation")))


def collisions(traj) -> int:
    """Number of (step, agent) collision flags raised."""
    return int(np.sum(_info(traj, "collision") != 0))


def violations(traj) -> int:
    """Total constraint violations counted by the environment."""
    return int(np.sum(_info(traj, "violations"), dtype=float))


def safety_cost(traj) -> float:
    """Sum of the environment's safety cost over the episode."""
    return float(_finite(np.sum(_info(traj, "cost")), "cost"))


def _tol(traj, tol: float | None) -> float:
    if tol is None:
        return _positive("trajectory.success_tol", getattr(traj, "success_tol", None))
    return _positive("tol", tol)


def time_to_converge(traj, tol: float | None = None) -> np.ndarray:
    """Per agent, the first time [s] after which the position tracking error stays <= ``tol`` m
    (default ``traj.success_tol``).

    ``nan`` for an agent that is not within ``tol`` at the end.
    """
    tol = _tol(traj, tol)
    e = _info(traj, "tracking_error")
    t = _times(traj)
    if e.ndim != 3 or t.shape != (e.shape[0],):
        raise SatenvError(f"trajectory.info['tracking_error'] must have shape (T + 1, M, k) with T + 1 = "
                          f"len(trajectory.t); got {e.shape} and {t.shape}")
    err = _finite(np.linalg.norm(e[..., :3], axis=-1), "tracking_error")   # (T+1, M)
    out = np.full(err.shape[1], np.nan)
    for i in range(err.shape[1]):
        outside = np.nonzero(err[:, i] > tol)[0]
        if outside.size == 0:
            out[i] = t[0]
        elif outside[-1] < len(err) - 1:
            out[i] = t[outside[-1] + 1]
    return out


def success(traj, tol: float | None = None) -> bool:
    """Every agent within ``tol`` m (default ``traj.success_tol``) of its target at the end and,
    if ``traj.collision_voids_success``, no collision flag during the episode."""
    reached = bool(np.all(final_position_error(traj) <= _tol(traj, tol)))
    voids = getattr(traj, "collision_voids_success", True)
    if not isinstance(voids, bool | np.bool_):
        raise SatenvTypeError(f"trajectory.collision_voids_success must be a bool, got {voids!r:.40}")
    return reached and not (voids and collisions(traj) > 0)


def summary(traj, tol: float | None = None) -> dict[str, Any]:
    """Every scoreboard metric of one episode (team aggregates are means / max over agents);
    ``tol`` defaults to ``traj.success_tol``."""
    ttc = time_to_converge(traj, tol)
    pinfo = traj.policy_info
    if not isinstance(pinfo, Mapping):
        raise SatenvTypeError(f"trajectory.policy_info must be a dict, got {type(pinfo).__name__}")
    fallbacks = pinfo.get("fallbacks", 0)
    if isinstance(fallbacks, bool) or not isinstance(fallbacks, numbers.Integral) or not 0 <= fallbacks < 2**63:
        raise SatenvError(f"trajectory.policy_info['fallbacks'] must be an int in [0, 2**63), got "
                          f"{fallbacks!r:.40}")
    compute = np.asarray(traj.compute_time)
    if compute.dtype.kind not in "biuf" or compute.ndim != 1 or not np.isfinite(compute).all() \
            or (compute < 0).any():
        raise SatenvError(f"trajectory.compute_time must be a 1-D array of finite seconds >= 0, got "
                          f"shape {compute.shape}, dtype {compute.dtype}")
    return {
        "success": success(traj, tol),
        "rmse": float(np.mean(rmse(traj))),
        "rmsee": float(np.mean(rmsee(traj))),
        "foe": float(np.mean(foe(traj))),
        "final_error_m": float(np.max(final_position_error(traj))),
        "delta_v": float(np.sum(delta_v_total(traj))),
        "time_to_converge_s": float(np.max(ttc)) if np.all(np.isfinite(ttc)) else float("nan"),
        "min_separation_m": min_separation(traj),
        "collisions": collisions(traj),
        "violations": violations(traj),
        "safety_cost": safety_cost(traj),
        "fallbacks": int(fallbacks),
        "compute_ms_per_decision": float(np.mean(compute) * 1e3) if compute.size else 0.0,
        "steps": traj.steps,
        "terminated": bool(traj.terminated),
    }


def matched_ratios(mine: list[dict[str, Any]], ref: list[dict[str, Any]]) -> dict[str, Any]:
    """RMSE and delta-v ratios, ``mine`` over ``ref``, of episode summaries (:func:`summary` records
    with a ``seed``), on *matched, completed* episodes only: the seeds where both ran to the end
    without a collision, so an episode that ends early cannot improve a ratio. Returns
    ``matched_seeds`` and, when it is > 0, ``rmse_ratio`` and ``delta_v_ratio`` (ratios of the means)."""
    by = {e["seed"]: e for e in ref}
    pairs = [(e, by[e["seed"]]) for e in mine if e["seed"] in by]
    ok = [(a, b) for a, b in pairs if not (a["terminated"] or b["terminated"] or a["collisions"] or b["collisions"])]
    if not ok:
        return {"matched_seeds": 0}
    return {"matched_seeds": len(ok),
            "rmse_ratio": float(np.mean([a["rmse"] for a, _ in ok]) / np.mean([b["rmse"] for _, b in ok])),
            "delta_v_ratio": float(np.mean([a["delta_v"] for a, _ in ok]) / np.mean([b["delta_v"] for _, b in ok]))}
