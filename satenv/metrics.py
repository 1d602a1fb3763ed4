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
"""

from __future__ import annotations

from typing import Any

import numpy as np


def rmse(traj) -> np.ndarray:
    """Root-mean-square tracking error over ``k = 0 .. n_k - 1`` per agent."""
    e = traj.info["tracking_error"][:-1]
    return np.sqrt(np.mean(np.sum(e.reshape(e.shape[0], e.shape[1], -1) ** 2, axis=-1), axis=0))


def rmsee(traj) -> np.ndarray:
    """Root-mean-square applied acceleration [m/s^2] per agent (the paper's 'energy expended')."""
    u = traj.info["accel"][1:]
    return np.sqrt(np.mean(np.sum(u**2, axis=-1), axis=0))


def foe(traj) -> np.ndarray:
    """Final output error ``||e(n_k)||`` per agent."""
    e = traj.info["tracking_error"][-1]
    return np.linalg.norm(e.reshape(e.shape[0], -1), axis=-1)


def final_position_error(traj) -> np.ndarray:
    """Norm of the position part (first 3 entries) of the final tracking error, per agent [m]."""
    return np.linalg.norm(traj.info["tracking_error"][-1][..., :3], axis=-1)


def delta_v_total(traj) -> np.ndarray:
    """Total delta-v spent per agent [m/s]."""
    return np.sum(traj.info["delta_v"][1:], axis=0)


def min_separation(traj) -> float:
    """Smallest distance between any agent and any other body over the episode [m]."""
    return float(np.min(traj.info["min_separation"]))


def collisions(traj) -> int:
    """Number of (step, agent) collision flags raised."""
    return int(np.sum(traj.info["collision"]))


def violations(traj) -> int:
    """Total constraint violations counted by the environment."""
    return int(np.sum(traj.info["violations"]))


def safety_cost(traj) -> float:
    """Sum of the environment's safety cost over the episode."""
    return float(np.sum(traj.info["cost"]))


def _tol(traj, tol: float | None) -> float:
    return float(traj.success_tol if tol is None else tol)


def time_to_converge(traj, tol: float | None = None) -> np.ndarray:
    """Per agent, the first time [s] after which the position tracking error stays <= ``tol`` m
    (default ``traj.success_tol``).

    ``nan`` for an agent that is not within ``tol`` at the end.
    """
    tol = _tol(traj, tol)
    err = np.linalg.norm(traj.info["tracking_error"][..., :3], axis=-1)   # (T+1, M)
    out = np.full(err.shape[1], np.nan)
    for i in range(err.shape[1]):
        outside = np.nonzero(err[:, i] > tol)[0]
        if outside.size == 0:
            out[i] = traj.t[0]
        elif outside[-1] < len(err) - 1:
            out[i] = traj.t[outside[-1] + 1]
    return out


def success(traj, tol: float | None = None) -> bool:
    """Every agent within ``tol`` m (default ``traj.success_tol``) of its target at the end and,
    if ``traj.collision_voids_success``, no collision flag during the episode."""
    reached = bool(np.all(final_position_error(traj) <= _tol(traj, tol)))
    return reached and not (traj.collision_voids_success and collisions(traj) > 0)


def summary(traj, tol: float | None = None) -> dict[str, Any]:
    """Every scoreboard metric of one episode (team aggregates are means / max over agents);
    ``tol`` defaults to ``traj.success_tol``."""
    ttc = time_to_converge(traj, tol)
    pinfo = traj.policy_info
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
        "fallbacks": int(pinfo.get("fallbacks", 0)),
        "compute_ms_per_decision": float(np.mean(traj.compute_time) * 1e3) if traj.compute_time.size else 0.0,
        "steps": traj.steps,
        "terminated": bool(traj.terminated),
    }
