"""Compiled (numba) truth propagation: :meth:`RelativeModel.step` of the ``nonlinear`` / ``j2`` /
``j2_drag`` models over many steps in one call.

The numpy path (:mod:`._soa`, :func:`.forces.acceleration_soa`, :func:`.integrators.rk4_step`) is
the reference; this kernel evaluates the same formulas (in the same order but for the reciprocal of
``|r|^2``), per copy and per body, with no temporaries. The LVLH <-> ECI conversions are hoisted out
of the step loop: a call converts the LVLH states to ECI once, integrates ``n`` steps of
``substeps`` RK4 sub-steps (the LVLH inputs of step ``s`` held in the rotating frame, as the
reference: they are rotated by the chief's current LVLH axes at every stage) and converts back once.
Converting back and forth at every step, as ``n`` calls of the reference do, is the identity up to
rounding, so the two agree to rounding (``tests/test_truth_kernel.py``). The chief's motion does not
depend on the deputies: its RK4 stages are computed once (:func:`_chief_track`) and shared by
consecutive copies with the same chief, as the copies of a batch stepped in lockstep are. Optionally
the LVLH positions after every step are written out (a rotation only: the frame rate does not enter
positions). Importing this module imports numba; compiled code is cached next to the module.
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


TRACK = 18
"""Per RK4 stage of the chief, :func:`_chief_track` keeps its state (6), acceleration (3) and
LVLH axes ex, ey, ez (9)."""


@_jit
def _chief_record(src, e, p, rec):
    """The chief's state ``src`` (6, 1), its acceleration and its LVLH axes (into ``e``) as one
    record row ``rec`` (18,): state, acceleration, axes row by row. Returns the acceleration."""
    a0, a1, a2 = _accel(src[0, 0], src[1, 0], src[2, 0], src[3, 0], src[4, 0], src[5, 0], p, p[7])
    _axes(src, e)
    for c in range(6):
        rec[c] = src[c, 0]
    rec[6], rec[7], rec[8] = a0, a1, a2
    for r in range(3):
        for c in range(3):
            rec[9 + 3 * r + c] = e[r, c]
    return a0, a1, a2


@_jit
def _chief_track(c0, n, h, p, track, ends):
    """The chief's ``n`` RK4 sub-steps from ``c0`` (6,) (:func:`satenv.dynamics.integrators.rk4_step`
    on the chief's row of the packed state): every stage's state, acceleration and axes into
    ``track`` (4 n, 18), the state after every sub-step into ``ends`` (n, 6). The chief does not
    depend on the deputies, so copies that share a chief share its track."""
    y, tmp, e = np.empty((6, 1)), np.empty((6, 1)), np.empty((3, 3))
    k = np.empty((4, 6))
    for c in range(6):
        y[c, 0] = c0[c]
    half, sixth = 0.5 * h, h / 6.0
    for i in range(n):
        for stage in range(4):
            src = y if stage == 0 else tmp
            a0, a1, a2 = _chief_record(src, e, p, track[4 * i + stage])
            k[stage, 0], k[stage, 1], k[stage, 2] = src[3, 0], src[4, 0], src[5, 0]
            k[stage, 3], k[stage, 4], k[stage, 5] = a0, a1, a2
            if stage < 3:
                coef = h if stage == 2 else half
                for c in range(6):
                    tmp[c, 0] = y[c, 0] + coef * k[stage, c]
        for c in range(6):
            y[c, 0] = y[c, 0] + sixth * (k[0, c] + 2.0 * (k[1, c] + k[2, c]) + k[3, c])
            ends[i, c] = y[c, 0]


@_jit
def _rhs_deputies(yd, u, p, rec, dy):
    """Right-hand side of the deputies' relative ECI states ``yd`` (6, M) under LVLH inputs ``u``
    (M, 3) at the chief's stage ``rec`` (a row of :func:`_chief_track`) into ``dy``
    (:func:`satenv.dynamics._soa.derivative_soa`)."""
    rc0, rc1, rc2, vc0, vc1, vc2 = rec[0], rec[1], rec[2], rec[3], rec[4], rec[5]
    ac0, ac1, ac2 = rec[6], rec[7], rec[8]
    for j in range(yd.shape[1]):
        a0, a1, a2 = _accel(rc0 + yd[0, j], rc1 + yd[1, j], rc2 + yd[2, j],
                            vc0 + yd[3, j], vc1 + yd[4, j], vc2 + yd[5, j], p, p[8])
        u0, u1, u2 = u[j, 0], u[j, 1], u[j, 2]
        dy[0, j], dy[1, j], dy[2, j] = yd[3, j], yd[4, j], yd[5, j]
        dy[3, j] = (a0 - ac0) + rec[9] * u0 + rec[12] * u1 + rec[15] * u2
        dy[4, j] = (a1 - ac1) + rec[10] * u0 + rec[13] * u1 + rec[16] * u2
        dy[5, j] = (a2 - ac2) + rec[11] * u0 + rec[14] * u1 + rec[17] * u2


@_jit
def _rk4_deputies(yd, u, h, p, track, i, k1, k2, k3, k4, tmp):
    """The deputies' RK4 sub-step ``i`` of the chief's track, in place (the same operations as
    :func:`satenv.dynamics.integrators.rk4_step` on their rows of the packed state)."""
    half = 0.5 * h
    m = yd.shape[1]
    _rhs_deputies(yd, u, p, track[4 * i], k1)
    for c in range(6):
        for j in range(m):
            tmp[c, j] = yd[c, j] + half * k1[c, j]
    _rhs_deputies(tmp, u, p, track[4 * i + 1], k2)
    for c in range(6):
        for j in range(m):
            tmp[c, j] = yd[c, j] + half * k2[c, j]
    _rhs_deputies(tmp, u, p, track[4 * i + 2], k3)
    for c in range(6):
        for j in range(m):
            tmp[c, j] = yd[c, j] + h * k3[c, j]
    _rhs_deputies(tmp, u, p, track[4 * i + 3], k4)
    sixth = h / 6.0
    for c in range(6):
        for j in range(m):
            yd[c, j] = yd[c, j] + sixth * (k1[c, j] + 2.0 * (k2[c, j] + k3[c, j]) + k4[c, j])


@_jit
def _new_chief(chief, b, last):
    """Whether copy ``b``'s chief differs from ``last`` (the previous copy's; then ``last`` takes
    it): copies with the same chief share its track."""
    same = True
    for c in range(6):
        same = same and chief[b, c] == last[c]
    if not same:
        for c in range(6):
            last[c] = chief[b, c]
    return not same


@_jit
def propagate(x, chief, u, substeps, h, p, x_out, chief_out, path):
    """Propagate LVLH states ``x`` (B, M, 6) and chief ECI states ``chief`` (B, 6) over
    ``u.shape[0]`` steps of ``substeps`` RK4 sub-steps of ``h`` seconds, the LVLH inputs ``u[s]``
    (B, M, 3) held over step ``s``; ``p`` from :func:`force_params`. Writes the final states into
    ``x_out`` / ``chief_out`` (may be ``x`` / ``chief``), and, when ``path.shape[0] > 0``, the
    LVLH positions after every step into ``path`` (S, B, M, 3). A copy whose chief equals the
    previous copy's reuses its track (copies stepped in lockstep share one)."""
    nb, m, n_steps = x.shape[0], x.shape[1], u.shape[0]
    n_sub = n_steps * substeps
    y = np.empty((6, 1 + m))
    k1, k2, k3 = np.empty((6, m)), np.empty((6, m)), np.empty((6, m))
    k4, tmp, yd = np.empty((6, m)), np.empty((6, m)), np.empty((6, m))
    e, yc = np.empty((3, 3)), np.empty((6, 1))
    track, ends = np.empty((4 * n_sub, TRACK)), np.empty((n_sub, 6))
    last = np.full(6, np.nan)
    recording = path.shape[0] > 0
    for b in range(nb):
        if _new_chief(chief, b, last):
            _chief_track(chief[b], n_sub, h, p, track, ends)
        _to_eci(x, b, chief, p, e, y)
        for c in range(6):
            for j in range(m):
                yd[c, j] = y[c, j + 1]
        for s in range(n_steps):
            us = u[s, b]
            for k in range(substeps):
                _rk4_deputies(yd, us, h, p, track, s * substeps + k, k1, k2, k3, k4, tmp)
            if recording:
                for c in range(6):
                    yc[c, 0] = ends[(s + 1) * substeps - 1, c]
                _axes(yc, e)
                for j in range(m):
                    for i in range(3):
                        path[s, b, j, i] = e[i, 0] * yd[0, j] + e[i, 1] * yd[1, j] + e[i, 2] * yd[2, j]
        for c in range(6):
            y[c, 0] = ends[n_sub - 1, c] if n_sub > 0 else chief[b, c]
            for j in range(m):
                y[c, j + 1] = yd[c, j]
        _to_lvlh(y, e, p, b, x_out, chief_out)
