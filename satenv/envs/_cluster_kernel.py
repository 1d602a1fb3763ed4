"""Compiled (numba) parts of the cluster core's decision: input saturation, separation minima,
graph, observation, infos and rewards.

:meth:`satenv.envs.cluster_v0.ClusterCore.step` propagates a decision's physics steps in one call
of the truth kernel (:meth:`satenv.dynamics.RelativeModel.propagate`), which returns the LVLH
positions after every physics step; :func:`separations` reduces them to each satellite's
smallest distance to the nearest other satellite (all pairs, the dense path), to the obstacle and
to the target spacecraft, in one pass without temporaries. The numpy loop of the core
(``fused=False``) is the reference (``tests/test_cluster_kernel.py``). On the dense path
:func:`neighbours` and :func:`observe` give the graph and the observation, and :func:`decision`
the infos, rewards, terminations and the finiteness check in one pass, with the numpy glue's
operations in its order (bit for bit the same numbers); :func:`saturate` is ``saturate_norm``
with the norms. Importing this module imports numba; compiled code is cached next to the module.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["decision", "neighbours", "observe", "saturate", "separations"]


@numba.njit(cache=True, nogil=True)
def separations(path, copies, ts, h, obstacle_pos, obstacle_vel, q_r, all_pairs, pair, obs, tgt):
    """Minima over the steps of ``path`` (S, B, M, 3) (row ``r`` the positions of copy
    ``copies[r]``) of the distances to the nearest other satellite (when ``all_pairs``; else
    ``pair`` is left as it is), to the obstacle (at ``obstacle_pos + (ts + h) obstacle_vel``, as
    :meth:`satenv.scenarios.cluster.ClusterScenario.obstacle_at`, ``ts`` (S, B) the physics
    steps' starts) and to the target spacecraft ``q_r`` (3,), into ``pair``, ``obs``, ``tgt``
    (B, M), which the caller fills with ``inf``. The minima are taken over squared
    distances and rooted once (the same numbers: the square root is monotone and correctly
    rounded)."""
    n_steps, nb, m = path.shape[0], path.shape[1], path.shape[2]
    q0, q1, q2 = q_r[0], q_r[1], q_r[2]
    pl, ol, tl = np.empty(m), np.empty(m), np.empty(m)
    px, py, pz = np.empty(m), np.empty(m), np.empty(m)
    for row in range(nb):   # one copy at a time, its minima in local arrays; per satellite the same operations in order
        b = copies[row]
        for i in range(m):
            pl[i] = pair[b, i] * pair[b, i]
            ol[i] = obs[b, i] * obs[b, i]
            tl[i] = tgt[b, i] * tgt[b, i]
        for s in range(n_steps):
            tt = ts[s, b] + h
            o0 = obstacle_pos[0] + tt * obstacle_vel[0]
            o1 = obstacle_pos[1] + tt * obstacle_vel[1]
            o2 = obstacle_pos[2] + tt * obstacle_vel[2]
            for i in range(m):
                p0, p1, p2 = path[s, row, i, 0], path[s, row, i, 1], path[s, row, i, 2]
                px[i], py[i], pz[i] = p0, p1, p2
                d0, d1, d2 = p0 - o0, p1 - o1, p2 - o2
                d = d0 * d0 + d1 * d1 + d2 * d2
                ol[i] = d if d < ol[i] else ol[i]
                d0, d1, d2 = p0 - q0, p1 - q1, p2 - q2
                d = d0 * d0 + d1 * d1 + d2 * d2
                tl[i] = d if d < tl[i] else tl[i]
            if all_pairs:
                for i in range(m):
                    p0, p1, p2 = px[i], py[i], pz[i]
                    best = pl[i]
                    for j in range(i + 1, m):
                        d0, d1, d2 = p0 - px[j], p1 - py[j], p2 - pz[j]
                        d = d0 * d0 + d1 * d1 + d2 * d2
                        best = d if d < best else best
                        pl[j] = d if d < pl[j] else pl[j]
                    pl[i] = best
        for i in range(m):
            if all_pairs:
                pair[b, i] = np.sqrt(pl[i])
            obs[b, i] = np.sqrt(ol[i])
            tgt[b, i] = np.sqrt(tl[i])


@numba.njit(cache=True, nogil=True)
def neighbours(pos, k, comm_range, order, degree):
    """The graph of :func:`satenv.cluster_graph.nearest_neighbour_graph` for positions ``pos``
    (B, M, 3): each satellite's ``k`` nearest others within ``comm_range``, nearest first (ties:
    lower index first, as the reference's stable sort) into ``order`` (B, M, k) (``-1`` for empty
    slots), and each satellite's degree in the undirected union graph into ``degree`` (B, M)."""
    nb, m = pos.shape[0], pos.shape[1]
    d = np.empty(m)
    adj = np.zeros((m, m), dtype=np.bool_)
    best_d = np.empty(k)
    for b in range(nb):
        adj[:, :] = False
        for i in range(m):
            filled = 0
            for j in range(m):
                if j == i:
                    continue
                d0 = pos[b, i, 0] - pos[b, j, 0]
                d1 = pos[b, i, 1] - pos[b, j, 1]
                d2 = pos[b, i, 2] - pos[b, j, 2]
                dj = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                d[j] = dj
                if not dj <= comm_range:
                    continue
                # insertion into the sorted first-k list (strict <: an equal distance stays behind)
                s = filled
                while s > 0 and dj < best_d[s - 1]:
                    s -= 1
                if s < k:
                    last = min(filled, k - 1)
                    for r in range(last, s, -1):
                        best_d[r] = best_d[r - 1]
                        order[b, i, r] = order[b, i, r - 1]
                    best_d[s] = dj
                    order[b, i, s] = j
                    filled = min(filled + 1, k)
            for s in range(filled, k):
                order[b, i, s] = -1
            for s in range(filled):
                adj[i, order[b, i, s]] = True
        for i in range(m):
            c = 0
            for j in range(m):
                if adj[i, j] or adj[j, i]:
                    c += 1
            degree[b, i] = c


