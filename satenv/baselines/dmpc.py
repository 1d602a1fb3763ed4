"""Distributed MPC baselines for the leader–follower platoon (``satenv.platoon_v0``).

``DMPC(env, **options)`` is a scripted policy (``reset(seed=None)``, ``act(observations)``) that
reads ``env.state()`` and ``env.scenario`` and returns normalised actions ``u / u_max`` in
``[-1, 1]^3``. Settings: one :class:`DMPCConfig` (the paper's per preset, :data:`PAPER_CONFIGS`).
Two algorithms, selected by ``DMPCConfig.variant`` (default: the preset's paper):

``"one_hop"`` — pereira2023 §III (Algorithm 1). Each follower f minimises its local cost
(14)/(18) over its own input sequence ``U_f`` given its neighbours' latest sequences
``U_i, i in N_f``. Condensed (eq. 16-19) with the CW prediction matrices of
``satenv.dynamics``::

    min_U  U^T S_f U + 2 s_f^T U,   S_f = a_f (c_f^2 B^T Q B + W),
    s_f = a_f c_f B^T Q (A E_f - B sum_i U_i - c_f E_d),       c_f = g_f + d_f.

Constraints (39)-(41): ``|u| <= u_max`` per axis; the velocity rows of the predicted
neighbourhood error within ``+-c_f v_max``; optionally the minimum-tracking-error constraint
``||E_f,pos|| >= c_f r_f`` linearised (42) as the half-space ``n^T E_f,pos(k) >= c_f r_f`` with
``n`` the unit direction of the current ``E_f,pos``. Jacobi iterations; agent f stops once
``||U_f(g+1) - U_f(g)|| <= sigma`` (Algorithm 1; ``stopping="all"``: all stop when
``max_f ||U_f(g+1) - U_f(g)|| <= sigma``); at the first step the iterates start from a seeded
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
1e-9; polishing off because OSQP prints a notice on every unpolished solve). Every QP solve goes
through :func:`satenv.baselines.base.guarded_solve` (an exception, a failed status, a wrong-shaped or
non-finite point, or a point outside the input box or the rows by more than ``QP_TOL`` is a
failure): a failed QP keeps the agent's previous iterate (always input-feasible) and is counted
in ``info["fallbacks"]`` (why: ``info["solver_status"]``); a non-finite plan applies zero thrust. ``info`` also keeps
``"solve_ms"`` (wall time of every ``act``), ``"qp_ms"`` (every QP solve), ``"iterations"``
(Jacobi iterations per decision) and ``"not_converged"``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from satenv.baselines.base import (
    MAX_HORIZON,
    Baseline,
    BaselineError,
    check_env,
    choice,
    config_from_options,
    flag,
    guarded_solve,
    integer,
    new_info,
    number,
    record_fallback,
    row_violation,
    time_limit,
    validate,
    weights,
)
from satenv.dynamics import cw_matrices, prediction_matrices
from satenv.perturbations import nominal

__all__ = ["DMPC", "DMPCConfig", "OneHopDMPC", "ConvexStepDMPC", "centralised_gain", "QPSolver"]

_SOLVERS = ("daqp", "osqp")
QP_TOL = 1e-5
"""Accepted violation of a QP's bounds / rows by a returned point (relative to max(1, |bound|))."""


