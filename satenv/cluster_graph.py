"""Time-varying communication graph of a satellite cluster (li2022 §2.3).

Each satellite talks to at most its ``n_nearest`` (N_a) nearest satellites within the
communication range ``comm_range`` (r_c). li2022 assumes bidirectional links (an undirected
graph), while "the N_a nearest" is not a symmetric relation; we make it undirected by the union
(``a_ij = a_ji = 1`` when j is among i's N_a nearest in range *or* i among j's), so a satellite
can have more than N_a neighbours. ``symmetric=False`` keeps the directed k-nearest relation
(row i lists whom i hears).

Two forms of the same graph: the dense adjacency (:func:`nearest_neighbour_graph`, ``M^2``
entries; the reference) and padded neighbour lists (:func:`neighbour_lists`, cost proportional to
the edges, from the exact k-nearest search of :mod:`satenv.neighbours`) for swarms.
"""

from __future__ import annotations

import numpy as np

from satenv.neighbours import nearest

__all__ = ["in_range_nearest", "nearest_neighbour_graph", "neighbour_lists", "pairwise_distances"]


def pairwise_distances(positions: np.ndarray) -> np.ndarray:
    """Distances ``(..., M, M)`` between the rows of ``positions`` ``(..., M, 3)``."""
    p = np.asarray(positions, dtype=np.float64)
    diff = p[..., :, None, :] - p[..., None, :, :]
    return np.sqrt(np.einsum("...ijk,...ijk->...ij", diff, diff))


def nearest_neighbour_graph(positions, n_nearest: int = 4, comm_range: float = 1000.0,
                            symmetric: bool = True) -> np.ndarray:
    """Adjacency ``(..., M, M)`` bool of the N_a-nearest-within-range graph (no self loops).

    Args:
        positions: ``(..., M, 3)`` satellite positions [m].
        n_nearest: N_a, the number of nearest satellites each one selects (>= 0).
        comm_range: r_c [m]; satellites farther apart never communicate.
        symmetric: undirected union (li2022's bidirectional links) or directed k-nearest.
    """
    p = np.asarray(positions, dtype=np.float64)
    _check(p, n_nearest, comm_range)
    m = p.shape[-2]
    d = pairwise_distances(p)
    d[..., np.arange(m), np.arange(m)] = np.inf
    d = np.where(d <= comm_range, d, np.inf)
    k = min(int(n_nearest), m - 1)
    adj = np.zeros(d.shape, dtype=bool)
    if k > 0:
        order = np.argsort(d, axis=-1, kind="stable")[..., :k]
        chosen = np.take_along_axis(d, order, axis=-1) < np.inf
        np.put_along_axis(adj, order, chosen, axis=-1)
    if symmetric:
        adj = adj | np.swapaxes(adj, -1, -2)
    return adj


def _check(p: np.ndarray, n_nearest: int, comm_range: float) -> None:
    if p.ndim < 2 or p.shape[-1] != 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"positions must be a finite array of shape (..., M, 3), got {p.shape}")
    if isinstance(n_nearest, bool) or int(n_nearest) != n_nearest or n_nearest < 0:
        raise ValueError(f"n_nearest must be a non-negative int, got {n_nearest!r}")
    if not np.isfinite(comm_range) or comm_range <= 0:
        raise ValueError(f"comm_range must be finite and > 0 [m], got {comm_range!r}")


def in_range_nearest(positions, n_nearest: int = 4, comm_range: float = 1000.0,
                     method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Each satellite's ``min(n_nearest, M - 1)`` nearest others within ``comm_range``.

    The directed k-nearest relation of :func:`nearest_neighbour_graph` (``symmetric=False``) as
    lists, from :func:`satenv.neighbours.nearest` (``method``). These are also a satellite's
    nearest neighbours in the undirected graph: a link added by the union is never shorter.

    Args:
        positions: ``(B, M, 3)`` satellite positions [m].

    Returns:
        ``(dist, index)``, each ``(B, M, K)``, nearest first; slots beyond the range hold ``inf``
        and ``-1``.
    """
    p = np.asarray(positions, dtype=np.float64)
    _check(p, n_nearest, comm_range)
    k = min(int(n_nearest), p.shape[-2] - 1)
    if k <= 0:
        shape = p.shape[:-1] + (0,)
        return np.zeros(shape), np.zeros(shape, dtype=np.int64)
    dist, index = nearest(p, k, method)
    out = dist > comm_range
    dist[out] = np.inf
    index[out] = -1
    return dist, index


def neighbour_lists(positions, n_nearest: int = 4, comm_range: float = 1000.0,
                    method: str = "auto") -> np.ndarray:
    """The undirected graph of :func:`nearest_neighbour_graph` as padded neighbour lists.

    Args:
        positions: ``(B, M, 3)`` satellite positions [m].

    Returns:
        ``(B, M, D)`` int, ``D`` the largest degree: the neighbours of each satellite in
        ascending index, padded with ``-1``. Cost proportional to the edges (plus the search).
    """
    p = np.asarray(positions, dtype=np.float64)
    b, m = p.shape[:2]
    index = in_range_nearest(p, n_nearest, comm_range, method)[1]
    bb, ii, kk = np.nonzero(index >= 0)
    jj = index[bb, ii, kk]
    src = np.concatenate([bb * m + ii, bb * m + jj])          # node (copy, satellite)
    dst = np.concatenate([jj, ii])
    key = np.unique(src * m + dst)                             # sorted: by node, then neighbour
    node, nbr = key // m, key % m
    count = np.bincount(node, minlength=b * m)
    out = np.full((b * m, max(int(count.max(initial=0)), 0)), -1, dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    out[node, np.arange(key.size) - start[node]] = nbr
    return out.reshape(b, m, -1)
