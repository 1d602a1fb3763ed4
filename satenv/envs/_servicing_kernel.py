"""Compiled (numba) kernels of the servicing core: the attitude reference (eq. 43-49) and the whole step.

:func:`attitude_features`: :func:`satenv.envs.servicing_v0.attitude_reference` with the numpy
functions of :mod:`satenv.dynamics.attitude` (``pointing_frame``, ``matrix_to_quat``,
``pointing_rate``, ``desired_angular_velocity``), then ``quat_error`` and ``pointing_error``, is
the reference; this kernel evaluates the same formulas in component arithmetic, one spacecraft at
a time (``tests/test_servicing_kernel.py``: 1e-12).

:func:`step`: one decision (LVLH thrust) in one call, the substeps by the compiled truth and
attitude kernels, then the reference above, the infos, eq. 39's reward, the terminations and the
observation, with the numpy glue's operations in its order (the same numbers bit for bit,
``tests/test_servicing_kernel.py``). Importing this module imports numba.
"""

from __future__ import annotations

import numba
import numpy as np

from satenv.dynamics._attitude_kernel import attitude_steps, quat_rotation
from satenv.dynamics._truth_kernel import propagate as truth_propagate

__all__ = ["attitude_features", "step"]


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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _minimum(a, b):
    """``np.minimum`` of two floats (a NaN propagates)."""
    if a != a or b != b:
        return np.nan
    return a if a <= b else b


