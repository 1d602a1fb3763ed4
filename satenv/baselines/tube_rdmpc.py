"""Tube-based robust distributed MPC for satellite-cluster reconfiguration (li2022 §3.1–3.2).

``TubeRDMPC(env, config=None, **options)`` (:class:`TubeRDMPCConfig`) controls ``satenv.cluster_v0``. It has two layers:

* **Nominal DMPC** (one NLP per satellite every decision period Δt = 5 s, horizon
  ``T_p = 50 s``, N = 10 steps): cost (27)–(28)
  ``sum_{m=0}^{N-1} alpha ||q~_m - q_d||^2 + beta ||F_m||^2 + gamma lambda_m^2`` with the nominal
  thrust ``F = m u~`` in newtons (li2022 calls u a control *force*), the Lyapunov-decrease
  constraint ``V_{m+1} - V_m <= -(sigma - lambda_m) V_m`` with ``V = alpha ||q~ - q_d||^2`` and
  ``0 <= lambda_m <= sigma``, thrust ``||u~_m|| <= u_max - kappa_bar`` (U ⊖ sup κ), collision
  constraints against the neighbours' predicted trajectories tightened by the tube (34),
  obstacle (36) and target-spacecraft keep-outs tightened by ε̄, and the terminal set (38) with
  the terminal controller ρ = 0 (39). Neighbours exchange the predictions (29)–(30): at t_k
  satellite i uses ``ζ*_j(t_k + mΔt | t_{k-1})`` (m < N) and the ρ = 0 coast for m = N; all
  satellites solve in parallel (Jacobi) from the previous exchange.
* **Tube controller** κ (13) with ``k1 = 2``, ``k2 = 4``, running at the env's physics rate on
  the state the env's inner-loop hook gives it (``env.set_inner_loop``: the truth, or under
  navigation error the estimate, ``satenv.perturbations``): ``u = u~ + κ``,
  ``κ = -(f(x) - f(x~)) - (1 + k1) ε - (k1 + k2) ε̇``, ``ε = q - q~``; the nominal state ``x~`` is
  propagated by the controller with ``u~``.

Prediction / nominal model: the exact zero-order-hold Clohessy–Wiltshire model of
``satenv.dynamics`` for the chief's mean motion (li2022 integrates its J2 + drag nominal model
(5)). Over the cluster's few kilometres the J2 / drag / nonlinear terms differ from CW by about
1e-5 m/s^2 (measured: 9.8e-6 m/s^2 at 1.7 km), 0.5 % of the disturbance the tube rejects and
0.06 % of the thrust: they change the predicted 50 s trajectory by ~1 cm, so the plans are the
same for practical purposes; the difference enters ε like a disturbance and is covered by
``model_error_bound`` in the tube radius. ``f`` in κ is the same CW model (so
``f(x) - f(x~) = A_c (x - x~)`` exactly).

Choices and deviations (documented; each is an option):

* ``v_max = 2.5 m/s``: the state constraint set Ξ_i of (36), which li2022 leaves unspecified, is
  a speed bound ``||p~_m|| <= v_max``. Without it the DMPC (whose 50 s horizon sees only ~20 m
  of lateral manoeuvre at 0.016 m/s^2) reaches 4-5 m/s, the moving obstacle then deflects the
  fastest satellites, which circle their targets at ~500 m for many minutes (measured on case 1:
  2 of 10 satellites not converged after 2000 s with ``v_max=None``; all within 1 m after about
  1100 s with 2.5 m/s).
* ``terminal_braking=True`` adds stopping-distance terminal rows: ``||p_N||^2 <= 2 a_b
  ||q_N - q_d||`` (able to stop before the target) and, for the obstacle, the target spacecraft
  and every neighbour, closing speed ``v_c`` with ``v_c |v_c| <= 2 a_b (d_N - d_safe)``
  (``a_b = braking_fraction (u_max - kappa_bar)``). li2022's terminal set (38) with ρ = 0 only
  guarantees one more safe Δt of coasting; with 0.02 m/s^2 of thrust a satellite closing at a few
  m/s needs minutes to stop, so (38) alone lets it run into states from which the Lyapunov and
  keep-out constraints are infeasible.
* ``safety_margin = 5 m`` is added to every keep-out distance: the Jacobi exchange plans against
  the neighbours' *previous* predictions while they re-plan at the same time.
* :meth:`TubeRDMPCConfig.published` drops the two additions above (``v_max=None``,
  ``terminal_braking=False``); li2022 as published also drops ``safety_margin``,
  ``lyapunov_tolerance`` and the relaxed NLP and re-allocates at every decision (Step 4, the env's
  ``reallocate_every=1``): ``satenv/bench/reproductions/li2022.py`` runs it beside ours.
* Infeasibility: every ipopt solve goes through :func:`satenv.baselines.base.guarded_solve` (an
  exception, a failed status, a wrong-shaped or non-finite point, a variable outside its bounds or
  a constraint row violated by more than ``NLP_CONSTRAINT_TOL`` is a failure; why:
  ``info["solver_status"]``). When the exact NLP fails, a relaxed NLP is solved (λ unbounded above,
  collision rows softened by an L1 slack of weight 1e9, terminal / speed rows by one of weight
  1e8); if that fails too, the previous plan shifted with ρ = 0 appended (li2022's candidate (29))
  is applied, or a braking input once that plan is exhausted. Both are counted
  (``info["relaxed"]``, ``info["fallbacks"]``), never raised.
* ``lyapunov_tolerance`` (1e-4 m^2) is added to the right-hand side of the Lyapunov rows so the
  nominal can hold a target it has reached to within ipopt's tolerance. It sets the accuracy
  floor: with λ = 0 the rows allow ``V <= tol / σ``, and because β prices the 0.02–0.09 N holding
  thrust far above a few cm of tracking error, the converged nominal drifts at
  ``sqrt(tol / σ) = 2.2 cm`` from its target (measured 0.0227 m including the tube error).

Tube radius (15): ``ε̄ = sqrt(eta / k1) w̄`` with ``w̄ = sup ||w|| + model_error_bound``;
``eta = 1`` by default (Theorem 1 allows any ``eta >= 1 / (4 k2)``; note that for the κ of (13)
the exact worst case is ``sup ||ε|| = w̄ / (1 + k1)`` — the closed loop
``ε'' + (k1 + k2) ε' + (1 + k1) ε = w`` has a non-negative impulse response — which exceeds
(15) for ``eta < (k1 / (1 + k1)^2) = 0.22``; ``satenv/bench/reproductions/li2022.py`` measures it).

Solver: CasADi + ipopt (MUMPS), NLPs built once per process and config
(:func:`satenv.baselines.base.nlpsol_cached`), one per neighbour-slot count of :func:`slot_sizes`
(``N_a + 1``, ``2 N_a``, ``4 N_a`` and ``M - 1`` for the symmetric ``N_a``-nearest graph): each
satellite solves the smallest that holds its neighbours (the rows of an unused slot, parked at
100 km, are inactive: the same optimum, first controls within 1e-6 of the all-slot NLP,
``tests/test_tube_rdmpc.py``; 1.4x faster at li2022's 4-5 neighbours of 9, and a 64-satellite
swarm solves 5-16-slot NLPs instead of 63). Warm-started per satellite from its shifted previous
solution and (``warm_duals``, default) its previous multipliers: about 6 ipopt iterations instead
of 13, the same optimum (objective within 1e-10 relative on recorded li2022 problems;
``tests/test_fast_solvers.py``). ``solver="ipopt-jit"`` compiles its functions with gcc.
``exact_max_iter`` caps the exact NLP's iterations (the relaxed one keeps ``max_iter``). li2022
names no solver; ipopt (every NLP solved to convergence) is the reference and the reproduction's
(``satenv/bench/reproductions/li2022.py``).

Sequential convexification (``solver="rti"``): QPs instead of the NLP, about each satellite's
previous plan shifted by one step (:meth:`_NominalNLP.qp_step`). Every row of the exact NLP is
linearised there (collision, obstacle and target keep-outs become tangent half-spaces, inside their
feasible sets; the Lyapunov, terminal and braking rows their first-order models; the convex thrust
ball and speed bound their supporting half-spaces at the nearest point of their sphere), the slacks
stay at zero, and the Hessian is the cost's exact (constant) one plus the convex rows' curvature
weighted by their multipliers of the satellite's last QP (moved one stage on): the Hessian of the
Lagrangian but for the nonconvex rows. Without that curvature the QP sees the thrust ball and the
speed bound as planes and slides along them, and the plans end up away from the NLP's optimum along
its flat directions (+3 to +5 % delta-v against ipopt in closed loop on li2022 case 1). Every row
the QP's point violates also gets its linearisation there, kept beside the first, and the QP is
solved again (``CUT_ROUNDS``); the inputs are then scaled onto the ball. The point is used only if
the exact NLP's own rows hold at it to ``NLP_CONSTRAINT_TOL``; else the QP is re-linearised there
(``SQP_ITERATIONS`` in all), and if they still do not hold, or a QP fails, the exact ipopt NLP solves
the decision (``info["rti_fallbacks"]``, ``info["solver_failures"]``), then the relaxed NLP and the
shifted plan as before. DAQP solves the QPs, each satellite's starting from the active set of its
previous one. The first decision after a reset is an ipopt solve; ``info["qp_steps"]`` counts the
QP decisions. At the exact NLP's optimum the step is zero (``tests/test_tube_rdmpc_rti.py``). On
li2022 case 1, 16 of 4000 satellite decisions go to ipopt (ones where the exact NLP is infeasible,
and the relaxed NLP follows), and the closed loop is within 2 % of ipopt's
(``satenv.bench.perf.experts.closed_loop_vs_ipopt``).
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, fields
from functools import partial
from typing import Any

import numpy as np

from satenv.baselines._qp import QP_INFINITY, QP_ROW_TOL, BufferedFunction, DenseQP, linearisation
from satenv.baselines.base import (
    JIT_OPTIONS,
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
    nlpsol_cached,
    number,
    record_fallback,
    row_violation,
    time_limit,
    validate,
)
from satenv.cluster_graph import nearest_neighbour_graph
from satenv.dynamics import cw_continuous, cw_matrices, prediction_matrices
from satenv.perturbations import nominal

__all__ = ["TubeController", "TubeRDMPC", "TubeRDMPCConfig", "slot_sizes"]

_FAR = 1.0e5  # [m] position of an unused neighbour slot (its constraints are inactive)
_SLACK_WEIGHT = 1.0e9           # L1 weight of the collision slacks (relaxed problem only)
_TERMINAL_SLACK_WEIGHT = 1.0e8  # L1 weight of the terminal / speed slack (relaxed problem only)
NLP_CONSTRAINT_TOL = 1e-2       # largest accepted row violation (ipopt's acceptable_constr_viol_tol)
SOLVERS = ("ipopt-jit", "ipopt", "rti")
SQP_ITERATIONS = 3
"""QPs of one ``solver="rti"`` decision at most (re-linearised at the last point while the exact
NLP's rows are violated there), before the ipopt fallback."""
CUT_ROUNDS = 4
"""QPs of one sequential-convexification step at most: the first, then with cutting planes of the
convex rows added where the point violated them."""
CUT_TOL = 1e-3
"""Violation of a convex row (thrust ball, speed bound) accepted without a cut."""
MAX_WORKERS = 16
WARM_DUAL_OPTIONS = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                     "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6}
"""ipopt options of ``warm_duals``: start from the given point and multipliers, near the central path."""


@dataclass(frozen=True)
class TubeRDMPCConfig:
    """Options of :class:`TubeRDMPC` (li2022 §4 values by default).

    Args:
        horizon: T_p [s] (N = T_p / Δt steps).
        alpha, beta, gamma: cost weights (28); sigma: the Lyapunov rate bound σ.
        k1, k2: tube-controller gains (13); eta: η of (15) (see the module docstring).
        model_error_bound: bound on ``||f_truth - f_CW||`` added to w̄ [m/s^2].
        kappa_margin: κ̄ = kappa_margin * w̄ is reserved from the thrust for the tube controller.
        terminal_braking, braking_fraction: the stopping-distance terminal constraints.
        v_max: speed bound [m/s] of the state set Ξ_i (None: no bound).
        safety_margin: [m] added to every keep-out distance (Jacobi-update margin).
        lyapunov_tolerance: [m^2] added to the Lyapunov rows.
        relax_on_failure: solve the relaxed NLP when the exact one fails.
        tube: run the tube controller κ (False: nominal DMPC applied open loop to the truth).
        max_iter, tol: ipopt iteration limit and tolerance.
        exact_max_iter: a lower iteration limit for the exact NLP only (None: ``max_iter``). A
            failed exact solve is followed by the relaxed one, and most failures run to the
            limit: li2022's as-published episodes spend about 82 % of their time in them, while no
            exact solve that succeeded took over 50 iterations (12 000 solves of three li2022
            episodes). Above that, the same decisions in less time.
        warm_duals: also warm-start ipopt's multipliers (``warm_start_init_point``, ``mu_init``
            1e-4) from the satellite's previous exact solve; about half the iterations, the same
            optimum (``tests/test_fast_solvers.py``). False: the primal warm start only.
        workers: threads that solve the satellites' exact NLPs of one decision in parallel (they
            are independent: each plans against the others' previous plans), each with its own
            solver copy (``ipopt-jit`` compiles one per thread); the same points as ``workers=1``.
        solver: ``"ipopt"`` (default, the reference), ``"ipopt-jit"`` or ``"rti"``. ``"ipopt-jit"``: the
            same NLP and ipopt options on gcc-compiled problem functions (the same iterates to round-off), compiled
            once per process and config (about 20-50 s of gcc on 2 cores). Not the default: with
            ``warm_duals`` (the default, most of the fast path's gain) it saves only ~10 % a solve
            (10.7 against 11.9 ms on recorded li2022 problems, ``satenv.bench.perf --sections
            fast_solvers``), so its 28 s compile pays back after ~2e4 solves, about ten li2022
            episodes in one process.
            ``"rti"``: one DAQP QP per satellite and decision, the NLP linearised about the shifted
            previous plan (module docstring), ipopt for the first decision and as the fallback.
        solve_time_limit: wall-time limit [s] of one NLP solve (None: none); a solve over it is a
            flagged failure like any other (``satenv.baselines.base.guarded_solve``): a stall guard (the
            median solve is 10-30 ms); ipopt's own ``max_wall_time`` is set to it.
    """

    horizon: float = 50.0
    alpha: float = 1.0
    beta: float = 200.0
    gamma: float = 500.0
    sigma: float = 0.2
    k1: float = 2.0
    k2: float = 4.0
    eta: float = 1.0
    model_error_bound: float = 5e-5
    kappa_margin: float = 1.1
    terminal_braking: bool = True
    braking_fraction: float = 0.5
    v_max: float | None = 2.5
    safety_margin: float = 5.0
    lyapunov_tolerance: float = 1e-4
    relax_on_failure: bool = True
    tube: bool = True
    max_iter: int = 150
    exact_max_iter: int | None = None
    tol: float = 1e-6
    warm_duals: bool = True
    workers: int = 1
    solver: str = "ipopt"
    solve_time_limit: float | None = 30.0

    def __post_init__(self) -> None:
        zero_ok = ("beta", "gamma", "model_error_bound", "lyapunov_tolerance", "safety_margin")
        rules: dict[str, Any] = {}
        for f in fields(self):
            if f.name in ("terminal_braking", "relax_on_failure", "tube", "warm_duals"):
                rules[f.name] = flag
            elif f.name == "solver":
                rules[f.name] = partial(choice, choices=SOLVERS)
            elif f.name == "solve_time_limit":
                rules[f.name] = time_limit
            elif f.name not in ("v_max", "exact_max_iter") or getattr(self, f.name) is not None:
                rules[f.name] = partial(number, zero_ok=f.name in zero_ok)
        rules["max_iter"] = integer
        if self.exact_max_iter is not None:
            rules["exact_max_iter"] = integer
        rules["workers"] = partial(integer, high=MAX_WORKERS)
        rules["sigma"] = partial(number, high=0.999999)
        rules["horizon"] = partial(number, high=math.inf)  # capped in decision periods by TubeRDMPC
        rules["braking_fraction"] = partial(number, high=1.0)
        validate(self, "TubeRDMPC", rules)
        if self.k2 < 1.0 / (4.0 * self.eta):
            raise BaselineError(f"TubeRDMPC: Theorem 1 needs k2 >= 1 / (4 eta): k2 = {self.k2}, "
                                f"eta = {self.eta}")

    @classmethod
    def published(cls, **options: Any) -> TubeRDMPCConfig:
        """li2022 as published: no speed bound (Ξ_i unspecified) and only the terminal set (38).

        Our other choices (``safety_margin``, ``lyapunov_tolerance``, the relaxed NLP) stay as
        options. The paper's Step 4 re-allocation at every decision is the env's, not the
        controller's: ``satenv.make("cluster_v0", ..., reallocate_every=1)``.
        """
        return config_from_options(cls, options, "TubeRDMPC",
                                   base=cls(v_max=None, terminal_braking=False))


class TubeController:
    """The auxiliary controller κ of li2022 eq. (13) around a CW nominal state (env inner loop).

    The env calls :meth:`correction` at every physics step; the controller returns κ and
    advances its nominal state ``x~`` with the commanded nominal input over the physics step.
    It records ``||ε||`` and ``u~ + κ`` at every physics step.
    """

    def __init__(self, n: float, physics_dt: float, k1: float, k2: float) -> None:
        self.a_h, self.b_h = cw_matrices(n, physics_dt)
        self.f_rows = cw_continuous(n)[0][3:, :]      # CW acceleration rows: f(x) = f_rows @ x
        self.h = float(physics_dt)
        self.k1, self.k2 = float(k1), float(k2)
        self.enabled = True
        self.nominal: np.ndarray | None = None
        self.t: float | None = None
        self.eps: list[np.ndarray] = []     # per physics step (M,) ||q - q~|| [m]
        self.u_total: list[np.ndarray] = []  # per physics step (M, 3) u~ + κ (before saturation)
        self.kappa: list[np.ndarray] = []   # per physics step (M, 3) κ
        self.stats: dict[str, Any] = {}     # receives "tube_error_max_m" (the policy's info)

    def sync(self, x: np.ndarray, t: float) -> None:
        """Start the nominal at the true state ``x`` (M, 6) at time ``t`` (ε = 0)."""
        self.nominal = np.array(x, dtype=float)
        self.t = float(t)

    def kappa_of(self, x: np.ndarray, nominal: np.ndarray) -> np.ndarray:
        """κ (M, 3) for true states ``x`` and nominal states ``nominal`` (M, 6)."""
        e = x - nominal
        return -(e @ self.f_rows.T) - (1.0 + self.k1) * e[:, :3] - (self.k1 + self.k2) * e[:, 3:]

    def correction(self, t, x, chief, u_cmd) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape[0] != 1:
            raise ValueError(f"TubeController drives one env copy, got a batch of {x.shape[0]}")
        if self.nominal is None:
            self.sync(x[0], float(np.asarray(t).ravel()[0]))
        u_cmd = np.asarray(u_cmd, dtype=float)[0]
        kappa = self.kappa_of(x[0], self.nominal) if self.enabled else np.zeros_like(u_cmd)
        eps = np.linalg.norm(x[0, :, :3] - self.nominal[:, :3], axis=-1)
        self.eps.append(eps)
        self.stats["tube_error_max_m"] = max(float(self.stats.get("tube_error_max_m", 0.0)),
                                             float(eps.max()))
        self.kappa.append(kappa)
        self.u_total.append(u_cmd + kappa)
        self.nominal = self.nominal @ self.a_h.T + u_cmd @ self.b_h.T
        self.t = float(np.asarray(t).ravel()[0]) + self.h
        return kappa[None]


def _support(g: np.ndarray) -> np.ndarray:
    """Right-hand sides ``J dw <= 2 rho (1 - rho)`` of the tangent planes of convex rows
    ``g = |y|^2 / r^2 - 1 <= 0`` (``y`` affine in ``w``, ``J`` their Jacobian at ``w``) at the
    point ``r y / |y|`` of the sphere, ``rho = |y| / r``: the supporting half-space of the ball,
    tighter than the linearisation at ``y`` (``J dw <= -g``) and the same where the row is active."""
    rho = np.sqrt(np.maximum(g + 1.0, 0.0))
    return 2.0 * rho * (1.0 - rho)


def slot_sizes(m: int, n_nearest: int) -> tuple[int, ...]:
    """Neighbour-slot counts of the tube-RDMPC NLPs for ``m`` satellites on the symmetric
    ``n_nearest``-nearest graph (ascending; the last holds every other satellite): most satellites
    have ``n_nearest`` to ``2 n_nearest`` neighbours, so the NLP stays that size in any swarm."""
    top = max(m - 1, 1)
    return tuple(sorted({min(top, max(1, v)) for v in (n_nearest + 1, 2 * n_nearest, 4 * n_nearest)} | {top}))


class _NominalNLP:
    """The nominal DMPC problem (36)+(38) of one satellite as CasADi/ipopt solvers, one per
    neighbour-slot count K of ``slot_sizes`` (a satellite uses the smallest that holds its
    neighbours: the unused slots' rows would only enlarge ipopt's linear systems).

    Decision variables ``w = [v (3N), lambda (N), s (N), s_t (1)]``: the inputs scaled to the
    unit ball (``u~ = u_nom v``), the slack of the Lyapunov rows, and two slacks that are fixed
    at zero in the exact problem and free (L1-penalised) in the relaxed one: ``s_m`` softens the
    collision rows of step m, ``s_t`` the terminal Lyapunov (38e), braking and velocity rows.
    Parameters ``p = [x0, q_d, neighbour positions (K, N + 1, 3), neighbour terminal coast
    displacements (K, 3), neighbour terminal velocities (K, 3), obstacle positions (N + 2, 3),
    obstacle velocity (3), q_r]``.
    """

    def __init__(self, cfg: TubeRDMPCConfig, n: float, dt: float, horizon: int, slot_sizes: tuple[int, ...],
                 u_nom: float, mass: float, r_pair: float, r_obs: float, r_tgt: float) -> None:
        self.N, self.slot_sizes, self.K = horizon, tuple(slot_sizes), max(slot_sizes)
        self.cfg, self.u_nom = cfg, u_nom
        self._constants = (n, dt, horizon)
        self._radii = (u_nom, mass, r_pair, r_obs, r_tgt)
        a, b = cw_matrices(n, dt)
        self.cal_a, self.cal_b = prediction_matrices(a, b, horizon)
        self.n_w = 5 * horizon + 1
        self.sigma = cfg.sigma
        self._qp = DenseQP()
        self._mu: dict[int, np.ndarray] = {}          # owner -> multipliers of its convex rows
        self.curvature = self._convex_hessians()
        self._buffers: dict[tuple, BufferedFunction] = {}
        self._fixed = 15 + 3 * (horizon + 2)          # parameter entries that are not per slot
        self._per_slot = 3 * (horizon + 1) + 6

    def forget(self) -> None:
        """Start every satellite's next QP cold, without multipliers of the convex rows (a new episode)."""
        self._mu.clear()
        self._qp.forget()

    def slots(self, params: np.ndarray) -> int:
        """The neighbour-slot count K of a parameter vector (its length: the layout above)."""
        return (params.size - self._fixed) // self._per_slot

    def slots_for(self, degree: int) -> int:
        """The smallest built slot count that holds ``degree`` neighbours."""
        return next(k for k in self.slot_sizes if k >= degree)

    def _built(self, k: int, relaxed: bool, copy: int) -> tuple[Any, np.ndarray, np.ndarray]:
        cfg = self.cfg
        max_iter = cfg.max_iter if relaxed else (cfg.exact_max_iter or cfg.max_iter)
        args = (cfg, *self._constants, k, *self._radii)
        copy = 0 if relaxed else copy
        return nlpsol_cached(("tube_rdmpc", *args, max_iter, copy), lambda: self._build(*args, max_iter=max_iter))

    def prepare(self, slots: list[int] | None = None, copies: int = 1) -> None:
        """Build (compile, for ``ipopt-jit``) the solvers of these slot counts (all when None) and
        worker copies now: CasADi builds are not thread-safe and a compile is slow."""
        for k in sorted(set(self.slot_sizes if slots is None else slots)):
            for copy in range(copies):
                self._built(k, False, copy)
                if self.cfg.solver == "rti":
                    self._buffered("lin", k, copy)
                    self._buffered("rows", k, copy)
            self._built(k, True, 0)

    def solver_for(self, k: int, copy: int = 0, relaxed: bool = False) -> Any:
        """The CasADi solver of the NLP with ``k`` neighbour slots: worker ``copy``'s for the
        exact NLP, or the relaxed one's (its own iteration limit when ``exact_max_iter`` is set)."""
        return self._built(k, relaxed, copy)[0]

    def row_bounds(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(lbg, ubg)`` of the NLP with ``k`` neighbour slots."""
        return self._built(k, False, 0)[1:]

    @property
    def solver(self) -> Any:
        """The exact solver with every slot (``K``), copy 0."""
        return self.solver_for(self.K)

    @staticmethod
    def _problem(cfg: TubeRDMPCConfig, n: float, dt: float, horizon: int, k_slots: int, u_nom: float,
                 mass: float, r_pair: float, r_obs: float, r_tgt: float) -> tuple[dict, list, list]:
        """The CasADi NLP ``{"x", "p", "f", "g"}`` with ``k_slots`` neighbour slots and its row
        bounds ``(lbg, ubg)``."""
        import casadi as ca

        a, b = cw_matrices(n, dt)
        cal_a, cal_b = prediction_matrices(a, b, horizon)
        N, K = horizon, k_slots
        v = ca.SX.sym("v", 3 * N)
        lam = ca.SX.sym("lam", N)
        s = ca.SX.sym("s", N)
        s_t = ca.SX.sym("s_t", 1)
        x0 = ca.SX.sym("x0", 6)
        qd = ca.SX.sym("qd", 3)
        qn = ca.SX.sym("qn", 3 * (N + 1) * K)
        dn = ca.SX.sym("dn", 3 * K)
        pn = ca.SX.sym("pn", 3 * K)
        qo = ca.SX.sym("qo", 3 * (N + 2))
        po = ca.SX.sym("po", 3)
        qr = ca.SX.sym("qr", 3)
        u = u_nom * v
        xs = ca.mtimes(ca.DM(cal_a), x0) + ca.mtimes(ca.DM(cal_b), u)
        states = [x0] + [xs[6 * m:6 * m + 6] for m in range(N)]
        q = [st[:3] for st in states]
        x_n = states[N]
        x_next = ca.mtimes(ca.DM(a), x_n)
        d_n = x_next[:3] - x_n[:3]
        q_n, p_n, q_next = x_n[:3], x_n[3:], x_next[:3]

        def sq(e):
            return ca.sumsqr(e)

        def nb_pos(j, m):
            k = 3 * ((N + 1) * j + m)
            return qn[k:k + 3]

        v_of = [cfg.alpha * sq(q[m] - qd) for m in range(N + 1)]
        v_scale = v_of[0] + 1.0
        cost = 0
        for m in range(N):                                           # (27)-(28)
            cost += v_of[m] + cfg.beta * mass**2 * sq(u[3 * m:3 * m + 3]) + cfg.gamma * lam[m] ** 2
        cost += _SLACK_WEIGHT * ca.sum1(s) + _TERMINAL_SLACK_WEIGHT * s_t

        g, lbg, ubg = [], [], []

        def add(expr, lo, hi):
            g.append(expr)
            lbg.append(lo)
            ubg.append(hi)

        inf = ca.inf
        for m in range(N):                                           # thrust: U ⊖ sup κ
            add(sq(v[3 * m:3 * m + 3]) - 1.0, -inf, 0.0)
        for m in range(N):                                           # Lyapunov decrease (36)
            add((v_of[m + 1] - (1.0 - cfg.sigma + lam[m]) * v_of[m] - cfg.lyapunov_tolerance) / v_scale,
                -inf, 0.0)
        for m in range(1, N + 1):                                    # (34) and the keep-outs
            for j in range(K):
                add((sq(q[m] - nb_pos(j, m)) - r_pair**2) / r_pair**2 + s[m - 1], 0.0, inf)
            add((sq(q[m] - qo[3 * m:3 * m + 3]) - r_obs**2) / r_obs**2 + s[m - 1], 0.0, inf)
            add((sq(q[m] - qr) - r_tgt**2) / r_tgt**2 + s[m - 1], 0.0, inf)
        if cfg.v_max is not None:                                    # state set Ξ_i: speed bound
            for m in range(1, N + 1):
                add((sq(states[m][3:]) - cfg.v_max**2) / cfg.v_max**2 - s_t, -inf, 0.0)
        step_len = ca.sqrt(sq(d_n) + 1e-6)                            # ||∫ f dt|| over one Δt
        qo_n, qo_next = qo[3 * N:3 * N + 3], qo[3 * (N + 1):3 * (N + 1) + 3]
        for j in range(K):                                           # terminal set (38)
            add((ca.sqrt(sq(q_n - nb_pos(j, N))) - step_len - r_pair) / r_pair + s[N - 1], 0.0, inf)
            add((sq(q_next - nb_pos(j, N) - dn[3 * j:3 * j + 3]) - r_pair**2) / r_pair**2 + s[N - 1],
                0.0, inf)
        add((ca.sqrt(sq(q_n - qo_n)) - step_len - r_obs) / r_obs + s[N - 1], 0.0, inf)
        add((sq(q_next - qo_next) - r_obs**2) / r_obs**2 + s[N - 1], 0.0, inf)
        add((ca.sqrt(sq(q_n - qr)) - step_len - r_tgt) / r_tgt + s[N - 1], 0.0, inf)
        add((sq(q_next - qr) - r_tgt**2) / r_tgt**2 + s[N - 1], 0.0, inf)
        add((sq(q_next - qd) - sq(q_n - qd) - cfg.lyapunov_tolerance) / v_scale - s_t, -inf, 0.0)
        if cfg.terminal_braking:                                     # stopping-distance rows
            a_b = cfg.braking_fraction * u_nom
            add(sq(p_n) - 2.0 * a_b * ca.sqrt(sq(q_n - qd) + cfg.lyapunov_tolerance) - s_t, -inf, 0.0)

            def closing_ok(q_b, p_b, radius):
                rel = q_n - q_b
                dist = ca.sqrt(sq(rel) + 1e-6)
                v_c = -ca.dot(p_n - p_b, rel) / dist                   # closing speed
                return v_c * ca.sqrt(v_c**2 + 1e-6) - 2.0 * a_b * (dist - radius) - s_t

            for j in range(K):
                add(closing_ok(nb_pos(j, N), pn[3 * j:3 * j + 3], r_pair), -inf, 0.0)
            add(closing_ok(qo_n, po, r_obs), -inf, 0.0)
            add(closing_ok(qr, ca.DM.zeros(3), r_tgt), -inf, 0.0)

        w = ca.vertcat(v, lam, s, s_t)
        p = ca.vertcat(x0, qd, qn, dn, pn, qo, po, qr)
        return {"x": w, "p": p, "f": cost, "g": ca.vertcat(*g)}, lbg, ubg

    @staticmethod
    def _build(cfg: TubeRDMPCConfig, *args: Any, max_iter: int) -> tuple[Any, np.ndarray, np.ndarray]:
        """The CasADi solver of :meth:`_problem` (ipopt with iteration limit ``max_iter``; its
        functions compiled for ``solver="ipopt-jit"``) and the row bounds ``(lbg, ubg)``."""
        import casadi as ca

        nlp, lbg, ubg = _NominalNLP._problem(cfg, *args)
        opts = {
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_iter": int(max_iter),
            "ipopt.tol": float(cfg.tol),
            "ipopt.acceptable_tol": 1e-4,
            "ipopt.acceptable_iter": 5,
            "ipopt.mu_strategy": "adaptive",
            **({"ipopt.max_wall_time": float(cfg.solve_time_limit)} if cfg.solve_time_limit else {}),
            **(WARM_DUAL_OPTIONS if cfg.warm_duals else {}),
            **(JIT_OPTIONS if cfg.solver == "ipopt-jit" else {}),
        }
        return (ca.nlpsol("tube_rdmpc", "ipopt", nlp, opts), np.array(lbg, dtype=float),
                np.array(ubg, dtype=float))

    def _linearised(self, k: int) -> Any:
        """``(w, p) -> (H_f, grad f, g, J_g)`` of the exact NLP with ``k`` slots (built once)."""
        args = (self.cfg, *self._constants, k, *self._radii)

        def build() -> Any:
            nlp = self._problem(*args)[0]
            return linearisation(nlp["x"], nlp["p"], nlp["f"], nlp["g"], "tube_rdmpc_rti")

        return nlpsol_cached(("tube_rdmpc-rti", *args), build)

    def _buffered(self, kind: str, k: int, copy: int) -> BufferedFunction:
        """Worker ``copy``'s buffered :meth:`_linearised` (``"lin"``) or :meth:`rows` (``"rows"``)."""
        key = (kind, k, copy)
        if key not in self._buffers:
            self._buffers[key] = BufferedFunction(self._linearised(k) if kind == "lin" else self.rows(k))
        return self._buffers[key]

    def qp_step(self, info: dict[str, Any], params: np.ndarray, w0: np.ndarray, owner: int,
                copy: int = 0) -> np.ndarray | None:
        """Sequential convexification of the exact NLP from ``w0`` (the shifted previous plan): one
        QP (:meth:`_qp_once`) about ``w0``, and again about its point while the exact NLP's own rows
        are violated there by more than ``NLP_CONSTRAINT_TOL`` (at most :data:`SQP_ITERATIONS` QPs
        in all). The point, or ``None`` when a QP failed or the rows still do not hold (``info``
        says why)."""
        k = self.slots(params)
        lbg, ubg = self.row_bounds(k)
        lbx, ubx = self.bounds(relaxed=False)
        w = np.clip(w0, lbx, ubx)
        if owner in self._mu:                         # the previous decision's, one stage on
            mu = self._mu[owner].reshape(-1, self.N)
            mu[:, :-1] = mu[:, 1:].copy()
        for _ in range(SQP_ITERATIONS):
            w = self._qp_once(info, params, w, owner, copy)
            if w is None:
                return None
            excess = row_violation(self._buffered("rows", k, copy)(w, params)[0].ravel(), lbg, ubg)
            if excess <= NLP_CONSTRAINT_TOL:
                return w
        info["solver_failures"] = info.get("solver_failures", 0) + 1
        info["solver_status"] = (f"{SQP_ITERATIONS} qp steps leave the NLP rows violated by {excess:.3g} "
                                 f"> {NLP_CONSTRAINT_TOL}")
        return None

    def _qp_once(self, info: dict[str, Any], params: np.ndarray, w0: np.ndarray, owner: int,
                 copy: int) -> np.ndarray | None:
        """One QP about ``w0``: every row linearised at ``w0`` (the collision and keep-out rows
        become tangent half-spaces inside their feasible sets), the slacks fixed at 0. Every row
        the QP's point violates by more than :data:`CUT_TOL` then also gets its linearisation at
        that point, added to the others, and the QP is solved again (at most :data:`CUT_ROUNDS`
        QPs): a cutting plane for the convex rows (thrust ball, speed bound: :meth:`convex_rows`),
        a second model of a nonconvex one (the terminal braking and closing-speed rows, the
        Lyapunov rows) that keeps the first. Each DAQP solve goes through
        :func:`satenv.baselines.base.guarded_solve` and starts from the satellite's previous QP's
        active set. The new point (its inputs scaled onto the unit ball), or ``None`` when a QP
        failed."""
        N, k = self.N, self.slots(params)
        n_q = 4 * N                                   # v (3N), lambda (N); the slacks stay 0
        lin = self._buffered("lin", k, copy)
        lbx, ubx = self.bounds(relaxed=False)
        lbg, ubg = self.row_bounds(k)
        hess, grad, g, jac = (o.copy() for o in lin(w0, params))
        g = g.ravel()
        h, f = hess[:n_q, :n_q], grad.ravel()[:n_q]
        convex = self.convex_rows(k)
        mu = self._mu.get(owner)
        if mu is not None:                            # the convex rows' curvature (Lagrangian Hessian)
            h[:3 * N, :3 * N] += np.tensordot(mu, self.curvature, 1)
        position = np.full(lbg.size, convex.size)     # each QP row's convex row (convex.size: none)
        position[convex] = np.arange(convex.size)
        bucket = position.copy()
        lb, ub = lbx[:n_q] - w0[:n_q], ubx[:n_q] - w0[:n_q]
        a, lo, hi = jac[:, :n_q], lbg - g, ubg - g
        hi[convex] = _support(g[convex])
        is_convex = position < convex.size
        for _ in range(CUT_ROUNDS):
            d = guarded_solve(info,
                              lambda a=a, lo=lo, hi=hi: self._qp.solve(h, f, a, lo, hi, lb, ub, owner=owner),
                              shape=(n_q,), lower=lb, upper=ub, fallback=False, tol=QP_ROW_TOL,
                              violation=lambda d, a=a, lo=lo, hi=hi: row_violation(a @ d, lo, hi),
                              violation_tol=QP_ROW_TOL, time_limit=self.cfg.solve_time_limit)
            if d is None:
                return None
            w = w0.copy()
            w[:n_q] += d
            lam = np.maximum(self._qp.multipliers[owner][n_q:], 0.0)
            self._mu[owner] = np.bincount(bucket, weights=lam, minlength=convex.size + 1)[:convex.size]
            _, _, g1, j1 = lin(w, params)
            g1 = g1.ravel()
            cut = np.flatnonzero(np.maximum(lbg - g1, g1 - ubg) > CUT_TOL)
            if cut.size == 0:
                break
            bucket = np.concatenate([bucket, position[cut]])
            # lbg <= g1 + J1 (w' - w) <= ubg, in the step d' = w' - w0
            a = np.vstack([a, j1[cut, :n_q]])
            step = j1[cut, :n_q] @ d
            upper = np.where(is_convex[cut], _support(g1[cut]), ubg[cut] - g1[cut])
            lo = np.concatenate([lo, np.clip(lbg[cut] - g1[cut] + step, -QP_INFINITY, QP_INFINITY)])
            hi = np.concatenate([hi, np.clip(upper + step, -QP_INFINITY, QP_INFINITY)])
        v = w[:3 * N].reshape(N, 3)
        w[:3 * N] = (v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1.0)).ravel()   # onto the ball
        return w

    def _convex_hessians(self) -> np.ndarray:
        """Hessians on ``v`` (3N x 3N) of the convex rows of :meth:`convex_rows`, in their order
        (the same for every slot count): ``2 I`` on ``v_m`` for the ball row of step m,
        ``2 (u_nom / v_max)^2 P_m' P_m`` for its speed row (``P_m``: the velocity of step m per
        unit input in the CW prediction)."""
        N = self.N
        mats = [np.kron(np.diag(np.eye(N)[m]), 2.0 * np.eye(3)) for m in range(N)]
        if self.cfg.v_max is not None:
            for m in range(N):
                vel = self.cal_b[6 * m + 3:6 * m + 6]
                mats.append(2.0 * (self.u_nom / self.cfg.v_max) ** 2 * vel.T @ vel)
        return np.array(mats)

    def convex_rows(self, k: int) -> np.ndarray:
        """Indices of the convex ``<=`` rows of the NLP with ``k`` slots: the thrust ball (the first
        N rows) and the speed bound (when ``v_max`` is set)."""
        N = self.N
        speed = 2 * N + N * (k + 2)                   # after the ball, Lyapunov and keep-out rows
        return np.r_[np.arange(N), np.arange(speed, speed + N) if self.cfg.v_max is not None else []].astype(int)

    def rows(self, k: int) -> Any:
        """``(w, p) -> g`` of the NLP with ``k`` slots (built once)."""
        args = (self.cfg, *self._constants, k, *self._radii)

        def build() -> Any:
            import casadi as ca

            nlp = self._problem(*args)[0]
            return ca.Function("tube_rdmpc_rows", [nlp["x"], nlp["p"]], [nlp["g"]])

        return nlpsol_cached(("tube_rdmpc-rows", *args), build)

    def bounds(self, relaxed: bool) -> tuple[np.ndarray, np.ndarray]:
        N = self.N
        lb = np.concatenate([-np.ones(3 * N), np.zeros(N), np.zeros(N + 1)])
        ub = np.concatenate([np.ones(3 * N), np.full(N, 1e3 if relaxed else self.sigma),
                             np.full(N + 1, np.inf if relaxed else 0.0)])
        return lb, ub

    def solve(self, info: dict[str, Any], params: np.ndarray, w0: np.ndarray,
              relaxed: bool, duals: dict[str, np.ndarray] | None = None, copy: int = 0) -> np.ndarray | None:
        """One guarded ipopt solve (:func:`satenv.baselines.base.guarded_solve`): the point, or ``None``
        on an exception, a failed status, a wrong-shaped or non-finite point, a variable outside
        its bounds or a constraint row violated by more than ``NLP_CONSTRAINT_TOL``.

        ``duals`` (``lam_x``, ``lam_g``): the multipliers to start from (used by a solver built
        with ``warm_duals``); the solve writes its own multipliers back into the dict. ``copy``:
        which solver copy (one per worker thread) runs it. The NLP's slot count is that of
        ``params`` (:meth:`slots`)."""
        lbx, ubx = self.bounds(relaxed)
        w0 = np.clip(w0, lbx, np.where(np.isfinite(ubx), ubx, w0))
        k = self.slots(params)
        lbg, ubg = self.row_bounds(k)
        g: dict[str, np.ndarray] = {}
        if duals and duals["lam_g"].size != lbg.size:
            duals.clear()                        # multipliers of another slot count: start without
        start = {} if not duals else {"lam_x0": duals["lam_x"], "lam_g0": duals["lam_g"]}

        def run() -> tuple[np.ndarray, bool, str]:
            solver = self.solver_for(k, copy, relaxed)
            sol = solver(x0=w0, p=params, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, **start)
            stats = solver.stats()
            status = str(stats.get("return_status", ""))
            g["g"] = np.asarray(sol["g"], dtype=float).ravel()
            if duals is not None:
                duals["lam_x"] = np.asarray(sol["lam_x"], dtype=float).ravel()
                duals["lam_g"] = np.asarray(sol["lam_g"], dtype=float).ravel()
            ok = bool(stats.get("success", False)) or status == "Solved_To_Acceptable_Level"
            return np.asarray(sol["x"], dtype=float).ravel(), ok, status

        return guarded_solve(info, run, shape=(self.n_w,), lower=lbx, upper=ubx, fallback=False,
                             violation=lambda _: row_violation(g["g"], lbg, ubg),
                             violation_tol=NLP_CONSTRAINT_TOL, time_limit=self.cfg.solve_time_limit)

    def states(self, x0: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Predicted nominal states (N + 1, 6) for scaled inputs ``v`` (3N,)."""
        xs = self.cal_a @ x0 + self.cal_b @ (self.u_nom * v)
        return np.vstack([x0, xs.reshape(self.N, 6)])


class TubeRDMPC(Baseline):
    """Tube-based robust DMPC (li2022) for ``satenv.cluster_v0`` (see the module docstring).

    Privileged: it reads the env's states (under navigation error, the estimate), allocated targets,
    obstacle state, time and scenario, and registers its tube controller with ``env.set_inner_loop`` (it acts inside the
    env's physics sub-steps).

    Args:
        env: a ``cluster_v0`` env.
        config: a :class:`TubeRDMPCConfig` (default: li2022 §4); ``**options`` replace fields.

    ``info``: ``fallbacks`` (decisions that used the shifted previous plan), ``relaxed`` (relaxed
    NLP solves), ``solve_ms`` (every NLP solve), ``tube_error_max_m`` (largest ``||q - q~||``),
    ``tube_bound_m`` (ε̄ of (15)), ``resyncs`` (nominal restarted at the true state).
    """

    name = "tube_rdmpc"
    env_ids = ("cluster_v0",)
    cheap = False

    @classmethod
    def supports(cls, env: Any) -> bool:
        return super().supports(env) and callable(getattr(env, "set_inner_loop", None))

    def __init__(self, env: Any, config: TubeRDMPCConfig | None = None, **options: Any) -> None:
        check_env(type(self), env)
        self.cfg = config_from_options(TubeRDMPCConfig, options, "TubeRDMPC", base=config)
        sc = nominal(env).scenario
        self.env = env
        self.sc = sc
        self.agents = list(env.possible_agents)
        self.m = len(self.agents)
        cfg = self.cfg
        steps = cfg.horizon / sc.dt
        if steps > MAX_HORIZON + 0.5:
            raise BaselineError(f"TubeRDMPC option horizon must be at most {MAX_HORIZON} decision periods "
                                f"({MAX_HORIZON * sc.dt:g} s at dt = {sc.dt} s; bounded work), got {cfg.horizon} s")
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise BaselineError(f"TubeRDMPC option horizon must be a positive multiple of the decision "
                                f"period dt = {sc.dt} s, got {cfg.horizon} s")
        self.N = int(round(steps))
        self.n = sc.orbit.n
        self.w_bar = sc.disturbance_bound + cfg.model_error_bound
        self.eps_bar = math.sqrt(cfg.eta / cfg.k1) * self.w_bar             # (15)
        self.kappa_bar = cfg.kappa_margin * self.w_bar if cfg.tube else 0.0
        self.u_nom = sc.u_max - self.kappa_bar
        if self.u_nom <= 0:
            raise BaselineError(f"the disturbance bound {self.w_bar:.3g} m/s^2 leaves no thrust for the "
                             f"nominal DMPC (u_max = {sc.u_max:.3g} m/s^2)")
        self.a, self.b = cw_matrices(self.n, sc.dt)
        self.nlp = _NominalNLP(cfg, self.n, sc.dt, self.N, slot_sizes(self.m, sc.n_neighbours), self.u_nom, sc.mass,
                               r_pair=sc.pair_distance + 2 * self.eps_bar + cfg.safety_margin,
                               r_obs=sc.obstacle_distance + self.eps_bar + cfg.safety_margin,
                               r_tgt=sc.target_distance + self.eps_bar + cfg.safety_margin)
        self.tube = TubeController(self.n, sc.physics_dt, cfg.k1, cfg.k2)
        self.tube.enabled = cfg.tube
        self._pool: ThreadPoolExecutor | None = None
        self.info: dict[str, Any] = {}
        self._reset_state()

    # ------------------------------------------------------------------ episode
    def _reset_state(self) -> None:
        self.plans: np.ndarray | None = None     # (M, N + 1, 6) nominal plans from the last decision
        self.warm: np.ndarray = np.zeros((self.m, self.nlp.n_w))
        self.duals: list[dict[str, np.ndarray]] = [{} for _ in range(self.m)]  # per satellite (warm_duals)
        self.expected_time: float | None = None
        self.history: dict[str, list] = {"t": [], "nominal": [], "lambda": [], "u_nominal": [],
                                         "status": []}
        self.tube.nominal = None
        self.tube.eps, self.tube.kappa, self.tube.u_total = [], [], []
        self.info = new_info(relaxed=0, solve_ms=[], tube_error_max_m=0.0,
                             tube_bound_m=self.eps_bar, resyncs=0, solves=0, qp_steps=0, rti_fallbacks=0)
        self.tube.stats = self.info
        self.nlp.forget()

    def reset(self, seed: int | None = None) -> None:
        """Forget plans and statistics; the nominal restarts at the env's true state."""
        self._reset_state()
        if self.env.agents:
            self._attach()

    def _attach(self) -> None:
        x = self.env.state()[: 6 * self.m].reshape(self.m, 6)
        self.tube.sync(x, self.env.time)
        self.plans = None
        self.env.set_inner_loop(self.tube)
        self.expected_time = self.env.time

    # ------------------------------------------------------------------ control
    def _shifted(self) -> np.ndarray:
        """Every satellite's prediction for t_k .. t_k + NΔt (29)–(30): (M, N + 1, 6)."""
        if self.plans is None:
            x = self.tube.nominal
            out = np.empty((self.m, self.N + 1, 6))
            out[:, 0] = x
            for k in range(self.N):
                out[:, k + 1] = out[:, k] @ self.a.T
            return out
        nxt = self.plans[:, -1] @ self.a.T
        return np.concatenate([self.plans[:, 1:], nxt[:, None]], axis=1)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        env = self.env
        if env.inner_loop is not self.tube or self.tube.nominal is None or (
                self.expected_time is not None and abs(env.time - self.expected_time) > 1e-6):
            if self.tube.nominal is not None:
                self.info["resyncs"] += 1
            self._attach()
        sc, N = self.sc, self.N
        t_k = env.time
        nominal = self.tube.nominal.copy()
        pred = self._shifted()
        pred[:, 0] = nominal
        pred_q = pred[..., :3]
        pred_p_end = pred[:, -1, 3:]                                   # (M, 3) terminal velocities
        coast = (pred[:, -1] @ self.a.T)[:, :3] - pred[:, -1, :3]     # (M, 3)
        q_o, p_o = env.obstacle_state()
        qo = q_o + np.arange(N + 2)[:, None] * sc.dt * p_o
        targets = env.targets()
        true_pos = env.state()[: 6 * self.m].reshape(self.m, 6)[:, :3]
        adj = nearest_neighbour_graph(true_pos, sc.n_neighbours, sc.comm_range)
        q_r = np.asarray(sc.target_spacecraft, dtype=float)
        new_plans = np.empty((self.m, N + 1, 6))
        actions: dict[str, np.ndarray] = {}
        lam0 = np.zeros(self.m)
        status_row = []
        params_all = []
        for i in range(self.m):
            nbrs = np.nonzero(adj[i])[0]
            K = self.nlp.slots_for(nbrs.size)
            qn = np.full((K, N + 1, 3), _FAR)
            dn = np.zeros((K, 3))
            pn = np.zeros((K, 3))
            for slot, j in enumerate(nbrs):
                qn[slot] = pred_q[j]
                dn[slot] = coast[j]
                pn[slot] = pred_p_end[j]
            params_all.append(np.concatenate([nominal[i], targets[i], qn.ravel(), dn.ravel(), pn.ravel(),
                                              qo.ravel(), p_o, q_r]))
        exact = self._solve_exact(params_all)
        for i, agent in enumerate(self.agents):
            params, w0 = params_all[i], self.warm[i]
            w = exact[i]
            kind = "ok"
            if w is None and self.cfg.warm_duals:
                self.duals[i].clear()                # the next decision starts from no multipliers
            if w is None and self.cfg.relax_on_failure:
                start = time.perf_counter()
                w = self.nlp.solve(self.info, params, w0, relaxed=True)
                self.info["solve_ms"].append((time.perf_counter() - start) * 1e3)
                self.info["relaxed"] += 1
                kind = "relaxed"
            if w is None:
                record_fallback(self.info, self.info["solver_status"])
                kind = "fallback"
                v = self.warm[i][: 3 * N].copy()     # the shifted previous plan, ρ = 0 appended (29)
                speed = np.linalg.norm(nominal[i, 3:])
                if not np.any(v[:3]) and speed > 1e-3:  # plan exhausted: brake instead of coasting
                    v[:3] = -self.cfg.braking_fraction * nominal[i, 3:] / speed
                w = np.concatenate([v, np.zeros(2 * N + 1)])
            v = w[: 3 * N]
            v = v.reshape(N, 3)
            norms = np.linalg.norm(v, axis=1, keepdims=True)
            v = (v / np.maximum(norms, 1.0)).ravel()                 # exact unit-ball feasibility
            new_plans[i] = self.nlp.states(nominal[i], v)
            lam0[i] = w[3 * N]
            # warm start of the next decision: shift by one step, ρ = 0 at the end
            self.warm[i] = np.concatenate([v[3:], np.zeros(3), w[3 * N + 1:4 * N], [0.0],
                                           np.zeros(N + 1)])
            u0 = self.u_nom * v[:3]
            actions[agent] = u0 / sc.u_max
            status_row.append(kind)
        self.plans = new_plans
        self.expected_time = t_k + sc.dt
        h = self.history
        h["t"].append(t_k)
        h["nominal"].append(nominal)
        h["lambda"].append(lam0)
        h["u_nominal"].append(np.array([actions[a] * sc.u_max for a in self.agents]))
        h["status"].append(status_row)
        return actions

    def _solve_exact(self, params_all: list[np.ndarray]) -> list[np.ndarray | None]:
        """Every satellite's exact NLP (their parameters come from the previous decision's plans,
        so they are independent): in turn, or on ``workers`` threads, each with its own solver
        copy (CasADi releases the GIL while ipopt runs). Same points either way; ``info`` gets the
        statuses, failures and times in satellite order."""
        def solve(i: int, copy: int) -> tuple[np.ndarray | None, dict[str, Any], float]:
            local: dict[str, Any] = {}
            start = time.perf_counter()
            if rti:
                w = self.nlp.qp_step(local, params_all[i], self.warm[i], owner=i, copy=copy)
                if w is not None:
                    local["qp_steps"] = 1
                    return w, local, (time.perf_counter() - start) * 1e3
                local["rti_fallbacks"] = 1
                self.duals[i].clear()                # the ipopt fallback starts from no multipliers
            duals = self.duals[i] if self.cfg.warm_duals else None
            w = self.nlp.solve(local, params_all[i], self.warm[i], relaxed=False, duals=duals, copy=copy)
            return w, local, (time.perf_counter() - start) * 1e3

        rti = self.cfg.solver == "rti" and self.plans is not None    # cold: ipopt
        workers = min(self.cfg.workers, self.m)
        self.nlp.prepare([self.nlp.slots(p) for p in params_all], workers)   # builds: not in threads
        if workers == 1:
            results = [solve(i, 0) for i in range(self.m)]
        else:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="tube_rdmpc")

            def chunk(copy: int) -> list[tuple]:
                return [solve(i, copy) for i in range(copy, self.m, workers)]

            chunks = list(self._pool.map(chunk, range(workers)))
            results = [chunks[i % workers][i // workers] for i in range(self.m)]
        for _, local, ms in results:
            self.info["solver_status"] = local["solver_status"]
            self.info["solver_failures"] = self.info.get("solver_failures", 0) + local.get("solver_failures", 0)
            for key in ("qp_steps", "rti_fallbacks"):
                self.info[key] += local.get(key, 0)
            self.info["solve_ms"].append(ms)
            self.info["solves"] += 1
        return [w for w, _, _ in results]

    # ------------------------------------------------------------------ diagnostics
    def tube_errors(self) -> np.ndarray:
        """``||q - q~||`` at every physics step so far (T_phys, M) [m]."""
        return np.array(self.tube.eps) if self.tube.eps else np.zeros((0, self.m))

    def config(self) -> dict[str, Any]:
        return asdict(self.cfg)
