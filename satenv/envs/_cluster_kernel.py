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

__all__ = ["separations"]


@numba.njit(cache=True, nogil=True)
def separations(path, obstacle, q_r, all_pairs, pair, obs, tgt):
    """Minima over the steps of ``path`` (S, B, M, 3) of the distances to the nearest other
    satellite (when ``all_pairs``; else ``pair`` is left as it is), to the obstacle at
    ``obstacle`` (S, B, 3) and to the target spacecraft ``q_r`` (3,), into ``pair``, ``obs``,
    ``tgt`` (B, M), which the caller fills with ``inf``."""
    n_steps, nb, m = path.shape[0], path.shape[1], path.shape[2]
    for s in range(n_steps):
        for b in range(nb):
            o0, o1, o2 = obstacle[s, b, 0], obstacle[s, b, 1], obstacle[s, b, 2]
            for i in range(m):
                p0, p1, p2 = path[s, b, i, 0], path[s, b, i, 1], path[s, b, i, 2]
                d0, d1, d2 = p0 - o0, p1 - o1, p2 - o2
                obs[b, i] = min(obs[b, i], np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
                d0, d1, d2 = p0 - q_r[0], p1 - q_r[1], p2 - q_r[2]
                tgt[b, i] = min(tgt[b, i], np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
                if all_pairs:
                    for j in range(i + 1, m):
                        d0 = p0 - path[s, b, j, 0]
                        d1 = p1 - path[s, b, j, 1]
                        d2 = p2 - path[s, b, j, 2]
                        d = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                        if d < pair[b, i]:
                            pair[b, i] = d
                        if d < pair[b, j]:
                            pair[b, j] = d