@numba.njit(cache=True, nogil=True, error_model="numpy")
def step(x, chief, force, torque, u, t, tp, att, j_f, j_f_inv, wl, lead_acc, target, reference, task, weights,
         waypoints, switch, x_out, chief_out, state, accel, dv, e_p, min_sep, collision, viol, cost, waypoint,
         phase, d_obj, d_other, pointing, eta, q_err, e_w, e_v, q_d, w_d, dist, rewards, terminated, finite, obs):
    """One decision of :meth:`satenv.envs.servicing_v0.ServicingCore.step` (LVLH thrust) in one pass.

    Inputs: states ``x`` (B, M, 13), chief ECI states ``chief`` (B, 6), the step's LVLH force,
    body torque and saturated inputs ``force``, ``torque`` (B, M, 3), ``u`` (B, M, 6) (numpy's
    products, as the reference), the step counts after the step ``t`` (B,); ``tp`` the force
    constants of the truth kernel (:func:`satenv.dynamics._truth_kernel.propagate`, RK4); ``att``
    ``(substeps, h, the truth model's substeps and sub-step, n, min_sine)``; ``j_f``, ``j_f_inv``,
    ``wl``, ``lead_acc`` the attitude constants (:func:`satenv.dynamics.attitude.attitude_constants`);
    ``target``, ``reference`` (3,) the pointing target and roll reference; ``task`` (14,)
    ``desired_velocity (3), keepout - tolerance, separation - tolerance, v_max, omega_max,
    max_distance, terminate_on_collision, reward_scale, collision_penalty, violation_penalty, dt,
    scale_p``; ``weights`` (19,) the stage cost's position (3), velocity (3), quaternion (4),
    omega (3) and input (6) weights;
    ``waypoints`` (P, M, 3), ``switch`` (P - 1,) the phase-switch steps.

    Writes the new states and chiefs, the info arrays (``eta`` the clipped ``q_err[..., 0]``
    whose arccos the caller takes), the features (``e_v``, ``q_d``, ``w_d``, ``dist``), rewards,
    terminations, which copies are all finite (states, rewards and, when ``obs`` has rows, the
    observations) and the float32 observations (when ``obs.shape[0] > 0``). The reference's
    formulas in its order of operations (the same numbers). Returns 0, 1 when the attitude step
    reached a zero-norm quaternion from finite inputs (nothing written but scratch) or 2 when a
    spacecraft sits on the pointing target (everything written; the caller raises)."""
    nb, m = x.shape[0], x.shape[1]
    n_sub, h, model_sub, model_h = int(att[0]), att[1], int(att[2]), att[3]
    x6 = np.empty((nb, m, 6))
    us = np.empty((1, nb, m, 3))
    path = np.empty((0, nb, m, 3))
    q = np.empty((nb * m, 4))
    w = np.empty((nb * m, 3))
    tq = np.empty((nb * m, 3))
    q_next = np.empty((nb * m, 4))
    w_next = np.empty((nb * m, 3))
    inputs_finite = True
    for b in range(nb):
        for c in range(6):
            chief_out[b, c] = chief[b, c]
        for i in range(m):
            r = b * m + i
            for c in range(6):
                x6[b, i, c] = x[b, i, c]
            for c in range(4):
                q[r, c] = x[b, i, 6 + c]
            for c in range(3):
                w[r, c] = x[b, i, 10 + c]
                tq[r, c] = torque[b, i, c]
                us[0, b, i, c] = force[b, i, c]
                accel[b, i, c] = 0.0
                inputs_finite = inputs_finite and np.isfinite(tq[r, c])
    for _ in range(n_sub):
        for b in range(nb):
            for i in range(m):
                for c in range(3):
                    accel[b, i, c] += force[b, i, c]
        truth_propagate(x6, chief_out, us, model_sub, model_h, tp, x6, chief_out, path)
        finite_in = inputs_finite
        for r in range(nb * m):
            for c in range(4):
                finite_in = finite_in and np.isfinite(q[r, c])
            for c in range(3):
                finite_in = finite_in and np.isfinite(w[r, c])
        attitude_steps(q, w, tq, h, 1, j_f, j_f_inv, wl, lead_acc, q_next, w_next)
        if finite_in:
            for r in range(nb * m):
                for c in range(4):
                    if np.isnan(q_next[r, c]):
                        return 1
        q, q_next = q_next, q
        w, w_next = w_next, w
    for b in range(nb):
        for i in range(m):
            r = b * m + i
            for c in range(6):
                x_out[b, i, c] = x6[b, i, c]
            for c in range(4):
                x_out[b, i, 6 + c] = q[r, c]
            for c in range(3):
                x_out[b, i, 10 + c] = w[r, c]
                accel[b, i, c] = accel[b, i, c] / n_sub
            for c in range(13):
                state[b, i, c] = x_out[b, i, c]
    bad = attitude_features(x_out, target, reference, att[4], att[5], q_d, w_d, q_err, pointing)
    keepout_r, sep_r, v_max, omega_max = task[3], task[4], task[5], task[6]
    max_distance, stop_on_collision = task[7], task[8] != 0.0
    reward_scale, collision_penalty, violation_penalty, dt, scale_p = task[9], task[10], task[11], task[12], task[13]
    observe = obs.shape[0] > 0
    for b in range(nb):
        k = 0
        for s in range(switch.shape[0]):
            if t[b] > switch[s]:
                k += 1
        ended = False
        collided = False
        ok = True
        for i in range(m):
            xi = x_out[b, i]
            p0, p1, p2 = xi[0], xi[1], xi[2]
            phase[b, i] = k
            for c in range(3):
                waypoint[b, i, c] = waypoints[k, i, c]
                e_p[b, i, c] = xi[c] - waypoints[k, i, c]
                e_v[b, i, c] = xi[3 + c] - task[c]
                e_w[b, i, c] = xi[10 + c] - w_d[b, i, c]
            d = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            d_obj[b, i] = d
            nearest = np.inf
            pairs = 0
            for j in range(m):
                if j == i:
                    dij = np.inf
                else:
                    d0, d1, d2 = p0 - x_out[b, j, 0], p1 - x_out[b, j, 1], p2 - x_out[b, j, 2]
                    dij = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                dist[b, i, j] = dij
                nearest = _minimum(nearest, dij)
                if dij < sep_r:
                    pairs += 1
            d_other[b, i] = nearest
            min_sep[b, i] = _minimum(d, nearest)
            keepout = d < keepout_r
            hit = keepout or pairs > 0
            collision[b, i] = hit
            n_viol = (1 if keepout else 0) + pairs
            for c in range(3):
                if abs(xi[3 + c]) > v_max:
                    n_viol += 1
            for c in range(3):
                if abs(xi[10 + c]) > omega_max:
                    n_viol += 1
            viol[b, i] = n_viol
            cost[b, i] = float(n_viol)
            a0, a1, a2 = accel[b, i, 0], accel[b, i, 1], accel[b, i, 2]
            dv[b, i] = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2) * dt
            eta[b, i] = min(max(q_err[b, i, 0], -1.0), 1.0) if q_err[b, i, 0] == q_err[b, i, 0] else np.nan
            # eq. 39's stage cost: each term summed over its axes, the terms in order
            s_p = weights[0] * (e_p[b, i, 0] * e_p[b, i, 0])
            for c in range(1, 3):
                s_p = s_p + weights[c] * (e_p[b, i, c] * e_p[b, i, c])
            s_v = weights[3] * (e_v[b, i, 0] * e_v[b, i, 0])
            for c in range(1, 3):
                s_v = s_v + weights[3 + c] * (e_v[b, i, c] * e_v[b, i, c])
            qe0 = 1.0 - q_err[b, i, 0]
            s_q = weights[6] * (qe0 * qe0)
            for c in range(1, 4):
                s_q = s_q + weights[6 + c] * (q_err[b, i, c] * q_err[b, i, c])
            s_w = weights[10] * (e_w[b, i, 0] * e_w[b, i, 0])
            for c in range(1, 3):
                s_w = s_w + weights[10 + c] * (e_w[b, i, c] * e_w[b, i, c])
            s_u = weights[13] * (u[b, i, 0] * u[b, i, 0])
            for c in range(1, 6):
                s_u = s_u + weights[13 + c] * (u[b, i, c] * u[b, i, c])
            stage = (((s_p + s_v) + s_q) + s_w) + s_u
            rw = (-stage / reward_scale - collision_penalty * (1.0 if hit else 0.0)) - violation_penalty * float(n_viol)
            rewards[b, i] = rw
            ended = ended or d > max_distance
            collided = collided or hit
            ok = ok and np.isfinite(rw)
            for c in range(13):
                ok = ok and np.isfinite(xi[c])
            if observe:
                o = obs[b, i]
                for c in range(3):
                    o[c] = e_p[b, i, c] / scale_p
                    o[3 + c] = e_v[b, i, c] / v_max
                    o[10 + c] = e_w[b, i, c] / omega_max
                    o[13 + c] = xi[c] / scale_p
                for c in range(4):
                    o[6 + c] = q_err[b, i, c]
                col = 16
                for j in range(m):
                    if j == i:
                        continue
                    for c in range(3):
                        o[col + c] = (x_out[b, j, c] - xi[c]) / scale_p
                        o[col + 3 + c] = (x_out[b, j, 3 + c] - xi[3 + c]) / v_max
                    col += 6
                for c in range(o.shape[0]):
                    ok = ok and np.isfinite(o[c])
        terminated[b] = ended or (stop_on_collision and collided)
        finite[b] = ok
    return 2 if bad else 0
