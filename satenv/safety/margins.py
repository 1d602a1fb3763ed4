"""Robust margins: the filter's rows tightened by the declared :class:`UncertaintyBounds`.

The filter plans with the nominal model and reads the navigation estimate
(:func:`satenv.perturbations.nominal`); what it cannot see is bounded by the env's declared
bounds (:func:`satenv.perturbations.declared_bounds`): position error ``dp`` and velocity error
``dv`` per agent, an unmodelled disturbance ``w`` per agent, a thrust loss ``theta``. Every margin
below is derived from them (none is tuned); zero bounds leave every row exactly as it was.

Per position slot, ``k`` is the number of estimated (and disturbed) agents in the relative state:
2 for a pair of agents or a platoon target-chaser pair, 1 against a body whose motion is known.

* **Position error.** The relative position estimate is off by at most ``e_p = k dp``, so the true
  gap is at least the estimated one minus ``e_p`` (triangle inequality for a sphere; unit normals
  for a half-space): a pair's separation shrinks by ``2 dp``.
* **Velocity error.** The relative velocity estimate is off by at most ``e_v = k dv``.
* **One decision of prediction.** The coasting prediction ``A r`` carries the estimate's error
  through the CW blocks: the predicted gap is off by ``||A_pp|| e_p + ||A_pv|| e_v``, the
  predicted velocity by ``||A_vp|| e_p + ||A_vv|| e_v`` (2-norms).
* **Rate.** ``rho = n^T r_v`` is off by the velocity error plus the direction error of ``n``
  times the speed: ``eps = e_v' + min(2, 2 e_p' / (d - e_p')) ||r_v||`` (``||n_hat - n|| <= 2 e /
  (d - e)`` for a sphere at distance ``d``; a half-space's normal is exact). The barrier
  ``h = rho + sqrt(2 a s)`` uses the rate lowered by ``eps``. That is the gap shrunk by what
  the error costs to brake: a closing speed ``c + eps`` stops in ``(c + eps)^2 / (2a) = c^2 / (2a)
  + eps t_brake + eps^2 / (2a)`` with ``t_brake = c / a``.
* **Disturbance.** ``w`` per agent lowers the braking authority by ``k w`` (as the scenario's own
  disturbance does) and over one decision moves the gap by at most ``k w dt^2 / 2`` and the rate
  by ``k w dt``.
* **Thrust loss.** The applied acceleration is ``kappa S u`` with ``kappa`` in ``[1 - theta, 1]``:
  the braking authority is ``(1 - theta) a``, and a row ``w^T S u >= l``, linear in ``kappa``,
  holds for every ``kappa`` iff it holds at both ends: for ``l <= 0`` the nominal row implies it
  (``kappa y >= min(y, 0) >= l``), for ``l > 0`` it is ``w^T S u >= l / (1 - theta)``.
* **Velocity boxes** (relative degree one): the predicted velocity is off by ``||A_vp|| dp +
  ||A_vv|| dv + w dt`` per agent (platoon: times ``sum_j |Lbar_fj|``), the bound tightens by it.

Bounds that hold only with a probability (a Gaussian navigation error) make the guarantee of
:mod:`satenv.safety` hold with that probability per draw.
"""

from __future__ import annotations

import numpy as np

from satenv.perturbations import UncertaintyBounds
from satenv.safety.model import SafetyModel

__all__ = ["UncertaintyBounds", "estimated_agents", "prediction_errors", "tighten_geometry",
           "tighten_lower", "velocity_error"]


def estimated_agents(m: SafetyModel) -> np.ndarray:
    """``k`` of every position slot ``(slots,)``, in the order of the rows: pairs, bodies, chain."""
    pairs = m.n_agents if m.pair_distance > 0 else 0
    return np.r_[np.full(pairs, 2.0), np.ones(len(m.bodies)), np.full(m.n_chain, 2.0)]


def prediction_errors(m: SafetyModel, e_p: np.ndarray, e_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on the position and velocity error of the one-decision coasting prediction of a
    state whose errors are bounded by ``e_p``, ``e_v``."""
    norm = lambda block: float(np.linalg.norm(block, 2))  # noqa: E731
    a = m.A
    return (norm(a[:3, :3]) * e_p + norm(a[:3, 3:]) * e_v, norm(a[3:, :3]) * e_p + norm(a[3:, 3:]) * e_v)


def tighten_geometry(m: SafetyModel, geo: list[np.ndarray], distance_bar: np.ndarray | None,
                     k: np.ndarray) -> list[np.ndarray]:
    """``(gap0, rate0, gap_bar, dirn, vel_bar)`` of the slots ``(..., slots)`` tightened by the
    bounds (module docstring). ``distance_bar``: the predicted distance of the sphere slots
    (``inf`` for a half-space, whose normal is exact)."""
    b: UncertaintyBounds = m.bounds
    if b.exact:
        return geo
    gap0, rate0, gap_bar, dirn, vel_bar = geo
    e_p, e_v = k * b.position, k * b.velocity
    p_bar, v_bar = prediction_errors(m, e_p, e_v)
    push = k * b.disturbance
    speed0 = np.linalg.norm(vel_bar, axis=-1)       # the direction term uses the predicted speed
    turn = lambda e, d: np.minimum(2.0, 2.0 * e / np.maximum(d - e, 1e-12))  # noqa: E731
    eps0 = e_v + turn(e_p, distance_bar) * speed0
    eps_bar = v_bar + turn(p_bar, distance_bar) * speed0 + push * m.dt
    return [gap0 - e_p, rate0 - eps0, gap_bar - p_bar - push * m.dt**2 / 2.0, dirn,
            vel_bar - eps_bar[..., None] * dirn]


def tighten_lower(m: SafetyModel, lower: np.ndarray) -> np.ndarray:
    """Rows ``w^T S u >= l`` robust to the thrust loss: ``l > 0`` becomes ``l / (1 - theta)``."""
    theta = m.bounds.thrust
    return lower if not theta else np.where(lower > 0.0, lower / (1.0 - theta), lower)


def velocity_error(m: SafetyModel) -> float:
    """Bound on one agent's predicted velocity error (for the velocity boxes)."""
    b: UncertaintyBounds = m.bounds
    return float(prediction_errors(m, np.float64(b.position), np.float64(b.velocity))[1]) + b.disturbance * m.dt
