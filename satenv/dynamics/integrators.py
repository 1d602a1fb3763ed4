"""Fixed-step explicit Runge-Kutta integrators for ``y' = f(t, y)`` on ndarrays."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ._dop853 import STAGES, A, B, C

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


def dop853_step(f: Derivative, t: float, y: np.ndarray, dt: float) -> np.ndarray:
    """One fixed step of DOP853's eighth-order solution (twelve stages, :mod:`._dop853`; no
    error estimate, no step control)."""
    k = [f(t, y)]
    for i in range(1, STAGES):
        acc = A[i, 0] * k[0]
        for j in range(1, i):
            if A[i, j] != 0.0:
                acc = acc + A[i, j] * k[j]
        k.append(f(t + C[i] * dt, y + dt * acc))
    acc = B[0] * k[0]
    for j in range(1, STAGES):
        if B[j] != 0.0:
            acc = acc + B[j] * k[j]
    return y + dt * acc


INTEGRATORS: dict[str, Callable[[Derivative, float, np.ndarray, float], np.ndarray]] = {
    "euler": euler_step,
    "rk4": rk4_step,
    "dop853": dop853_step,
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
