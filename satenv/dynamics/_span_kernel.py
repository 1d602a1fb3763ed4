"""Compiled (numba) DOP853 propagation of the truth models: one eighth-order step spans several
input steps (:class:`satenv.dynamics.RelativeModel` with ``integrator="dop853"``).

The state and the ODE are those of :mod:`._truth_kernel` (the chief's absolute ECI state, the
deputies' ECI states relative to it, LVLH inputs held in the rotating frame over each input step
of ``hs`` seconds); the integration differs. With ``group`` input steps per DOP853 step (the
``span``, e.g. the 20 physics steps of 0.25 s in a 5 s cluster decision), the inputs form a
staircase inside the step, which a Runge-Kutta step cannot integrate at its order. So the
deputies' relative motion is split as ``r = z + w``:

* ``w(t) = int_0^t (t - tau) E(tau) delta(tau) dtau`` is the free motion under the input's
  deviation ``delta_s = u_s - u_0`` from the span's first input (``E`` the chief's LVLH axes, a
  cubic in time from their values and rates at the span's ends, ~1e-11 relative over 5 s of LEO);
  it is a double integral of a staircase times a polynomial, computed exactly from prefix sums;
* ``z`` obeys ``z'' = g(r_c + z + w) - g(r_c) + E u_0`` (drag: with ``v = z' + w'``), smooth over
  the span, which DOP853 integrates in one step (12 evaluations per body instead of 4 per input
  step for RK4: 80 for the cluster's 20 physics steps).

The LVLH positions after every input step inside the span (the cluster's separation checks) come
from the quintic Hermite interpolant of ``z`` (its value, rate and acceleration at both ends: one
more evaluation per body) plus ``w``, rotated by the axes' cubic; the position at the span's end
is the step's own. When one input step is longer than a span, it takes ``substeps`` DOP853 steps
with its constant input (``w = 0``).

``w`` depends on the deviations only: bodies with equal deviations share one table. An input
common to every body of a copy (``common``: the cluster's sinusoid disturbance, the same for
every satellite and, in lockstep, every copy) is passed apart from the bodies' own held inputs,
so that their deviations are equal bit for bit: one table per span for the whole batch. A
result never depends on which other copies share a call. The chief's track is shared by
consecutive copies with the same chief, as in :mod:`._truth_kernel`. Importing this module imports
numba; compiled code is cached next to it.
"""

from __future__ import annotations

import numba
import numpy as np

from ._dop853 import STAGES
from ._truth_kernel import _accel, _axes, _chief_record, _new_chief, _to_eci, _to_lvlh

