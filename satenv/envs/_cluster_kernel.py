"""Compiled (numba) separation minima of the cluster core over one decision.

:meth:`satenv.envs.cluster_v0.ClusterCore.step` propagates a decision's physics steps in one call
of the truth kernel (:meth:`satenv.dynamics.RelativeModel.propagate`), which returns the LVLH
positions after every physics step; :func:`separations` reduces them to each satellite's
smallest distance to the nearest other satellite (all pairs, the dense path), to the obstacle and
to the target spacecraft, in one pass without temporaries. The numpy loop of the core
(``fused=False``) is the reference (``tests/test_cluster_kernel.py``). Importing this module
imports numba; compiled code is cached next to the module.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["neighbours", "observe", "separations"]


@numba.njit(cache=True, nogil=True)
def separations(path, obstacle, q_r, all_pairs, pair, obs, tgt):
    """Minima over the steps of ``path`` (S, B, M, 3) of the distances to the nearest other
    satellite (when ``all_pairs``; else ``pair`` is left as it is), to the obstacle at
    ``obstacle`` (S, B, 3) and to the target spacecraft ``q_r`` (3,), into ``pair``, ``obs``,
    ``tgt`` (B, M), which the caller fills with ``inf``. The minima are taken over squared
    distances and rooted once (the same numbers: the square root is monotone and correctly
    rounded)."""
    n_steps, nb, m = path.shape[0], path.shape[1], path.shape[2]
    for b in range(nb):
        for i in range(m):
            pair[b, i] *= pair[b, i]
            obs[b, i] *= obs[b, i]
            tgt[b, i] *= tgt[b, i]
    for s in range(n_steps):
        for b in range(nb):
            o0, o1, o2 = obstacle[s, b, 0], obstacle[s, b, 1], obstacle[s, b, 2]
            for i in range(m):
                p0, p1, p2 = path[s, b, i, 0], path[s, b, i, 1], path[s, b, i, 2]
                d0, d1, d2 = p0 - o0, p1 - o1, p2 - o2
                obs[b, i] = min(obs[b, i], d0 * d0 + d1 * d1 + d2 * d2)
                d0, d1, d2 = p0 - q_r[0], p1 - q_r[1], p2 - q_r[2]
                tgt[b, i] = min(tgt[b, i], d0 * d0 + d1 * d1 + d2 * d2)
                if all_pairs:
                    for j in range(i + 1, m):
                        d0 = p0 - path[s, b, j, 0]
                        d1 = p1 - path[s, b, j, 1]
                        d2 = p2 - path[s, b, j, 2]
                        d = d0 * d0 + d1 * d1 + d2 * d2
                        if d < pair[b, i]:
                            pair[b, i] = d
                        if d < pair[b, j]:
                            pair[b, j] = d
    for b in range(nb):
        for i in range(m):
            pair[b, i] = np.sqrt(pair[b, i])
            obs[b, i] = np.sqrt(obs[b, i])
            tgt[b, i] = np.sqrt(tgt[b, i])


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
def observe(x, targets, obstacle, p_obs, q_r, remaining, order, pos_scale, vel_scale, obs):
    """The cluster observation (module docstring of :mod:`satenv.envs.cluster_v0`) of states ``x``
    (B, M, 6) into ``obs`` (B, M, 19 + 7 K) float32: ``targets`` (B, M, 3) allocated targets,
    ``obstacle`` (B, 3) its positions, ``p_obs`` (3,) its velocity, ``q_r`` (3,) the target
    spacecraft, ``remaining`` (B,) the fraction of the episode left, ``order`` (B, M, K) the
    neighbour slots of :func:`neighbours`. The reference's float64 formulas, then float32."""
    nb, m, k = x.shape[0], x.shape[1], order.shape[2]
    for b in range(nb):
        for i in range(m):
            for c in range(3):
                q, p = x[b, i, c], x[b, i, 3 + c]
                obs[b, i, c] = (q - targets[b, i, c]) / pos_scale
                obs[b, i, 3 + c] = p / vel_scale
                obs[b, i, 6 + c] = q / pos_scale
                obs[b, i, 9 + c] = (obstacle[b, c] - q) / pos_scale
                obs[b, i, 12 + c] = (p_obs[c] - p) / vel_scale
                obs[b, i, 15 + c] = (q_r[c] - q) / pos_scale
            obs[b, i, 18] = remaining[b]
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
