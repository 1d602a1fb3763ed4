"""Dense QPs whose matrices change at every decision: the QP step of the real-time-iteration solvers.

:class:`DenseQP` solves ``min 0.5 x'Hx + f'x  s.t.  lb <= x <= ub,  lo <= A x <= hi`` with DAQP
(dual active set, dense) in one workspace per problem shape and owner (a spacecraft): the
workspace keeps the active set of the owner's previous QP, which starts the next one (the
linearisations of successive decisions differ little, so few active-set changes remain).
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
_EQUALITY, _INEQUALITY = 5, 0


class DenseQP:
    """DAQP with one reused workspace per ``(owner, n, rows)`` (module docstring)."""

    def __init__(self, iter_limit: int = 1000) -> None:
        self.iter_limit = int(iter_limit)
        self._models: dict[tuple, Any] = {}

    def solve(self, H: np.ndarray, f: np.ndarray, A: np.ndarray, lo: np.ndarray, hi: np.ndarray,
              lb: np.ndarray, ub: np.ndarray, owner: Any = 0) -> tuple[np.ndarray | None, bool, str]:
        """One QP: ``(x, ok, status)``; ``ok`` is DAQP's optimal (1) or soft-optimal (2) flag."""
        import daqp

        n, m = H.shape[0], A.shape[0]
        bu = np.clip(np.concatenate([ub, hi]), -QP_INFINITY, QP_INFINITY)
        bl = np.clip(np.concatenate([lb, lo]), -QP_INFINITY, QP_INFINITY)
        sense = np.where(np.r_[lb == ub, np.zeros(m, bool)], _EQUALITY, _INEQUALITY).astype(np.int32)
        H = np.ascontiguousarray(0.5 * (H + H.T))
        f, A = np.ascontiguousarray(f, dtype=float), np.ascontiguousarray(A, dtype=float)
        key = (owner, n, m)
        model = self._models.get(key)
        if model is None:
            model = daqp.Model()
            flag = model.setup(H, f, A, bu, bl, sense)[0]
            if flag < 0:
                return None, False, f"daqp setup {flag}"
            model.settings = {"iter_limit": self.iter_limit}
            self._models[key] = model
        elif (flag := model.update(H=H, f=f, A=A, bupper=bu, blower=bl)) < 0:
            del self._models[key]                 # e.g. H not positive definite: rebuild next time
            return None, False, f"daqp update {flag}"
        x, _, exitflag, _ = model.solve()
        exitflag = int(exitflag)
        if exitflag not in (1, 2):
            del self._models[key]                 # no stale active set for the next QP
        return np.asarray(x, dtype=float), exitflag in (1, 2), f"daqp {exitflag}"


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
