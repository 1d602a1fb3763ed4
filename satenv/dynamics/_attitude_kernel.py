"""Compiled (numba) relative attitude step: :func:`satenv.dynamics.attitude.attitude_step` in
component arithmetic, one body at a time, no temporaries.

The numpy functions of :mod:`.attitude` are the reference (eq. 10, 13-16, RK4 then
renormalisation); this kernel evaluates the same equations, with ``J_f^-1`` applied as a
precomputed inverse instead of a linear solve (rounding only: ``tests/test_attitude_kernel.py``
checks 1e-12 agreement). Importing this module imports numba; compiled code is cached.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["attitude_steps", "quat_rotation"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def _mv(a, x0, x1, x2):
    return (a[0, 0] * x0 + a[0, 1] * x1 + a[0, 2] * x2,
            a[1, 0] * x0 + a[1, 1] * x1 + a[1, 2] * x2,
            a[2, 0] * x0 + a[2, 1] * x1 + a[2, 2] * x2)


@_jit
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@_jit
def quat_rotation(e, x1, x2, x3):
    """The entries ``r00, r01, ..., r22`` (row by row) of ``R(q) = I + 2 eta S(eps) + 2 S(eps)^2``
    (:func:`satenv.dynamics.attitude.quat_to_matrix`) of ``q = [e, x1, x2, x3]`` (any norm)."""
    xx, yy, zz = x1 * x1, x2 * x2, x3 * x3
    return (1.0 - 2.0 * (yy + zz), 2.0 * (x1 * x2 - e * x3), 2.0 * (x1 * x3 + e * x2),
            2.0 * (x1 * x2 + e * x3), 1.0 - 2.0 * (xx + zz), 2.0 * (x2 * x3 - e * x1),
            2.0 * (x1 * x3 - e * x2), 2.0 * (x2 * x3 + e * x1), 1.0 - 2.0 * (xx + yy))


@_jit
def _derivative(y, tq, j_f, j_f_inv, wl, lead_acc, dy):
    """``d/dt [q, omega]`` (eq. 10 and eq. 13-16 with a passive leader) of ``y`` (7,) into ``dy``."""
    e, x1, x2, x3 = y[0], y[1], y[2], y[3]
    w0, w1, w2 = y[4], y[5], y[6]
    c0, c1, c2 = _cross(x1, x2, x3, w0, w1, w2)
    dy[0] = -0.5 * (x1 * w0 + x2 * w1 + x3 * w2)
    dy[1] = 0.5 * (e * w0 + c0)
    dy[2] = 0.5 * (e * w1 + c1)
    dy[3] = 0.5 * (e * w2 + c2)
    # R^fb_lb = R(q)^T: rows of R^T are columns of R
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = quat_rotation(e, x1, x2, x3)
    # w_lf = R^T w_l; R^T lead_acc
    v0 = r00 * wl[0] + r10 * wl[1] + r20 * wl[2]
    v1 = r01 * wl[0] + r11 * wl[1] + r21 * wl[2]
    v2 = r02 * wl[0] + r12 * wl[1] + r22 * wl[2]
    g0 = r00 * lead_acc[0] + r10 * lead_acc[1] + r20 * lead_acc[2]
    g1 = r01 * lead_acc[0] + r11 * lead_acc[1] + r21 * lead_acc[2]
    g2 = r02 * lead_acc[0] + r12 * lead_acc[1] + r22 * lead_acc[2]
    # C_r omega = -J_f (w_lf x omega) - w_lf x (J_f omega) + (J_f (omega + w_lf)) x omega  (eq. 14)
    a0, a1, a2 = _cross(v0, v1, v2, w0, w1, w2)
    ja0, ja1, ja2 = _mv(j_f, a0, a1, a2)
    jw0, jw1, jw2 = _mv(j_f, w0, w1, w2)
    b0, b1, b2 = _cross(v0, v1, v2, jw0, jw1, jw2)
    js0, js1, js2 = _mv(j_f, w0 + v0, w1 + v1, w2 + v2)
    s0, s1, s2 = _cross(js0, js1, js2, w0, w1, w2)
    # E_r = -w_lf x (J_f w_lf) + J_f R^T lead_acc  (eq. 15)
    jv0, jv1, jv2 = _mv(j_f, v0, v1, v2)
    f0, f1, f2 = _cross(v0, v1, v2, jv0, jv1, jv2)
    jg0, jg1, jg2 = _mv(j_f, g0, g1, g2)
    t0 = -ja0 - b0 + s0 - f0 + jg0 + tq[0]
    t1 = -ja1 - b1 + s1 - f1 + jg1 + tq[1]
    t2 = -ja2 - b2 + s2 - f2 + jg2 + tq[2]
    dy[4], dy[5], dy[6] = _mv(j_f_inv, t0, t1, t2)


@_jit
def attitude_steps(q, w, torque, h, substeps, j_f, j_f_inv, wl, lead_acc, q_out, w_out):
    """``substeps`` RK4 steps of ``h`` (then renormalisation of q) of every body of ``q`` (N, 4),
    ``w`` (N, 3) under body torques ``torque`` (N, 3) into ``q_out``, ``w_out``; ``wl`` the
    leader's angular velocity (3,), ``lead_acc = J_l^-1 (w_l x J_l w_l)`` (3,)."""
    y, tmp = np.empty(7), np.empty(7)
    k1, k2, k3, k4 = np.empty(7), np.empty(7), np.empty(7), np.empty(7)
    half, sixth = 0.5 * h, h / 6.0
    for i in range(q.shape[0]):
        for c in range(4):
            y[c] = q[i, c]
        for c in range(3):
            y[4 + c] = w[i, c]
        tq = torque[i]
        for _ in range(substeps):
            _derivative(y, tq, j_f, j_f_inv, wl, lead_acc, k1)
            for c in range(7):
                tmp[c] = y[c] + half * k1[c]
            _derivative(tmp, tq, j_f, j_f_inv, wl, lead_acc, k2)
            for c in range(7):
                tmp[c] = y[c] + half * k2[c]
            _derivative(tmp, tq, j_f, j_f_inv, wl, lead_acc, k3)
            for c in range(7):
                tmp[c] = y[c] + h * k3[c]
            _derivative(tmp, tq, j_f, j_f_inv, wl, lead_acc, k4)
            for c in range(7):
                y[c] = y[c] + sixth * (k1[c] + 2.0 * (k2[c] + k3[c]) + k4[c])
            norm = np.sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2] + y[3] * y[3])
            if norm < 1e-12:
                norm = np.nan    # the reference raises; the caller checks for non-finite q
            for c in range(4):
                y[c] = y[c] / norm
        for c in range(4):
            q_out[i, c] = y[c]
        for c in range(3):
            w_out[i, c] = y[4 + c]
