"""Compiled (numba) kernel of the platoon core: every per-step quantity in one pass.

:class:`satenv.envs.platoon_v0.PlatoonCore` evaluates a step with numpy (``method="dense"``
or ``"sparse"``, the reference) or, when numba is installed, with :func:`evaluate`
(``method="kernel"``): the info arrays, rewards, terminations and observations of a batch of
states in one loop over copies and followers, so a step costs a few microseconds at one copy and
no temporaries at thousands. It computes the reference's formulas (neighbourhood errors by
neighbour gathers, separations from the position differences, the observation of the
``sparse`` path), so both agree to rounding (``tests/test_platoon_kernel.py``). Importing this
module imports numba (``ImportError`` without it); compiled code is cached next to the module.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["SWEEP_MIN", "cw_step", "evaluate"]

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _errors(x, b, f, gains, nbr, nbr_mask, out):
    """Neighbourhood error ``E_f`` (pereira2023 eq. 9) of copy ``b`` into ``out`` (6,)."""
    for c in range(6):
        s = 0.0
        for k in range(nbr.shape[1]):
            s += x[b, nbr[f, k], c] * nbr_mask[f, k]
        out[c] = x[b, f, c] * gains[f] - s


@_jit
def evaluate(x, accel, table, nbr, params, out, t, offset, slot_src, obs):
    """Info arrays, rewards and terminations of states ``x`` (B, N, 6) under ``accel`` (B, N, 3),
    and, unless ``obs`` is empty, their observations at steps ``t`` (B,) into ``obs`` (B, N,
    obs_dim) float32: ``offset`` (N, obs_dim) is their state-independent part (slot masks
    included), ``slot_src`` (N, S) the follower each slot shows.

    ``table`` (N, 9 + K) holds each follower's ``[gain g_f + d_f, velocity bound, reward gain,
    E* (6), mask of its K neighbour slots nbr (N, K)]``; ``params`` = ``[Q (6), W (3), leader
    contact, follower contact, max_distance, dt, collision_penalty, violation_penalty,
    terminate_on_collision, observation scales (6), max_steps, check]``. Writes into ``out`` =
    ``(E, E - E*, min_separation, collision, violations, cost, delta_v, rewards, terminated,
    finite)`` (the caller allocates them: arrays made here cost more to return); ``finite[b]``:
    every state, reward and observation entry of copy b is finite (the env's step guard, fused:
    :func:`_check_finite`), computed when ``check`` is not 0 (else True).
    """
    err_raw, err, min_sep, collision, viol, cost, dv, rewards, terminated, finite = out
    nb, n = x.shape[0], x.shape[1]
    q, w = params[0:6], params[6:9]
    c_lead, c_pair, max_dist, dt, pen_c, pen_v = params[9], params[10], params[11], params[12], params[13], params[14]
    stop_on_contact = params[15] != 0.0
    scale, max_steps, checking = params[16:22], params[22], params[23] != 0.0
    gains, nbr_mask = table[:, 0], table[:, 9:]
    observing = obs.shape[0] > 0
    e = np.empty(6)
    xs = np.empty((n, 6))
    sweeping = n > SWEEP_MIN
    near2 = np.empty(n)
    for b in range(nb):
        terminated[b] = False
        if sweeping:
            _nearest_sq(x, b, near2)
        if observing:   # the copy's states / scale (each division once, as the sparse path)
            for j in range(n):
                for c in range(6):
                    xs[j, c] = x[b, j, c] / scale[c]
        for f in range(n):
            _errors(x, b, f, gains, nbr, nbr_mask, e)
            if observing:   # written out here: a helper call per follower costs 4x (measured)
                for c in range(6):
                    obs[b, f, c] = e[c] / scale[c] + offset[f, c]
                    obs[b, f, 6 + c] = xs[f, c]
                obs[b, f, 12] = offset[f, 12]
                obs[b, f, 13] = offset[f, 13]
                obs[b, f, 14] = offset[f, 14] - t[b] / max_steps
                for s in range(slot_src.shape[1]):
                    j, k = slot_src[f, s], 15 + 7 * s
                    m = offset[f, k]
                    obs[b, f, k] = m
                    for c in range(6):
                        obs[b, f, k + 1 + c] = (xs[j, c] - xs[f, c]) * m
            stage = 0.0
            for c in range(6):
                err_raw[b, f, c] = e[c]
                d = e[c] - table[f, 3 + c]
                err[b, f, c] = d
                stage += d * d * q[c]
            u0, u1, u2 = accel[b, f, 0], accel[b, f, 1], accel[b, f, 2]
            stage += u0 * u0 * w[0] + u1 * u1 * w[1] + u2 * u2 * w[2]
            dv[b, f] = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2) * dt
            p0, p1, p2 = x[b, f, 0], x[b, f, 1], x[b, f, 2]
            lead = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            if sweeping:
                sep = np.sqrt(near2[f])
            else:
                sep2 = np.inf
                for j in range(n):
                    if j != f:
                        d0, d1, d2 = p0 - x[b, j, 0], p1 - x[b, j, 1], p2 - x[b, j, 2]
                        sep2 = min(sep2, d0 * d0 + d1 * d1 + d2 * d2)
                sep = np.sqrt(sep2)
            vb = table[f, 1]
            hit = lead < c_lead or sep < c_pair
            bad = abs(e[3]) > vb or abs(e[4]) > vb or abs(e[5]) > vb
            hit_f, bad_f = 1.0 if hit else 0.0, 1.0 if bad else 0.0
            min_sep[b, f] = min(lead, sep)
            collision[b, f] = hit
            viol[b, f] = 1 if bad else 0
            cost[b, f] = hit_f + bad_f
            rewards[b, f] = stage * table[f, 2] - pen_c * hit_f - pen_v * bad_f
            if lead > max_dist or (stop_on_contact and hit):
                terminated[b] = True
    _check_finite(x, rewards, obs, checking, finite)


SWEEP_MIN = 24
"""Above this many followers the nearest-follower distances come from :func:`_nearest_sq` (sort
and sweep, about ``O(N log N)`` per copy) instead of all pairs; both give the same bits."""


@_jit
def _nearest_sq(x, b, out):
    """Squared distance from each follower of copy ``b`` to its nearest other follower into ``out``
    (N,) (``inf`` alone): the followers sorted along the axis of largest spread, each one's
    neighbours in that order scanned outwards until the gap along the axis reaches the best
    distance found (exact; the same squared differences as the all-pairs loop)."""
    n = x.shape[1]
    axis, spread = 0, -1.0
    for c in range(3):
        lo, hi = np.inf, -np.inf
        for j in range(n):
            lo, hi = min(lo, x[b, j, c]), max(hi, x[b, j, c])
        if hi - lo > spread:
            axis, spread = c, hi - lo
    key = np.empty(n)
    for j in range(n):
        key[j] = x[b, j, axis]
    order = np.argsort(key)
    for s in range(n):
        f = order[s]
        p0, p1, p2, kf = x[b, f, 0], x[b, f, 1], x[b, f, 2], key[f]
        best = np.inf
        for step in (-1, 1):
            t = s + step
            while 0 <= t < n:
                j = order[t]
                gap = key[j] - kf
                if gap * gap >= best:
                    break
                d0, d1, d2 = p0 - x[b, j, 0], p1 - x[b, j, 1], p2 - x[b, j, 2]
                best = min(best, d0 * d0 + d1 * d1 + d2 * d2)
                t += step
        out[f] = best


_EXP64 = np.uint64(0x7FF0000000000000)
_EXP32 = np.uint32(0x7F800000)


@_jit
def _check_finite(x, rewards, obs, checking, finite):
    """``finite[b]``: no entry of copy b's states, rewards and observations has all exponent bits
    set (inf / NaN). An integer max over the masked bits: exact, and it vectorises."""
    nb = x.shape[0]
    if not checking:
        finite[:] = True
        return
    xv = x.reshape(nb, -1).view(np.uint64)
    rv = rewards.view(np.uint64)
    ov = obs.reshape(obs.shape[0], -1).view(np.uint32)
    for b in range(nb):
        m64 = np.uint64(0)
        for k in range(xv.shape[1]):
            m64 = max(m64, xv[b, k] & _EXP64)
        for k in range(rv.shape[1]):
            m64 = max(m64, rv[b, k] & _EXP64)
        m32 = np.uint32(0)
        if ov.shape[0] > 0:
            for k in range(ov.shape[1]):
                m32 = max(m32, ov[b, k] & _EXP32)
        finite[b] = m64 != _EXP64 and m32 != _EXP32


@_jit
def cw_step(x, accel, chief, a_t, b_t, rot_t, x_next, chief_next):
    """One Clohessy-Wiltshire step ``x_next = x A^T + u B^T`` (B, N, 6) and the chief's
    ``chief_next = chief R^T`` (B, 6): :meth:`satenv.dynamics.RelativeModel.step` of the ``cw``
    model in one pass (its numpy products are the reference, ``tests/test_platoon_kernel.py``)."""
    for b in range(x.shape[0]):
        for f in range(x.shape[1]):
            for c in range(6):
                s = 0.0
                for k in range(6):
                    s += x[b, f, k] * a_t[k, c]
                for k in range(3):
                    s += accel[b, f, k] * b_t[k, c]
                x_next[b, f, c] = s
        for c in range(6):
            s = 0.0
            for k in range(6):
                s += chief[b, k] * rot_t[k, c]
            chief_next[b, c] = s