@numba.njit(cache=True, nogil=True)
def observe(x, all_targets, assignment, obstacle_pos, p_obs, t, dt, max_steps, q_r, order, pos_scale, vel_scale,
            obs):
    """The cluster observation (module docstring of :mod:`satenv.envs.cluster_v0`) of states ``x``
    (B, M, 6) into ``obs`` (B, M, 19 + 7 K) float32: the allocated targets ``all_targets``
    (B, T, 3) at ``assignment`` (B, M), the obstacle at ``obstacle_pos + t dt p_obs`` (``p_obs``
    (3,) its velocity, ``t`` (B,) the step counts), ``q_r`` (3,) the target spacecraft, the
    fraction of the episode left ``1 - t / max_steps``, ``order`` (B, M, K) the neighbour slots of
    :func:`neighbours`. The reference's float64 formulas, then float32."""
    nb, m, k = x.shape[0], x.shape[1], order.shape[2]
    for b in range(nb):
        tb = t[b] * dt
        remaining = 1.0 - t[b] / max_steps
        for i in range(m):
            a = assignment[b, i]
            for c in range(3):
                q, p = x[b, i, c], x[b, i, 3 + c]
                obs[b, i, c] = (q - all_targets[b, a, c]) / pos_scale
                obs[b, i, 3 + c] = p / vel_scale
                obs[b, i, 6 + c] = q / pos_scale
                obs[b, i, 9 + c] = ((obstacle_pos[c] + tb * p_obs[c]) - q) / pos_scale
                obs[b, i, 12 + c] = (p_obs[c] - p) / vel_scale
                obs[b, i, 15 + c] = (q_r[c] - q) / pos_scale
            obs[b, i, 18] = remaining
            for s in range(k):
                base = 19 + 7 * s
                j = order[b, i, s]
                if j < 0:
                    for c in range(7):
                        obs[b, i, base + c] = 0.0
                    continue
                obs[b, i, base] = 1.0
                for c in range(3):
                    obs[b, i, base + 1 + c] = (x[b, j, c] - x[b, i, c]) / pos_scale
                    obs[b, i, base + 4 + c] = (x[b, j, 3 + c] - x[b, i, 3 + c]) / vel_scale


