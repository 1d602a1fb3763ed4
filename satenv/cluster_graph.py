"""Time-varying communication graph of a satellite cluster (li2022 §2.3).

Each satellite talks to at most its ``n_nearest`` (N_a) nearest satellites within the
communication range ``comm_range`` (r_c). li2022 assumes bidirectional links (an undirected
graph), while "the N_a nearest" is not a symmetric relation; we make it undirected by the union
(``a_ij = a_ji = 1`` when j is among i's N_a nearest in range *or* i among j's), so a satellite
can have more than N_a neighbours. ``symmetric=False`` keeps the directed k-nearest relation
(row i lists whom i hears).
"""

from __future__ import annotations

import numpy as np

__all__ = ["nearest_neighbour_graph", "pairwise_distances"]


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
    if p.ndim < 2 or p.shape[-1] != 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"positions must be a finite array of shape (..., M, 3), got {p.shape}")
    if isinstance(n_nearest, bool) or int(n_nearest) != n_nearest or n_nearest < 0:
        raise ValueError(f"n_nearest must be a non-negative int, got {n_nearest!r}")
    if not np.isfinite(comm_range) or comm_range <= 0:
        raise ValueError(f"comm_range must be finite and > 0 [m], got {comm_range!r}")
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
