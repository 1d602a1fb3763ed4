"""Compiled (numba) truth propagation: :meth:`RelativeModel.step` of the ``nonlinear`` / ``j2`` /
``j2_drag`` models over many steps in one call.

The numpy path (:mod:`._soa`, :func:`.forces.acceleration_soa`, :func:`.integrators.rk4_step`)
is the reference; this kernel evaluates the same formulas (in the same order but for the
reciprocal of ``|r|^2``), per copy and per body, with no temporaries. The LVLH <-> ECI conversions are hoisted out of the step loop: a call
converts the LVLH states to ECI once, integrates ``n`` steps of ``substeps`` RK4 sub-steps (the
LVLH inputs of step ``s`` held in the rotating frame, as the reference: they are rotated by the
chief's current LVLH axes at every stage) and converts back once. Converting back and forth at
every step, as ``n`` calls of the reference do, is the identity up to rounding, so the two agree
to rounding (``tests/test_truth_kernel.py``). Optionally the LVLH positions after every step are
written out (a rotation only: the frame rate does not enter positions). Importing this module
imports numba; compiled code is cached next to the module.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .forces import ForceModel

__all__ = ["force_params", "propagate"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")  # IEEE division, no zero checks

N_PARAMS = 11


def force_params(force: ForceModel) -> np.ndarray:
    """The kernel's packed force constants: ``[mu, r_earth, -1.5 J2 r_earth^2, omega_earth,
    rho0, h0, scale_height, ballistic_chief, ballistic_deputy, j2 flag, drag flag]`` (the
    J2 factor formed with the same Python float operations as the reference)."""
    return np.array([force.mu, force.r_earth, -1.5 * force.j2_coef * force.r_earth**2,
                     force.omega_earth, force.rho0, force.h0, force.scale_height,
                     force.ballistic_chief, force.ballistic_deputy,
                     1.0 if force.j2 else 0.0, 1.0 if force.drag else 0.0])


@_jit
def _accel(x, y, z, vx, vy, vz, p, ballistic):
    """:func:`satenv.dynamics.forces.acceleration_soa` of one body (its formulas; the divisions by
    ``|r|^2`` as products with one reciprocal)."""
    rn2 = x * x + y * y + z * z
    inv2 = 1.0 / rn2                     # one division, multiplied (the reference divides thrice)
    rn = np.sqrt(rn2)
    inv_r3 = inv2 / rn
    mu = p[0]
    if p[9] != 0.0:
        k = p[2] * inv2
        z2 = 5.0 * z * z * inv2
        kxy = -mu * inv_r3 * (1.0 + k * (z2 - 1.0))
        kz = -mu * inv_r3 * (1.0 + k * (z2 - 3.0))
        a0, a1, a2 = kxy * x, kxy * y, kz * z
    else:
        kk = -mu * inv_r3
        a0, a1, a2 = kk * x, kk * y, kk * z
    if p[10] != 0.0:
        w = p[3]
        vr0, vr1, vr2 = vx + w * y, vy - w * x, vz
        h = rn - p[1]
        rho = p[4] * math.exp(-(h - p[5]) / p[6])
        kd = -0.5 * (rho * ballistic * np.sqrt(vr0 * vr0 + vr1 * vr1 + vr2 * vr2))
        a0 += kd * vr0
        a1 += kd * vr1
        a2 += kd * vr2
    return a0, a1, a2


@_jit
def _axes(y, e):
    """LVLH unit axes of the chief ``y[:, 0]`` into rows of ``e`` (3, 3): ex, ey, ez; returns
    ``h = r x v`` (:func:`satenv.dynamics._soa.lvlh_axes`)."""
    r0, r1, r2, v0, v1, v2 = y[0, 0], y[1, 0], y[2, 0], y[3, 0], y[4, 0], y[5, 0]
    rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    e[0, 0], e[0, 1], e[0, 2] = r0 / rn, r1 / rn, r2 / rn
    h0, h1, h2 = r1 * v2 - r2 * v1, r2 * v0 - r0 * v2, r0 * v1 - r1 * v0
    hn = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    e[2, 0], e[2, 1], e[2, 2] = h0 / hn, h1 / hn, h2 / hn
    e[1, 0] = e[2, 1] * e[0, 2] - e[2, 2] * e[0, 1]
    e[1, 1] = e[2, 2] * e[0, 0] - e[2, 0] * e[0, 2]
    e[1, 2] = e[2, 0] * e[0, 1] - e[2, 1] * e[0, 0]
    return h0, h1, h2


@_jit
def _frame_rate(y, h0, h1, h2, p):
    """``(omega_x, omega_z)`` of the LVLH frame of chief ``y[:, 0]`` under its full acceleration
    (:func:`satenv.dynamics._soa.frame_rate_soa`)."""
    r0, r1, r2 = y[0, 0], y[1, 0], y[2, 0]
    a0, a1, a2 = _accel(r0, r1, r2, y[3, 0], y[4, 0], y[5, 0], p, p[7])
    rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    hn = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    wz = hn / (rn * rn)
    wx = rn * (a0 * h0 + a1 * h1 + a2 * h2) / (hn * hn)
    return wx, wz


@_jit
def _rhs(y, u, p, e, dy):
    """Right-hand side of the packed state ``y`` (6, 1 + M) (row 0 the chief, ECI; rows 1.. the
    deputies relative to it, ECI) under LVLH inputs ``u`` (M, 3) into ``dy``
    (:func:`satenv.dynamics._soa.derivative_soa`)."""
    rc0, rc1, rc2, vc0, vc1, vc2 = y[0, 0], y[1, 0], y[2, 0], y[3, 0], y[4, 0], y[5, 0]
    ac0, ac1, ac2 = _accel(rc0, rc1, rc2, vc0, vc1, vc2, p, p[7])
    _axes(y, e)
    for c in range(3):
        dy[c, 0] = y[3 + c, 0]
    dy[3, 0], dy[4, 0], dy[5, 0] = ac0, ac1, ac2
    for j in range(1, y.shape[1]):
        a0, a1, a2 = _accel(rc0 + y[0, j], rc1 + y[1, j], rc2 + y[2, j],
                            vc0 + y[3, j], vc1 + y[4, j], vc2 + y[5, j], p, p[8])
        u0, u1, u2 = u[j - 1, 0], u[j - 1, 1], u[j - 1, 2]
        dy[0, j], dy[1, j], dy[2, j] = y[3, j], y[4, j], y[5, j]
        dy[3, j] = (a0 - ac0) + e[0, 0] * u0 + e[1, 0] * u1 + e[2, 0] * u2
        dy[4, j] = (a1 - ac1) + e[0, 1] * u0 + e[1, 1] * u1 + e[2, 1] * u2
        dy[5, j] = (a2 - ac2) + e[0, 2] * u0 + e[1, 2] * u1 + e[2, 2] * u2


@_jit
def _rk4(y, u, h, p, e, k1, k2, k3, k4, tmp):
    """One classical RK4 step of ``y`` in place (:func:`satenv.dynamics.integrators.rk4_step`)."""
    half = 0.5 * h
    _rhs(y, u, p, e, k1)
    for c in range(6):
        for j in range(y.shape[1]):
            tmp[c, j] = y[c, j] + half * k1[c, j]
    _rhs(tmp, u, p, e, k2)
    for c in range(6):
        for j in range(y.shape[1]):
            tmp[c, j] = y[c, j] + half * k2[c, j]
    _rhs(tmp, u, p, e, k3)
    for c in range(6):
        for j in range(y.shape[1]):
            tmp[c, j] = y[c, j] + h * k3[c, j]
    _rhs(tmp, u, p, e, k4)
    sixth = h / 6.0
    for c in range(6):
        for j in range(y.shape[1]):
            y[c, j] = y[c, j] + sixth * (k1[c, j] + 2.0 * (k2[c, j] + k3[c, j]) + k4[c, j])


@_jit
def _to_eci(x, b, chief, p, e, y):
    """LVLH states ``x[b]`` (M, 6) and chief ``chief[b]`` -> packed ``y``
    (:func:`satenv.dynamics._soa.lvlh_to_eci_rel_soa`)."""
    for c in range(6):
        y[c, 0] = chief[b, c]
    h0, h1, h2 = _axes(y, e)
    wx, wz = _frame_rate(y, h0, h1, h2, p)
    for j in range(x.shape[1]):
        r0, r1, r2 = x[b, j, 0], x[b, j, 1], x[b, j, 2]
        d0 = x[b, j, 3] - wz * r1
        d1 = x[b, j, 4] + (wz * r0 - wx * r2)
        d2 = x[b, j, 5] + wx * r1
        for c in range(3):
            y[c, j + 1] = e[0, c] * r0 + e[1, c] * r1 + e[2, c] * r2
            y[3 + c, j + 1] = e[0, c] * d0 + e[1, c] * d1 + e[2, c] * d2


@_jit
def _to_lvlh(y, e, p, b, x_out, chief_out):
    """Packed ``y`` -> LVLH states ``x_out[b]`` and chief ``chief_out[b]``
    (:func:`satenv.dynamics._soa.eci_rel_to_lvlh_soa`)."""
    for c in range(6):
        chief_out[b, c] = y[c, 0]
    h0, h1, h2 = _axes(y, e)
    wx, wz = _frame_rate(y, h0, h1, h2, p)
    for j in range(x_out.shape[1]):
        for i in range(3):
            x_out[b, j, i] = e[i, 0] * y[0, j + 1] + e[i, 1] * y[1, j + 1] + e[i, 2] * y[2, j + 1]
            x_out[b, j, 3 + i] = e[i, 0] * y[3, j + 1] + e[i, 1] * y[4, j + 1] + e[i, 2] * y[5, j + 1]
        r0, r1, r2 = x_out[b, j, 0], x_out[b, j, 1], x_out[b, j, 2]
        x_out[b, j, 3] += wz * r1
        x_out[b, j, 4] -= wz * r0 - wx * r2
        x_out[b, j, 5] -= wx * r1


@_jit
def propagate(x, chief, u, substeps, h, p, x_out, chief_out, path):
    """Propagate LVLH states ``x`` (B, M, 6) and chief ECI states ``chief`` (B, 6) over
    ``u.shape[0]`` steps of ``substeps`` RK4 sub-steps of ``h`` seconds, the LVLH inputs ``u[s]``
    (B, M, 3) held over step ``s``; ``p`` from :func:`force_params`. Writes the final states into
    ``x_out`` / ``chief_out`` (may be ``x`` / ``chief``), and, when ``path.shape[0] > 0``, the
    LVLH positions after every step into ``path`` (S, B, M, 3)."""
    nb, m = x.shape[0], x.shape[1]
    y = np.empty((6, 1 + m))
    k1, k2, k3 = np.empty((6, 1 + m)), np.empty((6, 1 + m)), np.empty((6, 1 + m))
    k4, tmp = np.empty((6, 1 + m)), np.empty((6, 1 + m))
    e = np.empty((3, 3))
    recording = path.shape[0] > 0
    for b in range(nb):
        _to_eci(x, b, chief, p, e, y)
        for s in range(u.shape[0]):
            us = u[s, b]
            for _ in range(substeps):
                _rk4(y, us, h, p, e, k1, k2, k3, k4, tmp)
            if recording:
                _axes(y, e)
                for j in range(m):
                    for i in range(3):
                        path[s, b, j, i] = (e[i, 0] * y[0, j + 1] + e[i, 1] * y[1, j + 1]
                                            + e[i, 2] * y[2, j + 1])
        _to_lvlh(y, e, p, b, x_out, chief_out)