@dataclass(frozen=True)
class DMPCConfig:
    """Settings of the platoon DMPCs (pereira2023 Table I by default; :meth:`paper` for §5.1 of
    pereira2022). Controller parameters only: the cost weights Q, W and alpha that the env's
    reward uses, the constraints' limits and ``min_error_constraint`` stay in the scenario.

    Args:
        variant: ``"one_hop"`` (pereira2023 Algorithm 1) or ``"convex_step"`` (pereira2022).
        horizon: MPC prediction horizon N (<= 200).
        terminal_weight: diagonal of P (6,).
        sigma: Jacobi stopping tolerance of Algorithm 1 (one_hop).
        max_iterations: cap on Jacobi iterations per decision (one_hop).
        stopping: ``"per_agent"`` (Algorithm 1, line 15: agent f stops iterating, and keeps
            broadcasting its last iterate, once ``||U_f(g+1) - U_f(g)|| <= sigma``) or ``"all"``
            (every agent iterates until ``max_f ||U_f(g+1) - U_f(g)|| <= sigma``) (one_hop).
        iterations: convex-step iterations gamma per decision (convex_step).
        convex_weights: w_j of pereira2022 eq. 30 (one per follower, in (0, 1), sum 1);
            ``None``: uniform.
        constrained: False drops every constraint (closed-form local solutions).
        min_error_constraint: add (41)-(42) (one_hop); ``None``: the scenario's.
        velocity_constraint: the (g+d)-scaled velocity box (40) (one_hop).
        velocity_margin: the box (40) is imposed as ``(g+d) v_max - velocity_margin`` [m/s]
            (one_hop): the applied error velocity also depends on the neighbours' final
            iterates, which differ from the ones agent f planned against by up to the Jacobi
            tolerance; without the margin the bound was exceeded by 1e-8 m/s on 2-3 steps.
        coupled_constraints: convex_step agents impose the constraints of both pairs they move
            (:class:`ConvexStepDMPC`).
        solver: ``"daqp"`` or ``"osqp"``.
        warm_start: ``"shift"`` or ``"previous"`` (one_hop); initial: ``"random"`` or ``"zeros"``.
        seed: seed of the random initial sequence (``reset(seed)`` overrides).
        solve_time_limit: wall-time limit [s] of one solve (None: none): a solve over it is a
            flagged failure like any other (``satenv.baselines.base.guarded_solve``); a stall guard, QP median
            0.1-2 ms (set the control period for a real-time check).
    """

    variant: str = "one_hop"
    horizon: int = 30
    terminal_weight: tuple[float, ...] = (25.0,) * 6
    sigma: float = 0.5
    max_iterations: int = 200
    stopping: str = "per_agent"
    iterations: int = 2
    convex_weights: tuple[float, ...] | None = None
    constrained: bool = True
    min_error_constraint: bool | None = None
    velocity_constraint: bool = True
    velocity_margin: float = 1e-4
    coupled_constraints: bool = False
    solver: str = "daqp"
    warm_start: str = "shift"
    initial: str = "random"
    seed: int | None = None
    solve_time_limit: float | None = 1.0

    def __post_init__(self) -> None:
        rules: dict[str, Any] = {
            "solve_time_limit": time_limit,
            "variant": partial(choice, choices=("one_hop", "convex_step")),
            "horizon": partial(integer, high=MAX_HORIZON), "sigma": number,
            "velocity_margin": partial(number, zero_ok=True),
            "terminal_weight": partial(weights, length=6),
            "max_iterations": integer, "iterations": integer,
            "constrained": flag, "velocity_constraint": flag, "coupled_constraints": flag,
            "solver": partial(choice, choices=_SOLVERS),
            "warm_start": partial(choice, choices=("shift", "previous")),
            "stopping": partial(choice, choices=("per_agent", "all")),
            "initial": partial(choice, choices=("random", "zeros")),
        }
        if self.min_error_constraint is not None:
            rules["min_error_constraint"] = flag
        if self.seed is not None:
            rules["seed"] = partial(integer, low=0, high=2**63 - 1)
        if self.convex_weights is not None:
            rules["convex_weights"] = partial(weights, zero_ok=False)
        validate(self, "DMPC", rules)
        w = self.convex_weights
        if w is not None and (max(w) >= 1 or abs(sum(w) - 1) > 1e-9):
            raise BaselineError(f"DMPC option convex_weights must be numbers in (0, 1) that sum to 1 "
                                f"(pereira2022 eq. 30), got {w}")

    @classmethod
    def paper(cls, preset: str = "pereira2023") -> DMPCConfig:
        """The controller of a platoon preset's paper (``"pereira2023"`` or ``"pereira2022"``)."""
        if preset not in PAPER_CONFIGS:
            raise BaselineError(f"no DMPC paper configuration for preset {preset!r}; expected one of "
                                f"{sorted(PAPER_CONFIGS)}")
        return PAPER_CONFIGS[preset]

    @classmethod
    def for_scenario(cls, scenario: Any) -> DMPCConfig:
        """The paper configuration of the scenario's preset (default for other names); paper
        convex weights that do not match the number of followers become uniform."""
        cfg = PAPER_CONFIGS.get(scenario.name, cls())
        if cfg.convex_weights is not None and len(cfg.convex_weights) != scenario.n_followers:
            cfg = replace(cfg, convex_weights=None)
        return cfg

    @classmethod
    def for_env(cls, env: Any) -> DMPCConfig:
        """:meth:`for_scenario` of ``env.scenario``."""
        return cls.for_scenario(nominal(env).scenario)


