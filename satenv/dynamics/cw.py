"""Clohessy-Wiltshire (Hill) linear relative dynamics about a circular chief orbit.

State ``[x, y, z, vx, vy, vz]`` in LVLH (x radial, y along-track, z normal), input the
deputy's control acceleration [m/s^2] (pereira2023 eq. 2-5)::

    x'' - 3 n^2 x - 2 n y' = u_x,   y'' + 2 n x' = u_y,   z'' + n^2 z = u_z
"""

from __future__ import annotations

import numpy as np

from ._checks import as_array, positive


def cw_continuous(n: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time ``(A_c, B_c)`` (6x6, 6x3) for mean motion ``n`` [rad/s] (eq. 5)."""
    n = positive(n, "n (mean motion, rad/s)")
    a_c = np.zeros((6, 6))
    a_c[:3, 3:] = np.eye(3)
    a_c[3, 0], a_c[3, 4] = 3.0 * n * n, 2.0 * n
    a_c[4, 3] = -2.0 * n
    a_c[5, 2] = -n * n
    b_c = np.vstack([np.zeros((3, 3)), np.eye(3)])
    return a_c, b_c


def _one_minus_cos(x: float) -> float:
    """``1 - cos x`` without cancellation."""
    return 2.0 * np.sin(0.5 * x) ** 2


def _x_minus_sin(x: float) -> float:
    """``x - sin x`` without cancellation (series for small ``|x|``)."""
    if abs(x) > 0.1:
        return x - np.sin(x)
    x2 = x * x
    term, total = x * x2 / 6.0, 0.0
    for k in range(1, 8):  # x^3/3! - x^5/5! + ... (error < x^19/19!)
        total += term
        term *= -x2 / ((2 * k + 2) * (2 * k + 3))
    return total


def cw_stm(n: float, t: float) -> np.ndarray:
    """Closed-form CW state-transition matrix ``Phi(t)`` (6x6): ``x(t) = Phi(t) x(0)``."""
    n = positive(n, "n (mean motion, rad/s)")
    t = float(t)
    s, nt = np.sin(n * t), n * t
    c = np.cos(nt)
    omc, xms = _one_minus_cos(nt), _x_minus_sin(nt)
    return np.array([
        [1 + 3 * omc, 0, 0, s / n, 2 * omc / n, 0],
        [-6 * xms, 1, 0, -2 * omc / n, (4 * s - 3 * nt) / n, 0],
        [0, 0, c, 0, 0, s / n],
        [3 * n * s, 0, 0, c, 2 * s, 0],
        [-6 * n * omc, 0, 0, -2 * s, 4 * c - 3, 0],
        [0, 0, -n * s, 0, 0, c],
    ])


def cw_matrices(n: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation ``(A, B)`` of the CW model (pereira2023 eq. 7).

    ``A = exp(A_c dt)`` and ``B = int_0^dt exp(A_c t) dt B_c``, both in closed form.
    """
    n = positive(n, "n (mean motion, rad/s)")
    dt = positive(dt, "dt (s)")
    s, nt = np.sin(n * dt), n * dt
    omc, xms = _one_minus_cos(nt), _x_minus_sin(nt)
    n2 = n * n
    b = np.array([
        [omc / n2, 2 * xms / n2, 0],
        [-2 * xms / n2, (4 * omc - 1.5 * nt * nt) / n2, 0],
        [0, 0, omc / n2],
        [s / n, 2 * omc / n, 0],
        [-2 * omc / n, (4 * s - 3 * nt) / n, 0],
        [0, 0, s / n],
    ])
    return cw_stm(n, dt), b


def prediction_matrices(a: np.ndarray, b: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Condensed prediction matrices over ``horizon`` steps (pereira2023 eq. 17).

    Returns ``(calA, calB)`` with shapes ``(nx*N, nx)`` and ``(nx*N, nu*N)`` such that the
    stacked states ``[x_1; ...; x_N] = calA x_0 + calB [u_0; ...; u_{N-1}]``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or b.ndim != 2 or b.shape[0] != a.shape[0]:
        raise ValueError(f"a must be (nx, nx) and b (nx, nu); got {a.shape} and {b.shape}")
    if int(horizon) != horizon or horizon < 1:
        raise ValueError(f"horizon must be a positive integer, got {horizon!r}")
    horizon = int(horizon)
    nx, nu = b.shape
    powers = [np.eye(nx)]
    for _ in range(horizon):
        powers.append(a @ powers[-1])
    cal_a = np.vstack(powers[1:])
    cal_b = np.zeros((nx * horizon, nu * horizon))
    for k in range(horizon):
        for j in range(k + 1):
            cal_b[k * nx:(k + 1) * nx, j * nu:(j + 1) * nu] = powers[k - j] @ b
    return cal_a, cal_b


def cw_step(x, u, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One discrete CW step for batched states ``(..., M, 6)`` and inputs ``(..., M, 3)``."""
    x = as_array(x, "x", (6,))
    u = as_array(u, "u", (3,))
    return x @ a.T + u @ b.T
