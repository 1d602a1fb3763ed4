"""Distributed MPC baselines for the leader–follower platoon (``satenv.platoon_v0``).

``DMPC(env, **options)`` is a scripted policy (``reset(seed=None)``, ``act(observations)``) that
reads ``env.state()`` and ``env.scenario`` and returns normalised actions ``u / u_max`` in
``[-1, 1]^3``. Two algorithms, selected by ``variant`` (default: ``env.scenario.controller``):

``"one_hop"`` — pereira2023 §III (Algorithm 1). Each follower f minimises its local cost
(14)/(18) over its own input sequence ``U_f`` given its neighbours' latest sequences
``U_i, i in N_f``. Condensed (eq. 16-19) with the CW prediction matrices of
``satenv.dynamics``::

    min_U  U^T S_f U + 2 s_f^T U,   S_f = a_f (c_f^2 B^T Q B + W),
    s_f = a_f c_f B^T Q (A E_f - B sum_i U_i - c_f E_d),       c_f = g_f + d_f.

Constraints (39)-(41): ``|u| <= u_max`` per axis; the velocity rows of the predicted
neighbourhood error within ``+-c_f v_max``; optionally the minimum-tracking-error constraint
``||E_f,pos|| >= c_f r_f`` linearised (42) as the half-space ``n^T E_f,pos(k) >= c_f r_f`` with
``n`` the unit direction of the current ``E_f,pos``. Jacobi iterations until
``max_f ||U_f(g+1) - U_f(g)|| <= sigma``; at the first step the iterates start from a seeded
uniform random sequence in ``[-u_max, u_max]``, afterwards from the previous solution (shifted by
one step by default). ``constrained=False`` drops all constraints; the iteration then converges
to the centralised closed form (25) (:func:`centralised_gain`, Proposition 3).

``"convex_step"`` — pereira2022 §3 (eq. 21-34). The joint model of the target–chaser pairs
``z_j = x_j - x_{j-1}`` (leader = 0, passive): ``z_j+ = A z_j + B u_j - B u_{j-1}``. Every agent j
minimises the cooperative cost ``sum_j a_j V_j`` (eq. 25-28, position outputs) over ``U_j`` with
the others fixed, subject to all joint constraints it affects (input box, pair velocity box,
keep-out sphere linearised as its tangent half-space (eq. 32-33), LOS cone (eq. 34)); the next
iterate is the convex step ``U_j <- w_j U_j* + (1 - w_j) U_j`` (eq. 30), ``iterations`` times.
With ``sum w_j = 1`` the joint iterate stays feasible.

Each agent's QP is built once (Hessian, constraint matrix) and only its linear term and bounds
(and the linearised rows) are updated per solve; solver ``"daqp"`` (default: dual active set,
workspace reused, warm-started from the previous active set) or ``"osqp"`` (tight tolerances
1e-9; polishing off because OSQP prints a notice on every unpolished solve). A failed QP keeps the agent's previous iterate (always input-feasible) and is
counted in ``info["fallbacks"]``; a non-finite result applies zero thrust. ``info`` also keeps
``"solve_ms"`` (wall time of every ``act``), ``"qp_ms"`` (every QP solve), ``"iterations"``
(Jacobi iterations per decision) and ``"not_converged"``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from satenv.dynamics import cw_matrices, prediction_matrices

__all__ = ["DMPC", "OneHopDMPC", "ConvexStepDMPC", "centralised_gain", "QPSolver"]

_SOLVERS = ("daqp", "osqp")


# ----------------------------------------------------------------------------------------------
# QP wrapper: built once, updated in place.
# ----------------------------------------------------------------------------------------------
class QPSolver:
    """``min 0.5 x'Hx + f'x  s.t.  lb <= x <= ub,  bl <= A x <= bu`` with a persistent workspace.

    ``H`` is fixed at construction; ``update`` changes ``f``, bounds and (optionally) ``A``.
    ``solve()`` returns ``(x, ok)``.
    """

    def __init__(self, H: np.ndarray, A: np.ndarray | None, lb: np.ndarray, ub: np.ndarray,
                 solver: str = "daqp", eps: float = 1e-9):
        if solver not in _SOLVERS:
            raise ValueError(f"solver must be one of {_SOLVERS}, got {solver!r}.")
        self.solver = solver
        self.n = H.shape[0]
        self.A = np.zeros((0, self.n)) if A is None else np.ascontiguousarray(A, dtype=float)
        self.m = self.A.shape[0]
        self.lb, self.ub = np.asarray(lb, float), np.asarray(ub, float)
        self.H = np.ascontiguousarray(0.5 * (H + H.T))
        if solver == "daqp":
            import daqp

            self._model = daqp.Model()
            bu = np.concatenate([self.ub, np.full(self.m, 1e30)])
            bl = np.concatenate([self.lb, np.full(self.m, -1e30)])
            self._model.setup(self.H, np.zeros(self.n), self.A, bu, bl)
        else:
            import osqp
            import scipy.sparse as sp

            self._sp = sp
            big = np.vstack([np.eye(self.n), self.A])
            # dense pattern (tiny fill) so that A can be updated in place with the same sparsity
            self._Amat_full = sp.csc_matrix(big + 1e-300 * (big == 0))
            self._model = osqp.OSQP()
            self._model.setup(
                P=sp.triu(sp.csc_matrix(self.H), format="csc"), q=np.zeros(self.n),
                A=self._Amat_full, l=np.concatenate([self.lb, np.full(self.m, -np.inf)]),
                u=np.concatenate([self.ub, np.full(self.m, np.inf)]), eps_abs=eps, eps_rel=eps,
                polishing=False, verbose=False, max_iter=20000,
            )
        self.status = 0

    def update(self, f: np.ndarray, bl: np.ndarray | None = None, bu: np.ndarray | None = None,
               A: np.ndarray | None = None) -> None:
        if A is not None:
            self.A = np.ascontiguousarray(A, dtype=float)
        bl = np.full(self.m, -1e30) if bl is None else bl
        bu = np.full(self.m, 1e30) if bu is None else bu
        if self.solver == "daqp":
            kw = {"f": np.ascontiguousarray(f, dtype=float),
                  "bupper": np.concatenate([self.ub, bu]),
                  "blower": np.concatenate([self.lb, bl])}
            if A is not None:
                kw["A"] = self.A
            self._model.update(**kw)
        else:
            kw = {"q": np.asarray(f, float),
                  "l": np.concatenate([self.lb, np.maximum(bl, -1e30)]),
                  "u": np.concatenate([self.ub, np.minimum(bu, 1e30)])}
            if A is not None:
                big = np.vstack([np.eye(self.n), self.A])
                kw["Ax"] = (big + 1e-300 * (big == 0)).flatten(order="F")
            self._model.update(**kw)

    def solve(self) -> tuple[np.ndarray, bool]:
        if self.solver == "daqp":
            x, _, flag, _ = self._model.solve()
            self.status = int(flag)
            ok = flag == 1 or flag == 2  # 2: soft optimal
        else:
            res = self._model.solve(raise_error=False)
            self.status = int(res.info.status_val)
            x = res.x
            ok = self.status in (1, 2)  # solved / solved inaccurate
        x = np.asarray(x, dtype=float)
        return x, bool(ok and x.shape == (self.n,) and np.all(np.isfinite(x)))


# ----------------------------------------------------------------------------------------------
# pereira2023: 1-hop DMPC
# ----------------------------------------------------------------------------------------------
def _stack_weights(scenario, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Diagonals of calQ = diag(Q, ..., Q, P) (6N,) and calW = diag(W, ..., W) (3N,)."""
    q = np.tile(np.asarray(scenario.state_weight), horizon)
    q[-6:] = np.asarray(scenario.terminal_weight)
    w = np.tile(np.asarray(scenario.input_weight), horizon)
    return q, w