PAPER_CONFIGS: dict[str, DMPCConfig] = {
    # pereira2023 Table I: N = 30, P = 25 I, sigma = 0.5 (Algorithm 1)
    "pereira2023": DMPCConfig(),
    # pereira2022 §5.1: convex step, N = 40, P on the position output, gamma = 2, w = (0.6, 0.4)
    "pereira2022": DMPCConfig(variant="convex_step", horizon=40,
                              terminal_weight=(25.0, 25.0, 25.0, 0.0, 0.0, 0.0), iterations=2,
                              convex_weights=(0.6, 0.4)),
}
"""The DMPC configuration of each platoon preset's paper (was part of the platoon scenario)."""


# ----------------------------------------------------------------------------------------------
# QP wrapper: built once, updated in place.
# ----------------------------------------------------------------------------------------------
class QPSolver:
    """``min 0.5 x'Hx + f'x  s.t.  lb <= x <= ub,  bl <= A x <= bu`` with a persistent workspace.

    ``H`` is fixed at construction; ``update`` changes ``f``, bounds and (optionally) ``A``.
    ``solve(info)`` returns the checked point or ``None`` (:meth:`solve`).
    """

    def __init__(self, H: np.ndarray, A: np.ndarray | None, lb: np.ndarray, ub: np.ndarray,
                 solver: str = "daqp", eps: float = 1e-9, time_limit: float | None = None):
        if solver not in _SOLVERS:
            raise BaselineError(f"solver must be one of {_SOLVERS}, got {solver!r}.")
        self.solver = solver
        self.time_limit = time_limit
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
        self._bl, self._bu = np.full(self.m, -1e30), np.full(self.m, 1e30)

    def update(self, f: np.ndarray, bl: np.ndarray | None = None, bu: np.ndarray | None = None,
               A: np.ndarray | None = None) -> None:
        if A is not None:
            self.A = np.ascontiguousarray(A, dtype=float)
        bl = np.full(self.m, -1e30) if bl is None else bl
        bu = np.full(self.m, 1e30) if bu is None else bu
        self._bl, self._bu = np.asarray(bl, dtype=float), np.asarray(bu, dtype=float)
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

    def solve_raw(self) -> tuple[np.ndarray, bool, str]:
        """One solve: ``(x, ok, status)`` as the solver reports them (unchecked)."""
        if self.solver == "daqp":
            x, _, flag_, _ = self._model.solve()
            self.status = int(flag_)
            ok = flag_ == 1 or flag_ == 2  # 2: soft optimal
        else:
            res = self._model.solve(raise_error=False)
            self.status = int(res.info.status_val)
            x = res.x
            ok = self.status in (1, 2)  # solved / solved inaccurate
        return x, bool(ok), f"{self.solver} {self.status}"

    def solve(self, info: dict[str, Any], fallback: bool = True) -> np.ndarray | None:
        """A guarded solve (:func:`satenv.baselines.base.guarded_solve`): the point, or ``None`` on an
        exception, a failed status, a wrong shape, a non-finite point or a point outside the box
        or the rows by more than ``QP_TOL``."""
        return guarded_solve(info, self.solve_raw, shape=(self.n,), lower=self.lb, upper=self.ub,
                             tol=QP_TOL, violation=self.row_violation, violation_tol=QP_TOL,
                             fallback=fallback, time_limit=self.time_limit)

    def row_violation(self, x: np.ndarray) -> float:
        """Largest violation of ``bl <= A x <= bu``, relative to ``max(1, |bound|)``."""
        if not self.m:
            return 0.0
        scale = np.maximum(1.0, np.minimum(np.abs(self._bl), np.abs(self._bu)))
        return row_violation((self.A @ x) / scale, self._bl / scale, self._bu / scale)


# ----------------------------------------------------------------------------------------------
# pereira2023: 1-hop DMPC
# ----------------------------------------------------------------------------------------------
def _stack_weights(scenario, config: DMPCConfig) -> tuple[np.ndarray, np.ndarray]:
    """Diagonals of calQ = diag(Q, ..., Q, P) (6N,) and calW = diag(W, ..., W) (3N,)."""
    q = np.tile(np.asarray(scenario.state_weight), config.horizon)
    q[-6:] = np.asarray(config.terminal_weight)
    w = np.tile(np.asarray(scenario.input_weight), config.horizon)
    return q, w


