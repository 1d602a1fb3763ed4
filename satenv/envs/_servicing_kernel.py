"""Compiled (numba) attitude reference of the servicing core: eq. 43-49 per spacecraft.

:func:`satenv.envs.servicing_v0.attitude_reference` with the numpy functions of
:mod:`satenv.dynamics.attitude` (``pointing_frame``, ``matrix_to_quat``, ``pointing_rate``,
``desired_angular_velocity``), then ``quat_error`` and ``pointing_error``, is the reference; this
kernel evaluates the same formulas in component arithmetic, one spacecraft at a time
(``tests/test_servicing_kernel.py``: 1e-12). Importing this module imports numba.
"""

from __future__ import annotations

import numba
import numpy as np

from satenv.dynamics._attitude_kernel import quat_rotation

__all__ = ["attitude_features"]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def attitude_features(x, target, reference, n, min_sine, q_d, w_d, q_err, pointing):
    """For states ``x`` (B, M, 13) ``[p, v, q, omega]``: the desired quaternion ``q_d`` (sign-aligned
    with q), the desired relative rate ``w_d``, the quaternion error ``q_err`` (eta >= 0) and the
    boresight pointing error [rad], into the (B, M, ...) outputs; ``target``, ``reference`` (3,)
    the pointing target and roll reference, ``n`` the mean motion. Returns the number of
    spacecraft at the target point (undefined pointing; the caller raises)."""
    bad = 0
    eye_pick = np.empty(3)
    for b in range(x.shape[0]):
        for i in range(x.shape[1]):
            p0, p1, p2 = x[b, i, 0], x[b, i, 1], x[b, i, 2]
            e, q1, q2, q3 = x[b, i, 6], x[b, i, 7], x[b, i, 8], x[b, i, 9]
            # pointing_frame (eq. 43-44): k to the target, j = k x a / |k x a|, i = j x k
            t0, t1, t2 = target[0] - p0, target[1] - p1, target[2] - p2
            dist = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            if dist < 1e-9:
                bad += 1
            dn = max(dist, 1e-300)
            k0, k1, k2 = t0 / dn, t1 / dn, t2 / dn
            a0, a1, a2 = reference[0], reference[1], reference[2]
            c0, c1, c2 = k1 * a2 - k2 * a1, k2 * a0 - k0 * a2, k0 * a1 - k1 * a0
            cn = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2) / max(np.sqrt(a0 * a0 + a1 * a1 + a2 * a2), 1e-300)
            if cn < min_sine:
                ak0, ak1, ak2 = abs(k0), abs(k1), abs(k2)
                eye_pick[:] = 0.0
                if ak0 <= ak1 and ak0 <= ak2:
                    eye_pick[0] = 1.0
                elif ak1 <= ak2:
                    eye_pick[1] = 1.0
                else:
                    eye_pick[2] = 1.0
                a0, a1, a2 = eye_pick[0], eye_pick[1], eye_pick[2]
                c0, c1, c2 = k1 * a2 - k2 * a1, k2 * a0 - k0 * a2, k0 * a1 - k1 * a0
            cm = max(np.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-300)
            j0, j1, j2 = c0 / cm, c1 / cm, c2 / cm
            i0, i1, i2 = j1 * k2 - j2 * k1, j2 * k0 - j0 * k2, j0 * k1 - j1 * k0
            # matrix_to_quat of R_d = [i j k] (columns), Shepperd's method
            r00, r01, r02 = i0, j0, k0
            r10, r11, r12 = i1, j1, k1
            r20, r21, r22 = i2, j2, k2
            tr = r00 + r11 + r22
            r21m, r02m, r10m = r21 - r12, r02 - r20, r10 - r01
            r21p, r02p, r10p = r21 + r12, r02 + r20, r10 + r01
            best = 0
            top = tr
            if r00 > top:
                best, top = 1, r00
            if r11 > top:
                best, top = 2, r11
            if r22 > top:
                best = 3
            if best == 0:
                s = 2.0 * np.sqrt(max(1.0 + tr, 0.0))
                d0, d1, d2, d3 = s / 4, r21m / s, r02m / s, r10m / s
            elif best == 1:
                s = 2.0 * np.sqrt(max(1.0 + 2 * r00 - tr, 0.0))
                d0, d1, d2, d3 = r21m / s, s / 4, r10p / s, r02p / s
            elif best == 2:
                s = 2.0 * np.sqrt(max(1.0 + 2 * r11 - tr, 0.0))
                d0, d1, d2, d3 = r02m / s, r10p / s, s / 4, r21p / s
            else:
                s = 2.0 * np.sqrt(max(1.0 + 2 * r22 - tr, 0.0))
                d0, d1, d2, d3 = r10m / s, r02p / s, r21p / s, s / 4
            sg = -1.0 if d0 < 0 else 1.0
            d0, d1, d2, d3 = d0 * sg, d1 * sg, d2 * sg, d3 * sg
            qn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3)
            d0, d1, d2, d3 = d0 / qn, d1 / qn, d2 / qn, d3 / qn
            sg = -1.0 if d0 * e + d1 * q1 + d2 * q2 + d3 * q3 < 0 else 1.0
            d0, d1, d2, d3 = d0 * sg, d1 * sg, d2 * sg, d3 * sg
            q_d[b, i, 0], q_d[b, i, 1], q_d[b, i, 2], q_d[b, i, 3] = d0, d1, d2, d3
            # pointing_rate (eq. 45-47), target at rest: t_dot = -v
            v0, v1, v2 = -x[b, i, 3], -x[b, i, 4], -x[b, i, 5]
            wf0 = -(v0 * j0 + v1 * j1 + v2 * j2) / dist
            wf1 = (v0 * i0 + v1 * i1 + v2 * i2) / dist
            # desired_angular_velocity (eq. 49): R(q)^T ([0, 0, n] + R_d w_f - [0, 0, n])
            g0 = (0.0 + (r00 * wf0 + r01 * wf1)) - 0.0
            g1 = (0.0 + (r10 * wf0 + r11 * wf1)) - 0.0
            g2 = (n + (r20 * wf0 + r21 * wf1)) - n
            m00, m01, m02, m10, m11, m12, m20, m21, m22 = quat_rotation(e, q1, q2, q3)
            w_d[b, i, 0] = m00 * g0 + m10 * g1 + m20 * g2
            w_d[b, i, 1] = m01 * g0 + m11 * g1 + m21 * g2
            w_d[b, i, 2] = m02 * g0 + m12 * g1 + m22 * g2
            # quat_error: q (x) conj(q_d), eta >= 0
            ee = e * d0 + (q1 * d1 + q2 * d2 + q3 * d3)
            x0 = -e * d1 + d0 * q1 + (-(q2 * d3) + q3 * d2)
            x1 = -e * d2 + d0 * q2 + (-(q3 * d1) + q1 * d3)
            x2 = -e * d3 + d0 * q3 + (-(q1 * d2) + q2 * d1)
            sg = -1.0 if ee < 0 else 1.0
            q_err[b, i, 0], q_err[b, i, 1], q_err[b, i, 2], q_err[b, i, 3] = ee * sg, x0 * sg, x1 * sg, x2 * sg
            # pointing_error: boresight (body z, third column of R(q)) vs the line of sight
            cosang = m02 * k0 + m12 * k1 + m22 * k2
            pointing[b, i] = np.arccos(min(max(cosang, -1.0), 1.0))
    return bad
