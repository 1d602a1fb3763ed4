"""Fixed-step explicit Runge-Kutta integrators for ``y' = f(t, y)`` on ndarrays."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

Derivative = Callable[[float, np.ndarray], np.ndarray]


def euler_step(f: Derivative, t: float, y: np.ndarray, dt: float) -> np.ndarray:
    """Explicit Euler (first order); for tests and comparisons only."""
    return y + dt * f(t, y)


def rk4_step(f: Derivative, t: float, y: np.ndarray, dt: float) -> np.ndarray:
    """Classical fourth-order Runge-Kutta step."""
    k1 = f(t, y)
    k2 = f(t + 0.5 * dt, y + (0.5 * dt) * k1)
    k3 = f(t + 0.5 * dt, y + (0.5 * dt) * k2)
    k4 = f(t + dt, y + dt * k3)
    return y + (dt / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)


INTEGRATORS: dict[str, Callable[[Derivative, float, np.ndarray, float], np.ndarray]] = {
    "euler": euler_step,
    "rk4": rk4_step,
}
"""Integrators by name; the relative propagator uses ``"rk4"`` by default."""


def integrate(f: Derivative, t0: float, y0: np.ndarray, dt: float, steps: int,
              method: str = "rk4") -> np.ndarray:
    """Integrate ``steps`` fixed steps; returns the trajectory ``(steps + 1, *y0.shape)``."""
    if method not in INTEGRATORS:
        raise ValueError(f"unknown integrator {method!r}; expected one of {sorted(INTEGRATORS)}")
    stepper = INTEGRATORS[method]
    out = np.empty((steps + 1, *np.shape(y0)))
    out[0] = y0
    for k in range(steps):
        out[k + 1] = stepper(f, t0 + k * dt, out[k], dt)
    return out
