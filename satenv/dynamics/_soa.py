"""Structure-of-arrays kernels of the truth-model step (the hot path of ``RelativeModel.step``).

The LVLH frame rate, the LVLH <-> ECI conversions and the right-hand side of the packed state
(the acceleration kernel itself is :func:`satenv.dynamics.forces.acceleration_soa`), evaluated on
component-major arrays so that every numpy operation
runs over one contiguous block (the batch-first public functions of :mod:`.forces` and
:mod:`.orbit` move the component axis and call these): the packed state is ``Y`` of shape ``(6, 1 + M, B)`` —
component, body (0 = chief, absolute ECI; 1.. = deputies relative to the chief, ECI), batch.
Chief quantities ``(3, B)`` broadcast over the deputies as ``(3, 1, B)``.
"""

from __future__ import annotations

import numpy as np

from .forces import ForceModel, acceleration_soa


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def lvlh_axes(r: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """LVLH unit axes ``ex, ey, ez`` (each ``(3, B)``, in ECI) of chief states ``r, v`` ``(3, B)``,
    and ``h = r x v``."""
    ex = r / np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    h = _cross(r, v)
    ez = h / np.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    return ex, _cross(ez, ex), ez, h


def frame_rate_soa(r: np.ndarray, h: np.ndarray, acc: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(omega_x, omega_z)`` of the LVLH frame (:func:`satenv.dynamics.orbit.frame_rate`)."""
    rn = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    hn = np.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    wz = hn / rn**2
    if acc is None:
        return np.zeros_like(wz), wz
    return rn * (acc[0] * h[0] + acc[1] * h[1] + acc[2] * h[2]) / hn**2, wz


def lvlh_to_eci_rel_soa(chief: np.ndarray, x: np.ndarray, acc: np.ndarray | None) -> np.ndarray:
    """LVLH relative states ``(6, M, B)`` -> relative ECI states ``(6, M, B)``; chief ``(6, B)``."""
    ex, ey, ez, h = lvlh_axes(chief[:3], chief[3:])
    wx, wz = frame_rate_soa(chief[:3], h, acc)
    r0, r1, r2 = x[0], x[1], x[2]
    d0 = x[3] - wz * r1                                    # rho_dot + omega x rho
    d1 = x[4] + (wz * r0 - wx * r2)
    d2 = x[5] + wx * r1
    ex, ey, ez = ex[:, None], ey[:, None], ez[:, None]
    out = np.empty_like(x)
    out[:3] = ex * r0 + ey * r1 + ez * r2
    out[3:] = ex * d0 + ey * d1 + ez * d2
    return out


def eci_rel_to_lvlh_soa(chief: np.ndarray, rel: np.ndarray, acc: np.ndarray | None) -> np.ndarray:
    """Relative ECI states ``(6, M, B)`` -> LVLH relative states ``(6, M, B)``; chief ``(6, B)``."""
    ex, ey, ez, h = lvlh_axes(chief[:3], chief[3:])
    wx, wz = frame_rate_soa(chief[:3], h, acc)
    out = np.empty_like(rel)
    for i, e in enumerate((ex, ey, ez)):
        e0, e1, e2 = e[0][None], e[1][None], e[2][None]
        out[i] = e0 * rel[0] + e1 * rel[1] + e2 * rel[2]
        out[3 + i] = e0 * rel[3] + e1 * rel[4] + e2 * rel[5]
    r0, r1, r2 = out[0], out[1], out[2]
    out[3] += wz * r1                                      # rho_dot = dv - omega x rho
    out[4] -= wz * r0 - wx * r2
    out[5] -= wx * r1
    return out


def derivative_soa(force: ForceModel):
    """Right-hand side on the packed state ``Y`` ``(6, 1 + M, B)`` under LVLH inputs ``(3, M, B)``."""

    def f(_t: float, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        rc, vc = y[:3, 0], y[3:, 0]
        ac = acceleration_soa(rc, vc, force, force.ballistic_chief)
        rd = rc[:, None] + y[:3, 1:]
        vd = vc[:, None] + y[3:, 1:] if force.drag else None
        ad = acceleration_soa(rd, vd, force, force.ballistic_deputy)
        ex, ey, ez, _ = lvlh_axes(rc, vc)
        dy = np.empty_like(y)
        dy[:3] = y[3:]
        dy[3:, 0] = ac
        ad -= ac[:, None]
        ad += ex[:, None] * u[0]
        ad += ey[:, None] * u[1]
        ad += ez[:, None] * u[2]
        dy[3:, 1:] = ad
        return dy

    return f
