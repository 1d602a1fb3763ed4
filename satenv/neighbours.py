"""Exact nearest-body searches on a batch of swarms (the cost of collisions and separations).

Every env reports each body's distance to the nearest other body (``min_separation``, exact) and
flags contacts closer than the bodies' radii. Two interchangeable kernels compute it on positions
``(B, M, 3)`` (``B`` env copies of ``M`` bodies):

* ``"dense"`` — all ``M^2`` pair distances of a copy (blocked over copies); the fastest below
  :data:`DENSE_MAX` bodies and the reference the tree is tested against;
* ``"tree"``  — one ``scipy.spatial.cKDTree`` over the whole batch, cost ``O(B M log M)``. The
  copies are kept apart by a fourth coordinate ``b * S`` with ``S`` larger than any distance within
  a copy, so a query never crosses copies and every in-copy distance is computed from the three
  position differences alone (the fourth difference is exactly zero). The distances of the
  neighbours found are then recomputed with the dense kernel's formula (:func:`norm3`).

:func:`nearest` picks the kernel by ``M`` (``method="auto"``). :func:`pairs_within` lists the pairs
closer than a radius (proximity graphs) with the same batched tree.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["DENSE_MAX", "METHODS", "nearest", "norm3", "pairs_within"]

DENSE_MAX: int = 24
"""Largest number of bodies per copy for which ``method="auto"`` uses the dense kernel (measured
crossover on one core: the tree wins from about 32 bodies; ``satenv.bench.perf --sections scaling``)."""

METHODS = ("auto", "dense", "tree")

_ONES3 = np.ones(3)
_BLOCK = 1 << 22  # pair distances held at once by the dense kernel (32 MiB of float64)


def nearest(pos: np.ndarray, k: int = 1, method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest other bodies of every body, per copy.

    Args:
        pos: positions ``(B, M, 3)`` [m], finite.
        k: how many neighbours (``1 <= k``); slots beyond ``M - 1`` get distance ``inf`` and index
            ``-1``.
        method: ``"auto"`` (dense up to :data:`DENSE_MAX` bodies, else tree), ``"dense"`` or ``"tree"``.

    Returns:
        ``(dist, index)``, each ``(B, M, k)``: distances in ascending order and the bodies' indices
        within their copy (ties in any order).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    pos = np.asarray(pos, dtype=np.float64)
    b, m, _ = pos.shape
    kk = min(k, m - 1)
    dist = np.full((b, m, k), np.inf)
    index = np.full((b, m, k), -1, dtype=np.int64)
    if kk <= 0:
        return dist, index
    if method == "dense" or (method == "auto" and m <= DENSE_MAX):
        _dense(pos, kk, dist, index)
    else:
        _tree(pos, kk, dist, index)
    return dist, index


def norm3(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the 3-vectors ``(..., 3)`` (the one formula of every separation, so that
    both kernels and the envs' dense paths give the same bits)."""
    return np.sqrt((v * v) @ _ONES3)


def _dense(pos: np.ndarray, k: int, dist: np.ndarray, index: np.ndarray) -> None:
    b, m, _ = pos.shape
    step = max(1, _BLOCK // (m * m))
    diag = np.arange(m)
    for lo in range(0, b, step):
        p = pos[lo:lo + step]
        diff = p[:, :, None, :] - p[:, None, :, :]
        d = norm3(diff)
        d[:, diag, diag] = np.inf
        if k == 1:
            idx = d.argmin(axis=-1)[..., None]
        else:
            idx = np.argpartition(d, k - 1, axis=-1)[..., :k] if k < m - 1 else np.argsort(d, axis=-1)[..., :k]
            idx = np.take_along_axis(idx, np.argsort(np.take_along_axis(d, idx, -1), axis=-1), -1)
        dist[lo:lo + step, :, :k] = np.take_along_axis(d, idx, -1)
        index[lo:lo + step, :, :k] = idx


def pairs_within(pos: np.ndarray, radius: float) -> np.ndarray:
    """The pairs of bodies of the same copy at most ``radius`` apart.

    Args:
        pos: positions ``(B, M, 3)`` [m], finite.
        radius: the link distance [m] (inclusive).

    Returns:
        ``(P, 2)`` int, each pair once as flat indices ``b * M + i < b * M + j``; cost
        proportional to the pairs (plus the tree).
    """
    pos = np.asarray(pos, dtype=np.float64)
    return _batch_tree(pos, radius).query_pairs(radius, output_type="ndarray")


def _batch_tree(pos: np.ndarray, reach: float = 0.0) -> cKDTree:
    """One tree of every copy's bodies, copies kept more than ``reach`` apart (module docstring)."""
    b, m, _ = pos.shape
    flat = pos.reshape(b * m, 3)
    if b > 1:
        sep = max(4.0 * float(np.abs(flat).max()) + 1.0, 2.0 * reach + 1.0)  # > any in-copy distance
        flat = np.column_stack([flat, np.repeat(np.arange(b) * sep, m)])
    return cKDTree(flat, balanced_tree=False, compact_nodes=False)


def _tree(pos: np.ndarray, k: int, dist: np.ndarray, index: np.ndarray) -> None:
    b, m, _ = pos.shape
    tree = _batch_tree(pos)
    flat = tree.data
    d, i = tree.query(flat, k=k + 1)
    # the body itself is one of the zero-distance answers: drop one answer equal to the body
    # (or the last one when a coincident body came first; both are at distance 0)
    own = np.arange(b * m)[:, None]
    drop = np.where((i == own).any(axis=1), (i == own).argmax(axis=1), k)
    keep = np.ones_like(i, dtype=bool)
    keep[np.arange(b * m), drop] = False
    idx = i[keep].reshape(b, m, k) % m
    index[..., :k] = idx
    # distances again from the position differences, with the dense kernel's formula
    dist[..., :k] = norm3(np.take_along_axis(pos[:, None], idx[..., None], 2) - pos[:, :, None])
