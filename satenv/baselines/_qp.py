"""Dense QPs whose matrices change at every decision: the QP step of the real-time-iteration solvers.

:class:`DenseQP` solves ``min 0.5 x'Hx + f'x  s.t.  lb <= x <= ub,  lo <= A x <= hi`` with DAQP
(dual active set, dense). The QP is brought to DAQP's least-distance form here, with LAPACK
(``H = R'R``, ``z = R x + R^-T f``: ``min 0.5 |z|^2`` over the rows ``[R^-1; A R^-1] z``), which
costs a third of DAQP's own transformation at the NMPC's 180 inputs. The active set of an
owner's (a spacecraft's) previous QP starts the next one, moved by ``shift`` (the previous
QP's constraint of each new one: a plan shifted by one step moves its active rows one stage
down; by default the same index, and rows the previous QP did not have start inactive): the
linearisations of successive decisions differ little, so few active-set changes remain.
A bound with ``lb == ub`` is an equality (DAQP's sense flag 5). :meth:`DenseQP.solve` returns
``(x, ok, status)`` for :func:`satenv.baselines.base.guarded_solve`.

:class:`BufferedFunction` evaluates a CasADi function into preallocated numpy arrays (20x faster
than converting its ``DM`` outputs on these problems). :func:`linearisation` builds, from a CasADi NLP,
the function ``(w, p) -> (H_f, grad f, g, J_g)`` (the cost's exact Hessian and gradient, the rows
and their Jacobian, dense) that a sequential-QP
step linearises about.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["QP_INFINITY", "QP_ROW_TOL", "BufferedFunction", "DenseQP", "linearisation"]

QP_INFINITY = 1e30
"""DAQP's infinite bound (an infinite float is replaced by it)."""
QP_ROW_TOL = 1e-5
"""Largest accepted violation of a QP bound or row by DAQP's point (its primal tolerance is 1e-6)."""
_EQUALITY = 5
_ACTIVE_UPPER, _ACTIVE_LOWER = 1, 3          # DAQP sense flags: active (1), at the lower bound (+2)


class DenseQP:
    """DAQP on the least-distance form, warm-started from each owner's previous QP (module docstring)."""

    def __init__(self, iter_limit: int = 1000) -> None:
        self.iter_limit = int(iter_limit)
        self._active: dict[Any, tuple[int, np.ndarray]] = {}      # owner -> (n, sense of its last QP)
        self.multipliers: dict[Any, np.ndarray] = {}
        """The multipliers of each owner's last solved QP (bounds, then rows; > 0 at an upper bound)."""

    def forget(self, owner: Any = None) -> None:
        """Drop the warm active sets of ``owner`` (all when None): its next QP starts cold."""
        if owner is None:
            self._active.clear()
            self.multipliers.clear()
        else:
            self._active.pop(owner, None)
            self.multipliers.pop(owner, None)

    def solve(self, H: np.ndarray, f: np.ndarray, A: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              lb: np.ndarray, ub: np.ndarray, owner: Any = 0,
              shift: np.ndarray | None = None) -> tuple[np.ndarray | None, bool, str]:
        """One QP: ``(x, ok, status)``; ``ok`` is DAQP's optimal (1) or soft-optimal (2) flag.

        ``shift``: for each of the ``n + rows`` constraints (bounds first), the index of the
        owner's previous QP's constraint whose active state starts it (-1 or beyond that QP's
        constraints: inactive); None: the same index. A QP of another ``n`` starts cold."""
        import daqp
        from scipy.linalg import blas, lapack

        n = H.shape[0]
        rows = n + A.shape[0]
        r, info = lapack.dpotrf(H, lower=0, clean=1)                 # H = R'R, R upper triangular
        if info != 0:
            return None, False, f"hessian not positive definite (dpotrf {info})"
        r_inv, info = lapack.dtrtri(r, lower=0)
        if info != 0:
            return None, False, f"singular cholesky factor (dtrtri {info})"
        m = np.empty((rows, n))
        m[:n] = r_inv
        if rows > n:
            m[n:] = blas.dtrmm(1.0, r_inv, A, side=1, lower=0)        # A R^-1
        v = r_inv.T @ f                                               # R^-T f
        off = m @ v
        bu = np.clip(np.concatenate([ub, hi]) + off, -QP_INFINITY, QP_INFINITY)
        bl = np.clip(np.concatenate([lb, lo]) + off, -QP_INFINITY, QP_INFINITY)
        sense = np.zeros(rows, dtype=np.intc)
        n_prev, prev = self._active.get(owner, (None, None))
        if n_prev == n:
            if shift is None:
                shift = np.arange(rows)
            ok = (shift >= 0) & (shift < prev.size)
            sense[ok] = prev[shift[ok]]
        eq = np.zeros(rows, dtype=bool)
        eq[:n] = lb == ub
        sense[eq] = _EQUALITY
        z, _, exitflag, out = daqp.solve(None, None, m, bu, bl, sense, eps_prox=0.0, iter_limit=self.iter_limit)
        exitflag = int(exitflag)
        if exitflag not in (1, 2):
            self._active.pop(owner, None)         # no stale active set for the next QP
            return None, False, f"daqp {exitflag}"
        lam = self.multipliers[owner] = np.asarray(out["lam"], dtype=float)
        sense = np.where(lam > 0, _ACTIVE_UPPER, np.where(lam < 0, _ACTIVE_LOWER, 0)).astype(np.intc)
        self._active[owner] = (n, sense)
        return r_inv @ (np.asarray(z, dtype=float) - v), True, f"daqp {exitflag}"


def linearisation(w: Any, p: Any, cost: Any, g: Any, name: str) -> Any:
    """``(w, p) -> (H_f, grad_f, g, J_g)`` of the CasADi NLP ``min cost(w, p) s.t. g(w, p)``
    (dense outputs; ``H_f`` the cost's exact Hessian)."""
    import casadi as ca

    h_f, grad_f = ca.hessian(cost, w)
    return ca.Function(name, [w, p], [ca.densify(h_f), ca.densify(grad_f), ca.densify(g),
                                      ca.densify(ca.jacobian(g, w))],
                       ["w", "p"], ["hess_f", "grad_f", "g", "jac_g"])


class BufferedFunction:
    """A CasADi ``Function`` (dense outputs) evaluated into preallocated numpy arrays.

    ``f(*args)`` copies the arguments in, runs the function and returns its outputs as arrays of
    their CasADi shapes: views of the buffers, overwritten by the next call. One instance per
    thread (the buffers are shared).
    """

    def __init__(self, function: Any) -> None:
        self._buffer, self._trigger = function.buffer()
        self._args = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self._out = [np.zeros((function.size2_out(i), function.size1_out(i))) for i in range(function.n_out())]
        for i, a in enumerate(self._args):
            self._buffer.set_arg(i, memoryview(a))
        for i, o in enumerate(self._out):
            if o.size != function.nnz_out(i):
                raise ValueError(f"BufferedFunction needs dense outputs: output {i} of {function.name()} is sparse")
            self._buffer.set_res(i, memoryview(o))

    def __call__(self, *args: Any) -> list[np.ndarray]:
        for dst, src in zip(self._args, args, strict=True):
            dst[:] = np.ravel(src, order="F")
        self._trigger()
        return [o.T for o in self._out]