def centralised_gain(scenario, config: DMPCConfig | None = None,
                     topology=None) -> tuple[np.ndarray, np.ndarray]:
    """Closed form (25)-(27) of the unconstrained problem: ``U* = -K E + K_d (E_d)x lambda``.

    Returns ``(K (3N*lam, 6*lam), K_d (3N*lam, 6N*lam))`` built with Kronecker products exactly
    as in the paper (the per-agent weights alpha cancel and are not used).
    """
    topo = scenario.graph if topology is None else topology
    config = DMPCConfig.for_scenario(scenario) if config is None else config
    a, b = cw_matrices(scenario.mean_motion, scenario.dt)
    ca, cb = prediction_matrices(a, b, config.horizon)
    q, w = _stack_weights(scenario, config)
    btq = cb.T * q[None, :]
    gd = topo.G + topo.D
    s = np.kron(gd @ topo.augmented_laplacian, btq @ cb) + np.kron(np.eye(topo.n_followers), np.diag(w))
    k = np.linalg.solve(s, np.kron(gd, btq @ ca))
    kd = np.linalg.solve(s, np.kron(gd @ gd, btq))
    return k, kd


class OneHopDMPC:
    """The pereira2023 1-hop DMPC on follower states (no env needed).

    Args:
        scenario: a :class:`satenv.scenarios.platoon.PlatoonScenario` (model, weights Q, W,
            alpha, limits).
        config: a :class:`DMPCConfig` (default: :meth:`DMPCConfig.for_scenario`); ``**options``
            replace its fields (``horizon``, ``sigma``, ``max_iterations``, ``constrained``,
            ``min_error_constraint``, ``velocity_constraint``, ``solver``, ``warm_start``,
            ``initial``, ``seed``).
        topology: override the scenario's graph (a ``satenv.graph.Topology``).

    ``info``: ``fallbacks`` (QP failures: the agent keeps its previous iterate; a non-finite
    plan: zero thrust), ``solver_status``, ``not_converged`` (decisions that hit
    ``max_iterations``).
    """

    def __init__(self, scenario, config: DMPCConfig | None = None, *, topology=None,
                 **options: Any):
        base = DMPCConfig.for_scenario(scenario) if config is None else config
        self.cfg = cfg = config_from_options(DMPCConfig, options, "DMPC", base=base)
        self.scenario = scenario
        self.topology = scenario.graph if topology is None else topology
        self.horizon = cfg.horizon
        self.constrained = cfg.constrained
        self.min_error = bool(scenario.min_error_constraint if cfg.min_error_constraint is None
                              else cfg.min_error_constraint) and self.constrained
        self.velocity = cfg.velocity_constraint and self.constrained
        self.solver = cfg.solver
        self.sigma = cfg.sigma
        self.max_iterations = cfg.max_iterations
        self.per_agent = cfg.stopping == "per_agent"
        self.warm_start = cfg.warm_start
        self.initial = cfg.initial
        self._seed = cfg.seed
        self._build()
        self.reset(cfg.seed)

    # -- construction (once) ------------------------------------------------------------------
    def _build(self) -> None:
        sc, topo = self.scenario, self.topology
        hz = self.horizon
        self.nu = 3 * hz
        a, b = cw_matrices(sc.mean_motion, sc.dt)
        self.A, self.B = a, b
        ca, cb = prediction_matrices(a, b, hz)
        q, w = _stack_weights(sc, self.cfg)
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
                self.qps.append(QPSolver(self.H[f], amat, lb, ub, solver=self.solver,
                                         time_limit=self.cfg.solve_time_limit))

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self._seed = seed
        self.rng = np.random.default_rng(self._seed)
        self.U: np.ndarray | None = None
        self.info = new_info(not_converged=0)
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

    def _local_constrained(self, err, su, u_prev, rows_a, active) -> np.ndarray:
        sc = self.scenario
        f_lin = (np.einsum("fij,fj->fi", self.M1, err) - np.einsum("fij,fj->fi", self.M2, su)
                 - self.m3)
        out = u_prev.copy()
        for f in np.flatnonzero(active):
            bl, bu = [], []
            if self.velocity:
                off = self.ca_v @ err[f] - self.cb_v @ su[f]
                lim = self.c[f] * sc.v_max - self.cfg.velocity_margin
                bl.append(-lim - off)
                bu.append(lim - off)
            if self.min_error:
                nvec, ok = rows_a[f]
                off_p = (self.ca_p @ err[f] - self.cb_p @ su[f]).reshape(-1, 3) @ nvec
                bl.append(self.c[f] * sc.follower_radius - off_p if ok
                          else np.full(self.horizon, -1e30))
                bu.append(np.full(self.horizon, 1e30))
            qp = self.qps[f]
            amat = None
            if self.min_error:
                amat = qp.A.copy()
                amat[-self.horizon:] = self.c[f] * np.einsum(
                    "c,kcj->kj", nvec, self.cb_p.reshape(self.horizon, 3, self.nu))
            t0 = time.perf_counter()
            qp.update(f_lin[f], np.concatenate(bl) if bl else None,
                      np.concatenate(bu) if bu else None, A=amat)
            x = qp.solve(self.info)
            self.qp_ms.append(1e3 * (time.perf_counter() - t0))
            # failure: keep the previous iterate (input-feasible)
            out[f] = np.clip(u_prev[f] if x is None else x, -self.u_max, self.u_max)
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
        active = np.ones(self.topology.n_followers, dtype=bool)
        it = 0
        while it < self.max_iterations and active.any():
            it += 1
            su = self.adj @ u
            if self.constrained:
                new = self._local_constrained(err, su, u, rows_a, active)
            else:
                new = self._local_unconstrained(err, su)
            delta = np.linalg.norm(new - u, axis=1)
            u = np.where(active[:, None], new, u)
            if self.per_agent:   # Algorithm 1: each agent stops on its own (line 15)
                active &= delta > self.sigma
            elif delta.max() <= self.sigma:
                active[:] = False
        self.iterations.append(it)
        if active.any():
            self.info["not_converged"] += 1
        if not np.all(np.isfinite(u)):
            record_fallback(self.info, "non-finite plan")
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
        scenario: a PlatoonScenario (uses ``keepout_*``, ``los_slopes``, ``port``, the weights;
            Q/P weight the pair states, usually positions only).
        config: a :class:`DMPCConfig` (default: :meth:`DMPCConfig.for_scenario`); ``**options``
            replace its fields (``horizon``, ``terminal_weight``, ``iterations``,
            ``convex_weights``, ``constrained``, ``coupled_constraints``, ``solver``).

    ``coupled_constraints=True`` makes agent j impose the constraints of every pair its input
    moves (pairs j and j+1, the joint problem of eq. 29); False (default) only those of its own
    pair j (it chases follower j-1). With the shifted warm start the coupled problems became
    infeasible within ~2 s on the §5.1 scenario (agent j cannot keep both pairs feasible against
    the other agents' stale plans), hence the default.

    When an agent's state-constrained QP fails it falls back to its input-box-only QP (counted in
    ``info["fallbacks"]``); if that fails too it keeps its previous iterate (counted again).
    """

    def __init__(self, scenario, config: DMPCConfig | None = None, **options: Any):
        base = DMPCConfig.for_scenario(scenario) if config is None else config
        self.cfg = cfg = config_from_options(DMPCConfig, options, "DMPC", base=base)
        self.scenario = scenario
        self.solver = cfg.solver
        self.horizon = cfg.horizon
        m = scenario.n_followers
        self.n_iter = cfg.iterations
        w = np.asarray(cfg.convex_weights or (1.0 / m,) * m, dtype=float)
        if w.shape != (m,):
            raise BaselineError(f"DMPC option convex_weights must have {m} entries (one per "
                                f"follower) that sum to 1, got {cfg.convex_weights}")
        self.w = w
        self.constrained = cfg.constrained
        self.coupled = cfg.coupled_constraints
        self._build()
        self.reset(cfg.seed)

    def _n_rows_pair(self) -> int:
        sc, hz = self.scenario, self.horizon
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
        hz, m = self.horizon, sc.n_followers
        self.nu = 3 * hz
        a, b = cw_matrices(sc.mean_motion, sc.dt)
        self.A, self.B = a, b
        ca, cb = prediction_matrices(a, b, hz)
        self.ca, self.cb = ca, cb
        q, w = _stack_weights(sc, self.cfg)
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
            self.qps.append(QPSolver(self.H[j], amat, lb, ub, solver=self.solver,
                                     time_limit=self.cfg.solve_time_limit))
            self.box_qps.append(QPSolver(self.H[j], None, lb, ub, solver=self.solver,
                                         time_limit=self.cfg.solve_time_limit) if rows else None)

    def reset(self, seed: int | None = None) -> None:
        self.U: np.ndarray | None = None
        self.info = new_info(not_converged=0)
        self.iterations: list[int] = []
        self.qp_ms: list[float] = []

    def _pair_rows(self, z0: np.ndarray, offset: np.ndarray, sign: float, margin: float = 0.0,
                   los: bool = True):
        """Rows ``G U_j in [lo, hi]`` of the constraints on one pair whose prediction is
        ``Z = offset + sign * calB U_j`` (offset includes calA z0 and the other agents);
        ``margin`` [m] is added to the keep-out radius, ``los=False`` leaves out the LOS cone
        (both for ``satenv.baselines.experts.JointPlatoonMPC``)."""
        sc, hz = self.scenario, self.horizon
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
            p_o = center + (sc.keepout_radius + margin) * nvec  # eq. 32-33: tangent plane at p_o
            g_rows.append(np.einsum("c,kcj->kj", nvec, cbp))
            lo.append(nvec @ p_o - off_p @ nvec)
            hi.append(np.full(hz, 1e30))
        if los and sc.los_slopes is not None:
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
                sol = qp.solve(self.info)
                if sol is None and self.box_qps[j] is not None:
                    self.box_qps[j].update(f_lin)
                    sol = self.box_qps[j].solve(self.info)
                self.qp_ms.append(1e3 * (time.perf_counter() - t0))
                # failure: keep the previous iterate (input-feasible)
                ustar[j] = np.clip(u[j] if sol is None else sol, -self.u_max, self.u_max)
            u = self.w[:, None] * ustar + (1 - self.w[:, None]) * u
        self.iterations.append(self.n_iter)
        if not np.all(np.isfinite(u)):
            record_fallback(self.info, "non-finite plan")
            self.U = None
            return np.zeros((m, 3))
        self.U = u
        return u[:, :3].copy()


# ----------------------------------------------------------------------------------------------
# Policy wrapper
# ----------------------------------------------------------------------------------------------
class DMPC(Baseline):
    """Distributed MPC policy for ``satenv.platoon_v0`` (see the module docstring).

    Privileged: it reads the env's true follower states (``env.state()``), its scenario and
    topology, not the observations.

    Args:
        env: the platoon env.
        config: a :class:`DMPCConfig` (default: :meth:`DMPCConfig.for_env`, the paper's
            controller of the env's preset); ``**options`` replace its fields, e.g.
            ``DMPC(env, variant="convex_step", solver="osqp")``. Unknown options raise
            :class:`satenv.baselines.BaselineError`.

    Safe actions: a failed QP keeps the agent's previous iterate (the shifted previous plan,
    always input-feasible); a non-finite plan or an exception in the decision applies zero
    thrust. Both count in ``info["fallbacks"]``; ``info["solver_status"]`` says why.
    """

    name = "dmpc"
    env_ids = ("platoon_v0",)

    def __init__(self, env, config: DMPCConfig | None = None, **options: Any):
        check_env(type(self), env)
        scenario = nominal(env).scenario
        base = DMPCConfig.for_env(env) if config is None else config
        self.cfg = config_from_options(DMPCConfig, options, "DMPC", base=base)
        self.env = env
        self.variant = self.cfg.variant
        if self.variant == "one_hop":
            self.core = OneHopDMPC(scenario, self.cfg, topology=getattr(env, "topology", None))
        else:
            self.core = ConvexStepDMPC(scenario, self.cfg)
        self.agents = [f"follower_{i + 1}" for i in range(scenario.n_followers)]
        self.u_max = float(scenario.u_max)
        self.info: dict = {}
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.core.reset(seed)
        self._solve_ms: list[float] = []
        self._refresh_info()

    def _refresh_info(self) -> None:
        self.info = {**self.core.info, "solve_ms": self._solve_ms, "qp_ms": self.core.qp_ms,
                     "iterations": self.core.iterations}

    def _states(self) -> np.ndarray:
        n = len(self.agents)
        s = np.asarray(self.env.state(), dtype=float).ravel()
        if s.size < 6 * n:
            raise BaselineError(f"env.state() has {s.size} entries, expected at least {6 * n}.")
        return s[: 6 * n].reshape(n, 6)

    def act(self, observations: dict) -> dict:
        t0 = time.perf_counter()
        x = self._states()
        try:
            u = self.core.solve(x)
        except (np.linalg.LinAlgError, ValueError, RuntimeError, ArithmeticError) as exc:
            record_fallback(self.core.info, f"error: {type(exc).__name__}: {exc}")
            self.core.U = None
            u = np.zeros((len(self.agents), 3))
        a = np.clip(u / self.u_max, -1.0, 1.0).astype(np.float32)
        self._solve_ms.append(1e3 * (time.perf_counter() - t0))
        self._refresh_info()
        return {name: a[i] for i, name in enumerate(self.agents) if name in observations}