def centralised_gain(scenario, topology=None) -> tuple[np.ndarray, np.ndarray]:
    """Closed form (25)-(27) of the unconstrained problem: ``U* = -K E + K_d (E_d)x lambda``.

    Returns ``(K (3N*lam, 6*lam), K_d (3N*lam, 6N*lam))`` built with Kronecker products exactly
    as in the paper (the per-agent weights alpha cancel and are not used).
    """
    topo = scenario.graph if topology is None else topology
    horizon = scenario.horizon
    a, b = cw_matrices(scenario.mean_motion, scenario.dt)
    ca, cb = prediction_matrices(a, b, horizon)
    q, w = _stack_weights(scenario, horizon)
    btq = cb.T * q[None, :]
    gd = topo.G + topo.D
    s = np.kron(gd @ topo.augmented_laplacian, btq @ cb) + np.kron(np.eye(topo.n_followers), np.diag(w))
    k = np.linalg.solve(s, np.kron(gd, btq @ ca))
    kd = np.linalg.solve(s, np.kron(gd @ gd, btq))
    return k, kd


@dataclass
class _Stats:
    fallbacks: int = 0
    not_converged: int = 0


class OneHopDMPC:
    """The pereira2023 1-hop DMPC on follower states (no env needed).

    Args:
        scenario: a :class:`satenv.scenarios.platoon.PlatoonScenario`.
        topology: override the scenario's graph (a ``satenv.graph.Topology``).
        constrained: False drops every constraint (closed-form local solutions).
        min_error_constraint: add (41)-(42); default: ``scenario.min_error_constraint``.
        velocity_constraint: the (g+d)-scaled velocity box (40) (default True).
        solver: ``"daqp"`` or ``"osqp"``.
        sigma: Jacobi tolerance (default ``scenario.sigma``).
        max_iterations: cap on Jacobi iterations per decision.
        warm_start: ``"shift"`` (previous solution shifted one step, last input repeated) or
            ``"previous"`` (the previous solution as is, Algorithm 1 line 6).
        initial: ``"random"`` (uniform in ``[-u_max, u_max]``, Algorithm 1 line 4) or ``"zeros"``.
        seed: seed of the random initial sequence (``reset(seed)`` overrides).
    """

    def __init__(self, scenario, *, topology=None, constrained: bool = True,
                 min_error_constraint: bool | None = None, velocity_constraint: bool = True,
                 solver: str = "daqp", sigma: float | None = None, max_iterations: int = 200,
                 warm_start: str = "shift", initial: str = "random", seed: int | None = None):
        if solver not in _SOLVERS:
            raise ValueError(f"solver must be one of {_SOLVERS}, got {solver!r}.")
        if warm_start not in ("shift", "previous"):
            raise ValueError(f"warm_start must be 'shift' or 'previous', got {warm_start!r}.")
        if initial not in ("random", "zeros"):
            raise ValueError(f"initial must be 'random' or 'zeros', got {initial!r}.")
        if not isinstance(max_iterations, int) or max_iterations < 1:
            raise ValueError(f"max_iterations must be a positive int, got {max_iterations!r}.")
        self.scenario = scenario
        self.topology = scenario.graph if topology is None else topology
        self.constrained = bool(constrained)
        self.min_error = bool(scenario.min_error_constraint if min_error_constraint is None
                              else min_error_constraint) and self.constrained
        self.velocity = bool(velocity_constraint) and self.constrained
        self.solver = solver
        self.sigma = float(scenario.sigma if sigma is None else sigma)
        if not np.isfinite(self.sigma) or self.sigma <= 0:
            raise ValueError(f"sigma must be > 0, got {sigma!r}.")
        self.max_iterations = max_iterations
        self.warm_start = warm_start
        self.initial = initial
        self._seed = seed
        self._build()
        self.reset(seed)

    # -- construction (once) ------------------------------------------------------------------
    def _build(self) -> None:
        sc, topo = self.scenario, self.topology
        hz = sc.horizon
        self.nu = 3 * hz
        a, b = cw_matrices(sc.mean_motion, sc.dt)
        self.A, self.B = a, b
        ca, cb = prediction_matrices(a, b, hz)
        q, w = _stack_weights(sc, hz)
        btq = cb.T * q[None, :]
        btqb, btqa = btq @ cb, btq @ ca
        nf = topo.n_followers
        c = topo.gains.astype(float)
        alpha = np.asarray(sc.alpha, dtype=float)
        self.c = c
        # Target of each neighbourhood error over the horizon: (g_f + d_f) E_d for pereira2023's
        # formation (eq. 15); in general (L_bar x*)_f, e.g. for the chain formation.
        target = np.asarray(sc.desired_neighbourhood_error(), dtype=float)  # (N, 6)
        # Gradient of V_f: H_f U + M1_f E_f - M2_f sum U_i - m3_f, with H_f = 2 S_f.
        self.H = np.stack([2 * alpha[f] * (c[f] ** 2 * btqb + np.diag(w)) for f in range(nf)])
        self.M1 = np.stack([2 * alpha[f] * c[f] * btqa for f in range(nf)])
        self.M2 = np.stack([2 * alpha[f] * c[f] * btqb for f in range(nf)])
        self.m3 = np.stack([2 * alpha[f] * c[f] * btq @ np.tile(target[f], hz) for f in range(nf)])
        hinv = np.linalg.inv(self.H)
        self.K1 = np.einsum("fij,fjk->fik", hinv, self.M1)
        self.K2 = np.einsum("fij,fjk->fik", hinv, self.M2)
        self.k3 = np.einsum("fij,fj->fi", hinv, self.m3)
        vel_rows = (np.arange(6 * hz) % 6) >= 3
        pos_rows = ~vel_rows
        self.ca_v, self.cb_v = ca[vel_rows], cb[vel_rows]
        self.ca_p, self.cb_p = ca[pos_rows], cb[pos_rows]
        self.adj = topo.adjacency.astype(float)
        self.u_max = float(sc.u_max)
        self.qps: list[QPSolver] = []
        if self.constrained:
            lb = np.full(self.nu, -self.u_max)
            ub = np.full(self.nu, self.u_max)
            for f in range(nf):
                rows = []
                if self.velocity:
                    rows.append(c[f] * self.cb_v)
                if self.min_error:
                    rows.append(np.zeros((hz, self.nu)))  # filled each step
                amat = np.vstack(rows) if rows else None
                self.qps.append(QPSolver(self.H[f], amat, lb, ub, solver=self.solver))

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self._seed = seed
        self.rng = np.random.default_rng(self._seed)
        self.U: np.ndarray | None = None
        self.stats = _Stats()
        self.iterations: list[int] = []
        self.qp_ms: list[float] = []

    # -- one decision ---------------------------------------------------------------------------
    def _initial_iterate(self) -> np.ndarray:
        nf = self.topology.n_followers
        if self.U is None:
            if self.initial == "random":
                return self.rng.uniform(-self.u_max, self.u_max, size=(nf, self.nu))
            return np.zeros((nf, self.nu))
        if self.warm_start == "previous":
            return self.U.copy()
        u = np.empty_like(self.U)
        u[:, :-3] = self.U[:, 3:]
        u[:, -3:] = self.U[:, -3:]
        return u

    def _local_unconstrained(self, err: np.ndarray, su: np.ndarray) -> np.ndarray:
        return (-np.einsum("fij,fj->fi", self.K1, err) + np.einsum("fij,fj->fi", self.K2, su)
                + self.k3)

    def _local_constrained(self, err, su, u_prev, rows_a) -> np.ndarray:
        sc = self.scenario
        nf = self.topology.n_followers
        f_lin = (np.einsum("fij,fj->fi", self.M1, err) - np.einsum("fij,fj->fi", self.M2, su)
                 - self.m3)
        out = np.empty_like(u_prev)
        for f in range(nf):
            bl, bu = [], []
            if self.velocity:
                off = self.ca_v @ err[f] - self.cb_v @ su[f]
                lim = self.c[f] * sc.v_max
                bl.append(-lim - off)
                bu.append(lim - off)
            if self.min_error:
                nvec, ok = rows_a[f]
                off_p = (self.ca_p @ err[f] - self.cb_p @ su[f]).reshape(-1, 3) @ nvec
                bl.append(self.c[f] * sc.follower_radius - off_p if ok
                          else np.full(sc.horizon, -1e30))
                bu.append(np.full(sc.horizon, 1e30))
            qp = self.qps[f]
            amat = None
            if self.min_error:
                amat = qp.A.copy()
                amat[-sc.horizon:] = self.c[f] * np.einsum(
                    "c,kcj->kj", nvec, self.cb_p.reshape(sc.horizon, 3, self.nu))
            t0 = time.perf_counter()
            qp.update(f_lin[f], np.concatenate(bl) if bl else None,
                      np.concatenate(bu) if bu else None, A=amat)
            x, ok = qp.solve()
            self.qp_ms.append(1e3 * (time.perf_counter() - t0))
            if ok:
                out[f] = np.clip(x, -self.u_max, self.u_max)  # solver tolerance ~1e-9
            else:
                self.stats.fallbacks += 1
                out[f] = np.clip(u_prev[f], -self.u_max, self.u_max)
        return out

    def solve(self, x: np.ndarray) -> np.ndarray:
        """One decision for follower states ``x`` (N, 6); returns the applied inputs (N, 3)."""
        x = np.asarray(x, dtype=float)
        err = self.topology.neighbourhood_error(x)
        u = self._initial_iterate()
        rows_a = None
        if self.min_error:
            rows_a = []
            for f in range(self.topology.n_followers):
                p = err[f, :3]
                nrm = np.linalg.norm(p)
                rows_a.append((p / nrm, True) if nrm > 1e-9 else (np.array([1.0, 0, 0]), False))
        converged = False
        it = 0
        while it < self.max_iterations:
            it += 1
            su = self.adj @ u
            if self.constrained:
                new = self._local_constrained(err, su, u, rows_a)
            else:
                new = self._local_unconstrained(err, su)
            delta = np.linalg.norm(new - u, axis=1).max()
            u = new
            if delta <= self.sigma:
                converged = True
                break
        self.iterations.append(it)
        if not converged:
            self.stats.not_converged += 1
        if not np.all(np.isfinite(u)):
            self.stats.fallbacks += 1
            self.U = None
            return np.zeros((self.topology.n_followers, 3))
        self.U = u
        return u[:, :3].copy()


