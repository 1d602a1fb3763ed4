"""Communication graphs of a leader–follower platoon (pereira2023 §III-A, eq. 9–12).

Followers are indexed ``0 … N-1`` here (``follower_1 … follower_N`` in the envs); the passive
leader is not a node of the graph, it enters only through the pinning vector ``g``.

Adjacency convention (pereira2023 eq. 12): ``adjacency[i, j] = a_ij = 1`` iff there is an edge
``j -> i``, i.e. **follower i hears follower j** (j is in the neighbour set N_i). Rows are
receivers, columns are senders. With this convention

* degree ``d_i = sum_j a_ij`` (in-degree: how many followers i hears),
* ``L = D - A_d`` (Laplacian), ``L_bar = G + D - A_d`` (augmented Laplacian, eq. 11),
* neighbourhood error ``E_i = sum_{j in N_i} (x_i - x_j) + g_i x_i = (L_bar x)_i`` (eq. 9).

Named topologies (pereira2023 Fig. 2, after Zheng et al. 2017), every follower pinned (g = 1):

* ``"PLF"``  predecessor–leader following: i hears i-1.
* ``"BDL"``  bidirectional with leader: i hears i-1 and i+1.
* ``"TPLF"`` two-predecessor–leader following: i hears i-1 and i-2.
* ``"RING"`` nearest neighbours on a ring: i hears i-1 and i+1 modulo N (the 2-nearest-neighbour
  graph of the ``"ring"`` formation, :mod:`satenv.scenarios.platoon`).

A user adjacency matrix must be square, 0/1, with a zero diagonal, and every follower must hear
the leader (all ``g_i = 1``): pereira2023 assumes it (Lemma 1 needs ``G`` positive definite).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "TOPOLOGIES",
    "Topology",
    "make_topology",
    "named_adjacency",
    "neighbourhood_error",
]

TOPOLOGIES: tuple[str, ...] = ("PLF", "BDL", "TPLF", "RING")


def named_adjacency(name: str, n_followers: int) -> np.ndarray:
    """Adjacency ``a_ij`` (i hears j) of a named topology for ``n_followers`` followers."""
    if not isinstance(n_followers, int | np.integer) or isinstance(n_followers, bool) or n_followers < 1:
        raise ValueError(
            f"n_followers must be a positive int, got {n_followers!r}; pass e.g. n_followers=4."
        )
    key = str(name).upper()
    if key not in TOPOLOGIES:
        raise ValueError(
            f"unknown topology {name!r}; expected one of {TOPOLOGIES} or an (N, N) 0/1 adjacency "
            "matrix with a_ij = 1 when follower i hears follower j."
        )
    n = int(n_followers)
    adj = np.zeros((n, n), dtype=np.int64)
    for i in range(n):
        if i >= 1:
            adj[i, i - 1] = 1
        if key == "BDL" and i + 1 < n:
            adj[i, i + 1] = 1
        if key == "TPLF" and i >= 2:
            adj[i, i - 2] = 1
        if key == "RING" and n > 1:
            adj[i, (i - 1) % n] = adj[i, (i + 1) % n] = 1
    return adj


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Topology:
    """A validated leader–follower communication graph.

    Attributes:
        adjacency: (N, N) int array, ``a_ij = 1`` iff follower i hears follower j.
        pinning: (N,) int array ``g``, ``g_i = 1`` iff follower i hears the leader.
        name: the named topology, or ``"custom"``.
    """

    adjacency: np.ndarray
    pinning: np.ndarray
    name: str = "custom"
    _lbar: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        adj = np.asarray(self.adjacency)
        if adj.ndim != 2 or adj.shape[0] != adj.shape[1] or adj.shape[0] < 1:
            raise ValueError(
                f"adjacency must be a square (N, N) matrix with N >= 1, got shape {adj.shape}; "
                "pass a_ij = 1 when follower i hears follower j."
            )
        if not np.issubdtype(adj.dtype, np.number) and adj.dtype != bool:
            raise ValueError(f"adjacency must be numeric 0/1, got dtype {adj.dtype}.")
        if not np.all((adj == 0) | (adj == 1)):
            bad = np.unique(adj[(adj != 0) & (adj != 1)])
            raise ValueError(
                f"adjacency entries must be 0 or 1, got values {bad.tolist()}; "
                "use a_ij = 1 when follower i hears follower j, else 0."
            )
        if np.any(np.diag(adj) != 0):
            idx = np.flatnonzero(np.diag(adj)).tolist()
            raise ValueError(
                f"adjacency must have a zero diagonal (no self-loops), got a_ii = 1 for followers "
                f"{[int(i) + 1 for i in idx]}; set those diagonal entries to 0."
            )
        n = adj.shape[0]
        g = np.asarray(self.pinning)
        if g.shape != (n,):
            raise ValueError(
                f"pinning vector g must have shape ({n},) to match the adjacency, got {g.shape}."
            )
        if not np.all((g == 0) | (g == 1)):
            raise ValueError(f"pinning entries must be 0 or 1, got {g.tolist()}.")
        if np.any(g != 1):
            missing = [int(i) + 1 for i in np.flatnonzero(g != 1)]
            raise ValueError(
                f"every follower must hear the leader (g_i = 1), but follower(s) {missing} do "
                "not; pereira2023 assumes all followers are pinned to the leader (Lemma 1). "
                "Use pinning=None (all ones)."
            )
        object.__setattr__(self, "adjacency", _frozen(adj.astype(np.int64)))
        object.__setattr__(self, "pinning", _frozen(g.astype(np.int64)))
        lbar = np.diag(self.pinning + self.adjacency.sum(axis=1)) - self.adjacency
        object.__setattr__(self, "_lbar", _frozen(lbar.astype(float)))

    # ---- basic graph quantities ------------------------------------------------------------
    @property
    def n_followers(self) -> int:
        return int(self.adjacency.shape[0])

    @property
    def degrees(self) -> np.ndarray:
        """In-degrees ``d_i = |N_i|`` (number of followers that follower i hears)."""
        return self.adjacency.sum(axis=1)

    @property
    def gains(self) -> np.ndarray:
        """``g_i + d_i``: the input gain of follower i in the error dynamics (eq. 10)."""
        return self.pinning + self.degrees

    def neighbours(self, i: int) -> np.ndarray:
        """Indices of the followers that follower ``i`` (0-based) hears."""
        return np.flatnonzero(self.adjacency[i])

    @property
    def G(self) -> np.ndarray:  # noqa: N802 - paper notation
        return np.diag(self.pinning).astype(float)

    @property
    def D(self) -> np.ndarray:  # noqa: N802 - paper notation
        return np.diag(self.degrees).astype(float)

    @property
    def laplacian(self) -> np.ndarray:
        """``L = D - A_d``."""
        return self.D - self.adjacency

    @property
    def augmented_laplacian(self) -> np.ndarray:
        """``L_bar = G + D - A_d`` (eq. 11); nonsingular when every follower is pinned."""
        return self._lbar

    def neighbourhood_error(self, x: np.ndarray) -> np.ndarray:
        """Eq. 9 batched: ``x`` (..., N, d) -> ``E`` (..., N, d)."""
        return neighbourhood_error(x, self)

    def desired_states(self, desired_error: np.ndarray) -> np.ndarray:
        """States ``x*`` (N, d) at which ``E_i = (g_i + d_i) E_d`` for every follower (eq. 15).

        Solves ``L_bar x* = (g + d) ⊗ E_d``.
        """
        e_d = np.asarray(desired_error, dtype=float)
        rhs = self.gains[:, None] * e_d[None, :]
        return np.linalg.solve(self.augmented_laplacian, rhs)


def make_topology(
    spec: str | np.ndarray | Topology, n_followers: int | None = None, pinning=None
) -> Topology:
    """Build a :class:`Topology` from a name (``"PLF"``, ``"BDL"``, ``"TPLF"``), an adjacency
    matrix (``a_ij = 1`` iff follower i hears j), or return ``spec`` if it is already one.

    ``pinning`` (``g``) defaults to all ones; it must be all ones (see module docstring).
    """
    if isinstance(spec, Topology):
        if n_followers is not None and spec.n_followers != n_followers:
            raise ValueError(
                f"topology has {spec.n_followers} followers but the scenario has {n_followers}."
            )
        return spec
    if isinstance(spec, str):
        if n_followers is None:
            raise ValueError(f"a named topology {spec!r} needs n_followers.")
        adj = named_adjacency(spec, n_followers)
        name = spec.upper()
    else:
        try:
            adj = np.asarray(spec)
        except Exception as exc:  # pragma: no cover - exotic inputs
            raise ValueError(f"topology must be a name or an adjacency matrix, got {spec!r}") from exc
        if adj.dtype == object:
            raise ValueError(
                f"topology must be one of {TOPOLOGIES} or a numeric (N, N) adjacency matrix, "
                f"got {spec!r}."
            )
        if n_followers is not None and adj.shape != (n_followers, n_followers):
            raise ValueError(
                f"adjacency has shape {adj.shape} but the scenario has {n_followers} followers; "
                f"pass an ({n_followers}, {n_followers}) matrix."
            )
        name = "custom"
    n = adj.shape[0] if adj.ndim == 2 else 0
    g = np.ones(n, dtype=np.int64) if pinning is None else np.asarray(pinning)
    return Topology(adjacency=adj, pinning=g, name=name)


def neighbourhood_error(x: np.ndarray, topology: Topology) -> np.ndarray:
    """Neighbourhood error (eq. 9), batched: ``x`` (..., N, d) -> (..., N, d).

    ``E_i = sum_{j in N_i} (x_i - x_j) + g_i x_i = (L_bar x)_i``.
    """
    x = np.asarray(x, dtype=float)
    n = topology.n_followers
    if x.ndim < 2 or x.shape[-2] != n:
        raise ValueError(
            f"x must have shape (..., {n}, d) for {n} followers, got {x.shape}."
        )
    return np.einsum("ij,...jd->...id", topology.augmented_laplacian, x)