@numba.njit(cache=True, nogil=True, error_model="numpy")
def saturate(accel, u_max, u, norm):
    """:func:`satenv.dynamics.saturate_norm` of the rows of ``accel`` (N, 3) onto the ``u_max``
    ball into ``u``, and the saturated rows' norms into ``norm`` (N,): the reference's operations
    (a NaN propagates as there)."""
    tiny = np.finfo(np.float64).tiny
    for r in range(accel.shape[0]):
        a0, a1, a2 = accel[r, 0], accel[r, 1], accel[r, 2]
        n = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if n != n:
            scale = np.nan
        else:
            scale = u_max / (n if n >= tiny else tiny)
            if scale != scale:
                scale = np.nan
            elif scale > 1.0:
                scale = 1.0
        v0, v1, v2 = a0 * scale, a1 * scale, a2 * scale
        u[r, 0], u[r, 1], u[r, 2] = v0, v1, v2
        norm[r] = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)


@numba.njit(cache=True, nogil=True)
def _minimum(a, b):
    """``np.minimum`` of two floats (a NaN propagates)."""
    if a != a or b != b:
        return np.nan
    return a if a <= b else b


@numba.njit(cache=True, nogil=True, error_model="numpy")
def decision(x, all_targets, assignment, un, pair, obs_dist, tgt_dist, limits, obs, err, min_sep, collision, viol,
             cost, rewards, terminated, finite):
    """The end of a dense decision of :meth:`satenv.envs.cluster_v0.ClusterCore.step` in one pass:
    from the states ``x`` (B, M, 6) after the decision, the allocated targets (``all_targets``
    (B, T, 3) at ``assignment`` (B, M)), the saturated inputs' norms ``un`` (B, M) and the
    separation minima ``pair``, ``obs_dist``, ``tgt_dist`` (B, M) (:func:`separations`): the
    tracking errors, minimum separations, collision flags, violations, costs, rewards and
    terminations of the infos, and which copies are all finite (states, rewards and the
    observations ``obs`` (B, M, D) float32 when it has rows). ``limits``: ``pair_distance,
    obstacle_distance, target_distance, reward_distance_scale, reward_control_weight, u_max,
    collision_penalty, max_distance, terminate_on_collision``. The numpy glue's operations in its
    order (the same numbers)."""
    nb, m = x.shape[0], x.shape[1]
    pair_d, obstacle_d, target_d = limits[0], limits[1], limits[2]
    scale_d, weight_u, u_max, penalty, max_distance = limits[3], limits[4], limits[5], limits[6], limits[7]
    stop_on_collision = limits[8] != 0.0
    for b in range(nb):
        ended = False
        collided = False
        ok = True
        for i in range(m):
            a = assignment[b, i]
            e0 = x[b, i, 0] - all_targets[b, a, 0]
            e1 = x[b, i, 1] - all_targets[b, a, 1]
            e2 = x[b, i, 2] - all_targets[b, a, 2]
            err[b, i, 0], err[b, i, 1], err[b, i, 2] = e0, e1, e2
            for c in range(3, 6):
                err[b, i, c] = x[b, i, c]
            n_viol = 0
            if pair[b, i] < pair_d:
                n_viol += 1
            if obs_dist[b, i] < obstacle_d:
                n_viol += 1
            if tgt_dist[b, i] < target_d:
                n_viol += 1
            min_sep[b, i] = _minimum(_minimum(pair[b, i], obs_dist[b, i]), tgt_dist[b, i])
            hit = n_viol > 0
            collision[b, i] = hit
            viol[b, i] = n_viol
            cost[b, i] = float(n_viol)
            d = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            q = un[b, i] / u_max
            r = (-d / scale_d - weight_u * (q * q)) - penalty * (1.0 if hit else 0.0)
            rewards[b, i] = r
            p0, p1, p2 = x[b, i, 0], x[b, i, 1], x[b, i, 2]
            ended = ended or np.sqrt(p0 * p0 + p1 * p1 + p2 * p2) > max_distance
            collided = collided or hit
            ok = ok and np.isfinite(r)
            for c in range(6):
                ok = ok and np.isfinite(x[b, i, c])
        terminated[b] = ended or (stop_on_collision and collided)
        finite[b] = ok
    if obs.shape[0] > 0:
        bits = obs.reshape(nb, -1).view(np.uint32)    # float32 exponent all ones: inf or NaN
        for b in range(nb):
            bad = 0
            for c in range(bits.shape[1]):
                bad += (bits[b, c] & 0x7F800000) == 0x7F800000
            finite[b] = finite[b] and bad == 0
