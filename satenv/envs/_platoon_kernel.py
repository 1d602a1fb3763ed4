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

__all__ = ["evaluate"]

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
    terminate_on_collision, observation scales (6), max_steps]``. Writes into ``out`` = ``(E,
    E - E*, min_separation, collision, violations, cost, delta_v, rewards, terminated)`` (the
    caller allocates them: arrays made here cost more to return).
    """
    err_raw, err, min_sep, collision, viol, cost, dv, rewards, terminated = out
    nb, n = x.shape[0], x.shape[1]
    q, w = params[0:6], params[6:9]
    c_lead, c_pair, max_dist, dt, pen_c, pen_v = params[9], params[10], params[11], params[12], params[13], params[14]
    stop_on_contact = params[15] != 0.0
    scale, max_steps = params[16:22], params[22]
    gains, nbr_mask = table[:, 0], table[:, 9:]
    observing = obs.shape[0] > 0
    e = np.empty(6)
    xs = np.empty((n, 6))
    for b in range(nb):
        terminated[b] = False
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