# ----------------------------------------------------------------------------------------------
# pereira2022: convex-step cooperative DMPC on the joint pair model (eq. 21)
# ----------------------------------------------------------------------------------------------
class ConvexStepDMPC:
    """pereira2022 §3 convex-step cooperative DMPC (joint target–chaser pair model).

    Args:
        scenario: a PlatoonScenario (uses ``convex_weights``, ``iterations``, ``keepout_*``,
            ``los_slopes``, ``port``; Q/P weight the pair states, usually positions only).
        solver: ``"daqp"`` or ``"osqp"``.
        iterations: convex-step iterations per decision (default ``scenario.iterations`` or 2).
        weights: convex weights w_j (default ``scenario.convex_weights`` or uniform).
        constrained: False drops the state constraints (input box kept).
        coupled_constraints: True makes agent j impose the constraints of every pair its input
            moves (pairs j and j+1, the joint problem of eq. 29); False (default) only those of
            its own pair j (it chases follower j-1). With the shifted warm start the coupled
            problems became infeasible within ~2 s on the §5.1 scenario (agent j cannot keep
            both pairs feasible against the other agents' stale plans), hence the default.

    When an agent's state-constrained QP is infeasible it falls back to its input-box-only QP
    (counted in ``stats.fallbacks``); if that fails too it keeps its previous iterate.
    """

    def __init__(self, scenario, *, solver: str = "daqp", iterations: int | None = None,
                 weights=None, constrained: bool = True, coupled_constraints: bool = False,
                 seed: int | None = None):
        if solver not in _SOLVERS:
            raise ValueError(f"solver must be one of {_SOLVERS}, got {solver!r}.")
        self.scenario = scenario
        self.solver = solver
        m = scenario.n_followers
        it = iterations if iterations is not None else (scenario.iterations or 2)
        if not isinstance(it, int) or it < 1:
            raise ValueError(f"iterations must be a positive int, got {it!r}.")
        self.n_iter = it
        w = weights if weights is not None else (scenario.convex_weights or (1.0 / m,) * m)
        w = np.asarray(w, dtype=float)
        if w.shape != (m,) or np.any(w <= 0) or abs(w.sum() - 1) > 1e-9:
            raise ValueError(f"weights must be {m} positive numbers summing to 1, got {w}.")
        self.w = w
        self.constrained = bool(constrained)
        self.coupled = bool(coupled_constraints)
        self._build()
        self.reset(seed)

    def _n_rows_pair(self) -> int:
        sc, hz = self.scenario, self.scenario.horizon
        if not self.constrained:
            return 0
        rows = 3 * hz  # velocity box
        if sc.keepout_radius > 0:
            rows += hz
        if sc.los_slopes is not None:
            rows += 5 * hz
        return rows

    def _build(self) -> None:
        sc = self.scenario
        hz, m = sc.horizon, sc.n_followers
        self.nu = 3 * hz
        a, b = cw_matrices(sc.mean_motion, sc.dt)
        self.A, self.B = a, b
        ca, cb = prediction_matrices(a, b, hz)
        self.ca, self.cb = ca, cb
        q, w = _stack_weights(sc, hz)
        alpha = np.asarray(sc.alpha, dtype=float)
        atot = alpha.sum()
        btq = cb.T * q[None, :]
        self.btqb, self.btqa, self.btq = btq @ cb, btq @ ca, btq
        self.yd = np.tile(np.asarray(sc.desired_error), hz)
        # V = atot * sum_i alpha_i |Z_i - Yd|^2_calQ + sum_j alpha_j^2 |U_j|^2_calW  (+ const)
        self.wq = atot * alpha  # weight of pair i's tracking term
        self.wu = alpha ** 2
        self.H = []
        for j in range(m):
            hj = self.wq[j] * self.btqb + (self.wq[j + 1] * self.btqb if j + 1 < m else 0)
            self.H.append(2 * (hj + self.wu[j] * np.diag(w)))
        vel_rows = (np.arange(6 * hz) % 6) >= 3
        pos_rows = ~vel_rows
        self.ca_v, self.cb_v = ca[vel_rows], cb[vel_rows]
        self.ca_p, self.cb_p = ca[pos_rows], cb[pos_rows]
        self.u_max = float(sc.u_max)
        self.qps, self.box_qps = [], []
        lb, ub = np.full(self.nu, -self.u_max), np.full(self.nu, self.u_max)
        for j in range(m):
            npairs = 2 if (self.coupled and j + 1 < m) else 1
            rows = self._n_rows_pair() * npairs
            amat = np.zeros((rows, self.nu)) if rows else None
            self.qps.append(QPSolver(self.H[j], amat, lb, ub, solver=self.solver))
            self.box_qps.append(QPSolver(self.H[j], None, lb, ub, solver=self.solver)
                                if rows else None)

    def reset(self, seed: int | None = None) -> None:
        self.U: np.ndarray | None = None
        self.stats = _Stats()
        self.iterations: list[int] = []
        self.qp_ms: list[float] = []

    def _pair_rows(self, z0: np.ndarray, offset: np.ndarray, sign: float):
        """Rows ``G U_j in [lo, hi]`` of the constraints on one pair whose prediction is
        ``Z = offset + sign * calB U_j`` (offset includes calA z0 and the other agents)."""
        sc, hz = self.scenario, self.scenario.horizon
        g_rows, lo, hi = [], [], []
        gv = sign * self.cb_v
        off_v = offset.reshape(hz, 6)[:, 3:].ravel()
        g_rows.append(gv)
        lo.append(-sc.v_max - off_v)
        hi.append(sc.v_max - off_v)
        cbp = (sign * self.cb_p).reshape(hz, 3, self.nu)
        off_p = offset.reshape(hz, 6)[:, :3]
        if sc.keepout_radius > 0:
            center = np.asarray(sc.keepout_center)
            d = z0[:3] - center
            nrm = np.linalg.norm(d)
            nvec = d / nrm if nrm > 1e-9 else np.array([0.0, -1.0, 0.0])
            p_o = center + sc.keepout_radius * nvec  # eq. 32-33: tangent plane at p_o
            g_rows.append(np.einsum("c,kcj->kj", nvec, cbp))
            lo.append(nvec @ p_o - off_p @ nvec)
            hi.append(np.full(hz, 1e30))
        if sc.los_slopes is not None:
            cx, cz = sc.los_slopes
            xr, yr, zr = sc.port
            a_los = np.array([[0, 1, 0], [cx, 1, 0], [-cx, 1, 0], [0, 1, cz], [0, 1, -cz]], float)
            b_los = np.array([-yr, cx * xr, cx * xr, cz * zr, cz * zr])
            g = np.einsum("rc,kcj->krj", a_los, cbp).reshape(5 * hz, self.nu)
            off = (off_p @ a_los.T).ravel()
            g_rows.append(g)
            lo.append(np.full(5 * hz, -1e30))
            hi.append(np.tile(b_los, hz) - off)
        return np.vstack(g_rows), np.concatenate(lo), np.concatenate(hi)

    def solve(self, x: np.ndarray) -> np.ndarray:
        """One decision for follower states ``x`` (M, 6) relative to the leader -> inputs (M, 3)."""
        sc = self.scenario
        m = sc.n_followers
        x = np.asarray(x, dtype=float)
        z = x - np.concatenate([np.zeros((1, 6)), x[:-1]], axis=0)
        if self.U is None:
            u = np.zeros((m, self.nu))
        else:
            u = np.empty_like(self.U)
            u[:, :-3] = self.U[:, 3:]
            u[:, -3:] = 0.0
        free = np.einsum("ij,mj->mi", self.ca, z)  # calA z_i  (m, 6N)
        for _ in range(self.n_iter):
            ustar = np.empty_like(u)
            for j in range(m):
                # pair j: Z_j = free_j + calB U_j - calB U_{j-1}
                off_j = free[j] - (self.cb @ u[j - 1] if j >= 1 else 0.0)
                f_lin = 2 * self.wq[j] * (self.btq @ (off_j - self.yd))
                rows = []
                if self.constrained:
                    rows.append(self._pair_rows(z[j], off_j, +1.0))
                if j + 1 < m:
                    # pair j+1: Z_{j+1} = free_{j+1} + calB U_{j+1} - calB U_j
                    off_n = free[j + 1] + self.cb @ u[j + 1]
                    f_lin = f_lin - 2 * self.wq[j + 1] * (self.btq @ (off_n - self.yd))
                    if self.constrained and self.coupled:
                        rows.append(self._pair_rows(z[j + 1], off_n, -1.0))
                qp = self.qps[j]
                t0 = time.perf_counter()
                if rows:
                    gmat = np.vstack([r[0] for r in rows])
                    qp.update(f_lin, np.concatenate([r[1] for r in rows]),
                              np.concatenate([r[2] for r in rows]), A=gmat)
                else:
                    qp.update(f_lin)
                sol, ok = qp.solve()
                if not ok and self.box_qps[j] is not None:
                    self.stats.fallbacks += 1
                    self.box_qps[j].update(f_lin)
                    sol, ok = self.box_qps[j].solve()
                self.qp_ms.append(1e3 * (time.perf_counter() - t0))
                if ok:
                    ustar[j] = np.clip(sol, -self.u_max, self.u_max)
                else:
                    self.stats.fallbacks += 1
                    ustar[j] = np.clip(u[j], -self.u_max, self.u_max)
            u = self.w[:, None] * ustar + (1 - self.w[:, None]) * u
        self.iterations.append(self.n_iter)
        if not np.all(np.isfinite(u)):
            self.stats.fallbacks += 1
            self.U = None
            return np.zeros((m, 3))
        self.U = u
        return u[:, :3].copy()