__all__ = ["propagate"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


NODES = STAGES + 1
"""The chief's records per step: its twelve stages and the step's end."""
REC = 18
"""A chief record: state (6), acceleration (3), LVLH axes ex, ey, ez (9)."""


@_jit
def _omega(rec):
    """The LVLH frame's angular velocity in ECI from a chief record: ``omega_x ex + omega_z ez``
    (:func:`satenv.dynamics._soa.frame_rate_soa`)."""
    r0, r1, r2, v0, v1, v2 = rec[0], rec[1], rec[2], rec[3], rec[4], rec[5]
    h0, h1, h2 = r1 * v2 - r2 * v1, r2 * v0 - r0 * v2, r0 * v1 - r1 * v0
    rn = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    hn2 = h0 * h0 + h1 * h1 + h2 * h2
    wz = np.sqrt(hn2) / (rn * rn)
    wx = rn * (rec[6] * h0 + rec[7] * h1 + rec[8] * h2) / hn2
    return (wx * rec[9] + wz * rec[15], wx * rec[10] + wz * rec[16], wx * rec[11] + wz * rec[17])


@_jit
def _chief_step(c0, H, p, a_tab, b_tab, c_tab, rec, ecoef):
    """One DOP853 step of ``H`` seconds of the chief from ``c0`` (6,): its stages' and its end's
    records into ``rec`` (13, 18), and the cubic ``E(tau) = sum_k ecoef[k] tau^k`` (4, 3, 3) of its
    axes over the step (Hermite: the axes and their rates ``omega x e`` at both ends)."""
    k = np.empty((STAGES, 6))
    y = np.empty((6, 1))
    e = np.empty((3, 3))
    for i in range(NODES):
        for c in range(6):
            acc = 0.0
            if i < STAGES:
                for j in range(i):
                    acc += a_tab[i, j] * k[j, c]
            else:
                for j in range(STAGES):
                    acc += b_tab[j] * k[j, c]
            y[c, 0] = c0[c] + H * acc
        a0, a1, a2 = _chief_record(y, e, p, rec[i])
        if i < STAGES:
            k[i, 0], k[i, 1], k[i, 2] = y[3, 0], y[4, 0], y[5, 0]
            k[i, 3], k[i, 4], k[i, 5] = a0, a1, a2
    w0 = _omega(rec[0])
    w1 = _omega(rec[STAGES])
    for row in range(3):
        for c in range(3):
            e0, e1 = rec[0, 9 + 3 * row + c], rec[STAGES, 9 + 3 * row + c]
            # (omega x e_row)_c
            c1, c2 = (c + 1) % 3, (c + 2) % 3
            d0 = w0[c1] * rec[0, 9 + 3 * row + c2] - w0[c2] * rec[0, 9 + 3 * row + c1]
            d1 = w1[c1] * rec[STAGES, 9 + 3 * row + c2] - w1[c2] * rec[STAGES, 9 + 3 * row + c1]
            ecoef[0, row, c] = e0
            ecoef[1, row, c] = d0
            ecoef[2, row, c] = (3.0 * (e1 - e0) / H - 2.0 * d0 - d1) / H
            ecoef[3, row, c] = (2.0 * (e0 - e1) / H + d0 + d1) / (H * H)


@_jit
def _tables(n, hi, c_tab, mom, ev_s, ev_t, ev_part, ev_partd, herm, hermd):
    """The scalar factors of a step of ``n`` input intervals of ``hi`` seconds: the interval
    moments ``mom[s, k] = int tau^k`` (n, 5); per evaluation time ``ev_t`` (the 12 stage nodes,
    then the ``n`` interval ends) its interval ``ev_s``, ``int_{tau_s}^t (t - tau) tau^k`` and
    ``int_{tau_s}^t tau^k`` (k < 4) over its part of that interval; the quintic Hermite weights
    ``herm`` (n, 6) of the interior interval ends (of the values, rates and accelerations at the
    step's start, then at its end) and ``hermd`` (n, 6) of the interpolant's rate there."""
    H = n * hi
    for s in range(n):
        a, b = s * hi, (s + 1) * hi
        for k in range(5):
            mom[s, k] = (b ** (k + 1) - a ** (k + 1)) / (k + 1)
    for ev in range(STAGES + n):
        t = c_tab[ev] * H if ev < STAGES else (ev - STAGES + 1) * hi
        s = min(int(t / hi), n - 1)
        a = s * hi
        ev_s[ev] = s
        ev_t[ev] = t
        for k in range(4):
            ev_partd[ev, k] = (t ** (k + 1) - a ** (k + 1)) / (k + 1)
            ev_part[ev, k] = t * ev_partd[ev, k] - (t ** (k + 2) - a ** (k + 2)) / (k + 2)
    for q in range(n - 1):
        th = (q + 1) / n
        t2, t3 = th * th, th * th * th
        t4, t5 = t3 * th, t3 * t2
        herm[q, 0] = 1.0 - 10.0 * t3 + 15.0 * t4 - 6.0 * t5
        herm[q, 1] = (th - 6.0 * t3 + 8.0 * t4 - 3.0 * t5) * H
        herm[q, 2] = 0.5 * (t2 - 3.0 * t3 + 3.0 * t4 - t5) * H * H
        herm[q, 3] = 10.0 * t3 - 15.0 * t4 + 6.0 * t5
        herm[q, 4] = (-4.0 * t3 + 7.0 * t4 - 3.0 * t5) * H
        herm[q, 5] = 0.5 * (t3 - 2.0 * t4 + t5) * H * H
        hermd[q, 0] = (-30.0 * t2 + 60.0 * t3 - 30.0 * t4) / H
        hermd[q, 1] = 1.0 - 18.0 * t2 + 32.0 * t3 - 15.0 * t4
        hermd[q, 2] = (th - 4.5 * t2 + 6.0 * t3 - 2.5 * t4) * H
        hermd[q, 3] = (30.0 * t2 - 60.0 * t3 + 30.0 * t4) / H
        hermd[q, 4] = -12.0 * t2 + 28.0 * t3 - 15.0 * t4
        hermd[q, 5] = (1.5 * t2 - 4.0 * t3 + 2.5 * t4) * H


@_jit
def _z_accel(rec, yy, w, moving, u0, u1, u2, p):
    """``z''`` of one body (module docstring) at the chief's record ``rec`` (a stage or the end):
    its stage state ``yy`` (z, z') plus ``w, w'`` (``w``, when ``moving``), the LVLH input
    ``u0, u1, u2`` rotated by the record's axes (:func:`._truth_kernel._rhs_deputies`)."""
    q0, q1, q2, p0, p1, p2 = yy[0], yy[1], yy[2], yy[3], yy[4], yy[5]
    if moving:
        q0, q1, q2 = q0 + w[0], q1 + w[1], q2 + w[2]
        p0, p1, p2 = p0 + w[3], p1 + w[4], p2 + w[5]
    a0, a1, a2 = _accel(rec[0] + q0, rec[1] + q1, rec[2] + q2, rec[3] + p0, rec[4] + p1, rec[5] + p2,
                        p, p[8])
    return ((a0 - rec[6]) + rec[9] * u0 + rec[12] * u1 + rec[15] * u2,
            (a1 - rec[7]) + rec[10] * u0 + rec[13] * u1 + rec[16] * u2,
            (a2 - rec[8]) + rec[11] * u0 + rec[14] * u1 + rec[17] * u2)


@_jit
def _interior_axes(rec, n, herm, hermd, eq):
    """The LVLH axes at the ``n - 1`` interior interval ends of a chief step into ``eq`` (n, 3, 3):
    exact axes of the chief's quintic Hermite state (position, velocity from the step's start and
    end records; ~1e-12 m on the chief over 5 s of LEO)."""
    y = np.empty((6, 1))
    e = np.empty((3, 3))
    end = rec[STAGES]
    for q in range(n - 1):
        for c in range(3):
            ends = (rec[0, c], rec[0, 3 + c], rec[0, 6 + c], end[c], end[3 + c], end[6 + c])
            y[c, 0] = 0.0
            y[3 + c, 0] = 0.0
            for i in range(6):
                y[c, 0] += herm[q, i] * ends[i]
                y[3 + c, 0] += hermd[q, i] * ends[i]
        _axes(y, e)
        for row in range(3):
            for c in range(3):
                eq[q, row, c] = e[row, c]


@_jit
def _w_table(delta, n, mom, ev_s, ev_t, ev_part, ev_partd, ecoef, wtab):
    """``w`` and ``w'`` (6,) at every evaluation time into ``wtab`` (12 + n, 6) for the deviations
    ``delta`` (n, 3) (module docstring)."""
    pre = np.zeros((n + 1, 5, 3))
    for s in range(n):
        for k in range(5):
            for c in range(3):
                pre[s + 1, k, c] = pre[s, k, c] + delta[s, c] * mom[s, k]
    d = np.empty((4, 3))
    dd = np.empty((4, 3))
    for ev in range(STAGES + n):
        s, t = ev_s[ev], ev_t[ev]
        for k in range(4):
            for j in range(3):
                dd[k, j] = pre[s, k, j] + delta[s, j] * ev_partd[ev, k]
        for k in range(4):
            for j in range(3):
                d[k, j] = t * pre[s, k, j] - pre[s, k + 1, j] + delta[s, j] * ev_part[ev, k]
        for c in range(3):
            wp = 0.0
            wv = 0.0
            for k in range(4):
                for j in range(3):
                    wp += ecoef[k, j, c] * d[k, j]
                    wv += ecoef[k, j, c] * dd[k, j]
            wtab[ev, c] = wp
            wtab[ev, 3 + c] = wv


@_jit
def propagate(x, chief, u, common, n_steps, group, substeps, hs, p, a_tab, b_tab, c_tab, x_out,
              chief_out, path):
    """Propagate LVLH states ``x`` (B, M, 6) and chief ECI states ``chief`` (B, 6) over
    ``n_steps`` input steps of ``hs`` seconds, the LVLH input of body ``j`` over step ``s``
    ``u[s, :, j] + common[s]`` (``u`` (S or 1, B, M, 3): one row is held over every step;
    ``common`` (S, B, 3), or (0, B, 3) for none), with
    one DOP853 step per ``group`` input steps (``substeps == 1``) or ``substeps`` DOP853 steps
    per input step (``group == 1``); ``p`` from :func:`._truth_kernel.force_params`, ``a_tab``,
    ``b_tab``, ``c_tab`` the tableau (:mod:`._dop853`). Writes the final states into ``x_out`` /
    ``chief_out`` (may be ``x`` / ``chief``) and, when ``path.shape[0] > 0``, the LVLH positions
    after every input step into ``path`` (S, B, M, 3)."""
    nb, m = x.shape[0], x.shape[1]
    held = u.shape[0] == 1
    has_common = common.shape[0] > 0
    if substeps > 1:
        n_spans, nmax, hi = n_steps * substeps, 1, hs / substeps
    else:
        n_spans, nmax, hi = (n_steps + group - 1) // group, max(1, min(group, n_steps)), hs
    n_last = n_steps - (n_spans - 1) * group if (substeps == 1 and n_spans > 0) else nmax
    # scalar tables: [0] for full spans of nmax intervals, [1] for a shorter last one
    mom = np.zeros((2, nmax, 5))
    ev_s = np.zeros((2, STAGES + nmax), np.int64)
    ev_t = np.zeros((2, STAGES + nmax))
    ev_part, ev_partd = np.zeros((2, STAGES + nmax, 4)), np.zeros((2, STAGES + nmax, 4))
    herm, hermd = np.zeros((2, nmax, 6)), np.zeros((2, nmax, 6))
    _tables(nmax, hi, c_tab, mom[0], ev_s[0], ev_t[0], ev_part[0], ev_partd[0], herm[0], hermd[0])
    _tables(n_last, hi, c_tab, mom[1], ev_s[1], ev_t[1], ev_part[1], ev_partd[1], herm[1], hermd[1])
    rec = np.empty((n_spans, NODES, REC))
    ecoef = np.empty((n_spans, 4, 3, 3))
    eq = np.empty((n_spans, nmax, 3, 3))          # axes at the interval ends
    wtab = np.empty((n_spans, STAGES + nmax, 6))
    wdel = np.empty((n_spans, nmax, 3))
    wok = np.zeros(n_spans, np.bool_)
    y = np.empty((6, 1 + m))
    yd = np.empty((6, m))
    e = np.empty((3, 3))
    kk = np.empty((STAGES, 6))
    yy = np.empty(6)
    delta = np.empty((nmax, 3))
    last = np.full(6, np.nan)
    recording = path.shape[0] > 0
    for b in range(nb):
        if _new_chief(chief, b, last):
            for sp in range(n_spans):
                n = n_last if sp == n_spans - 1 else nmax
                c0 = chief[b] if sp == 0 else rec[sp - 1, STAGES, :6]
                _chief_step(c0, n * hi, p, a_tab, b_tab, c_tab, rec[sp], ecoef[sp])
                _interior_axes(rec[sp], n, herm[0 if n == nmax else 1], hermd[0 if n == nmax else 1],
                               eq[sp])
                for row in range(3):
                    for c in range(3):
                        eq[sp, n - 1, row, c] = rec[sp, STAGES, 9 + 3 * row + c]
            wok[:] = False
        _to_eci(x, b, chief, p, e, y)
        for c in range(6):
            for j in range(m):
                yd[c, j] = y[c, j + 1]
        for sp in range(n_spans):
            full = 0 if (sp < n_spans - 1 or n_last == nmax) else 1
            n = nmax if full == 0 else n_last
            H = n * hi
            s0 = sp // substeps if substeps > 1 else sp * group
            ends_step = substeps == 1 or sp % substeps == substeps - 1
            r = rec[sp]
            for j in range(m):
                ui = 0 if held else s0
                u0, u1, u2 = u[ui, b, j, 0], u[ui, b, j, 1], u[ui, b, j, 2]
                if has_common:
                    u0, u1, u2 = u0 + common[s0, b, 0], u1 + common[s0, b, 1], u2 + common[s0, b, 2]
                moving = False
                for s in range(n):
                    for c in range(3):
                        dev = 0.0
                        if substeps == 1 and s > 0:
                            if not held:
                                dev = u[s0 + s, b, j, c] - u[s0, b, j, c]
                            if has_common:
                                dev = dev + (common[s0 + s, b, c] - common[s0, b, c])
                        delta[s, c] = dev
                        moving = moving or dev != 0.0
                if moving:
                    same = wok[sp]
                    if same:
                        for s in range(n):
                            for c in range(3):
                                same = same and delta[s, c] == wdel[sp, s, c]
                    if not same:
                        _w_table(delta, n, mom[full], ev_s[full], ev_t[full], ev_part[full],
                                 ev_partd[full], ecoef[sp], wtab[sp])
                        for s in range(n):
                            for c in range(3):
                                wdel[sp, s, c] = delta[s, c]
                        wok[sp] = True
                w = wtab[sp]
                for i in range(STAGES):
                    for c in range(6):
                        acc = 0.0
                        for l in range(i):
                            acc += a_tab[i, l] * kk[l, c]
                        yy[c] = yd[c, j] + H * acc
                    kk[i, 0], kk[i, 1], kk[i, 2] = yy[3], yy[4], yy[5]
                    kk[i, 3], kk[i, 4], kk[i, 5] = _z_accel(r[i], yy, w[i], moving, u0, u1, u2, p)
                for c in range(6):
                    acc = 0.0
                    for l in range(STAGES):
                        acc += b_tab[l] * kk[l, c]
                    yy[c] = yd[c, j] + H * acc          # z, z' at the end
                endw = STAGES + n - 1
                if recording and n > 1:
                    # the acceleration of z at the end, for the Hermite interpolant
                    e0, e1, e2 = _z_accel(r[STAGES], yy, w[endw], moving, u0, u1, u2, p)
                    hw = herm[full]
                    for q in range(n - 1):
                        h0, h1, h2, h3, h4, h5 = hw[q, 0], hw[q, 1], hw[q, 2], hw[q, 3], hw[q, 4], hw[q, 5]
                        z0 = (h0 * yd[0, j] + h1 * yd[3, j] + h2 * kk[0, 3]
                              + h3 * yy[0] + h4 * yy[3] + h5 * e0)
                        z1 = (h0 * yd[1, j] + h1 * yd[4, j] + h2 * kk[0, 4]
                              + h3 * yy[1] + h4 * yy[4] + h5 * e1)
                        z2 = (h0 * yd[2, j] + h1 * yd[5, j] + h2 * kk[0, 5]
                              + h3 * yy[2] + h4 * yy[5] + h5 * e2)
                        if moving:
                            z0, z1, z2 = z0 + w[STAGES + q, 0], z1 + w[STAGES + q, 1], z2 + w[STAGES + q, 2]
                        for row in range(3):
                            path[s0 + q, b, j, row] = (eq[sp, q, row, 0] * z0 + eq[sp, q, row, 1] * z1
                                                       + eq[sp, q, row, 2] * z2)
                for c in range(6):
                    yd[c, j] = yy[c] + (w[endw, c] if moving else 0.0)
                if recording and ends_step:
                    for row in range(3):
                        path[s0 + n - 1, b, j, row] = (eq[sp, n - 1, row, 0] * yd[0, j]
                                                       + eq[sp, n - 1, row, 1] * yd[1, j]
                                                       + eq[sp, n - 1, row, 2] * yd[2, j])
        for c in range(6):
            y[c, 0] = rec[n_spans - 1, STAGES, c] if n_spans > 0 else chief[b, c]
            for j in range(m):
                y[c, j + 1] = yd[c, j]
        _to_lvlh(y, e, p, b, x_out, chief_out)