# ----------------------------------------------------------------------------------------------
# Policy wrapper
# ----------------------------------------------------------------------------------------------
class DMPC:
    """Distributed MPC policy for ``satenv.platoon_v0`` (see the module docstring).

    Args:
        env: the platoon env; ``env.scenario`` gives the model, ``env.state()`` the states.
        variant: ``"one_hop"`` (pereira2023) or ``"convex_step"`` (pereira2022); default
            ``env.scenario.controller``.
        **options: passed to :class:`OneHopDMPC` or :class:`ConvexStepDMPC` (e.g.
            ``constrained``, ``solver``, ``sigma``, ``min_error_constraint``, ``warm_start``,
            ``seed``, ``iterations``, ``weights``). Unknown options raise ``ValueError``.
    """

    _ONE_HOP_OPTS = ("constrained", "min_error_constraint", "velocity_constraint", "solver",
                     "sigma", "max_iterations", "warm_start", "initial", "seed")
    _CONVEX_OPTS = ("solver", "iterations", "weights", "constrained", "coupled_constraints",
                    "seed")

    def __init__(self, env, variant: str | None = None, **options):
        scenario = getattr(env, "scenario", None)
        if scenario is None:
            raise ValueError(
                f"DMPC needs a platoon env exposing .scenario (satenv.platoon_v0), got {env!r}."
            )
        self.env = env
        self.variant = scenario.controller if variant is None else variant
        if self.variant == "one_hop":
            allowed = self._ONE_HOP_OPTS
        elif self.variant == "convex_step":
            allowed = self._CONVEX_OPTS
        else:
            raise ValueError(
                f"variant must be 'one_hop' or 'convex_step', got {variant!r}."
            )
        bad = sorted(set(options) - set(allowed))
        if bad:
            raise ValueError(
                f"unknown DMPC option(s) {bad} for variant {self.variant!r}; "
                f"valid options: {list(allowed)}."
            )
        topo = getattr(env, "topology", None)
        if self.variant == "one_hop":
            self.core = OneHopDMPC(scenario, topology=topo, **options)
        else:
            self.core = ConvexStepDMPC(scenario, **options)
        self.agents = [f"follower_{i + 1}" for i in range(scenario.n_followers)]
        self.u_max = float(scenario.u_max)
        self.info: dict = {}
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.core.reset(seed)
        self._solve_ms: list[float] = []
        self._refresh_info()

    def _refresh_info(self) -> None:
        self.info = {
            "fallbacks": self.core.stats.fallbacks,
            "not_converged": self.core.stats.not_converged,
            "solve_ms": self._solve_ms,
            "qp_ms": self.core.qp_ms,
            "iterations": self.core.iterations,
        }

    def _states(self) -> np.ndarray:
        n = len(self.agents)
        s = np.asarray(self.env.state(), dtype=float).ravel()
        if s.size < 6 * n:
            raise ValueError(f"env.state() has {s.size} entries, expected at least {6 * n}.")
        return s[: 6 * n].reshape(n, 6)

    def act(self, observations: dict) -> dict:
        t0 = time.perf_counter()
        x = self._states()
        try:
            u = self.core.solve(x)
        except (np.linalg.LinAlgError, ValueError, RuntimeError, ArithmeticError):
            self.core.stats.fallbacks += 1
            self.core.U = None
            u = np.zeros((len(self.agents), 3))
        a = np.clip(u / self.u_max, -1.0, 1.0).astype(np.float32)
        self._solve_ms.append(1e3 * (time.perf_counter() - t0))
        self._refresh_info()
        return {name: a[i] for i, name in enumerate(self.agents) if name in observations}
