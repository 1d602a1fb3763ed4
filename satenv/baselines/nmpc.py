"""Cooperative nonlinear MPC for on-orbit servicing (pereira2022 §4.2-4.4; ``satenv.servicing_v0``).

``NMPC(env, config=None, **options)`` (:class:`NMPCConfig`) is a scripted policy (``reset(seed=None)``,
``act(observations)``) that reads ``env.state()`` and ``env.scenario`` and returns normalised inputs
``u / u_max`` in ``[-1, 1]^6`` per spacecraft.

Per spacecraft i and decision step, one NLP (eq. 38) over ``N`` steps (``NMPCConfig.horizon``,
30 as in §5.2), multiple shooting with stage-wise variables ``(x_0, u_0, x_1, …, x_N)``:

* model — eq. 35: translation with the exact zero-order-hold Clohessy-Wiltshire matrices of
  ``satenv.dynamics.cw_matrices`` (at the 15-30 m ranges of §5.2 the linearisation of eq. 4-5
  changes the acceleration by < 1e-9 m/s^2), attitude eq. 10-17 about the LVLH-fixed object
  with ``rk4_steps`` RK4 steps per T_s, the thruster matrices of eq. 36 (force along LVLH, or
  rotated by ``R(q_k)`` and held over the step when ``scenario.thrust_frame == "body"``);
* cost — eq. 39, ``sum_{k=0}^{N-1}`` of the stage cost with the scenario's weights
  (§5.2: Q_p = 10 I, Q_v = 0.5 I, Q_q = 15 I_4, Q_w = 0.5 I, H = 2 I_6), ``p_d`` the current
  waypoint held over the horizon (``preview=True``: the eq. 50 schedule over the horizon), ``v_d``;
  ``q_d,k`` and ``omega_d,k`` of eq. 43-49 are expressions of the stage's own decision variables
  ``(p_k, v_k, q_k)`` inside the NLP (:func:`attitude_reference_sym`, the env's reference), and
  the quaternion error enters as ``[1 - |eta~|, eps~]`` of ``q~ = q_k (x) q_d,k_bar``
  (:func:`quaternion_cost_terms`: the same for ``q_d`` and ``-q_d``). Ours, not in eq. 39:
  ``terminal_attitude_weight`` (default 100) times the attitude terms (Q_q, Q_w) at ``x_N``;
  with the paper's stage cost alone (weight 0) the N = 30 (3 s) horizon sees too little of the
  attitude manoeuvre and the pointing error swings (a 30 deg step at rest: 1.2 deg after 7.5 s,
  back to 12 deg at 15 s; with 100: 0.05 deg at 15 s).
* constraints — ``|u_j| <= u_max`` (eq. 36 inputs), ``|v_j| <= v_max`` and
  ``|omega_j| <= omega_max`` per axis (eq. 42), the keep-out ``|p_k|^2 >= (r_sigma + r_s +
  keepout_margin)^2`` (eq. 40) and the coupled collision constraints
  ``|p_k - p_j,k|^2 >= (r_i + r_j + separation_margin)^2`` (eq. 41) against every other
  spacecraft's predicted positions (k = 1..N). Velocity and angular-velocity bounds are tightened
  by the relative ``bound_margin`` so that round-off never reads as a violation in the env.

Cooperation (``order``): ``"sequential"`` (default, Gauss-Seidel) — spacecraft solve in index
order, each against the plans the others published last (the ones solved earlier in this step:
their new plans; the rest: their previous plans shifted by one step, the last position held);
``"jacobi"`` — all against the previous plans. Before the first plan of a spacecraft exists the
others assume it stays where it is.

Built once (one CasADi ``nlpsol`` shared by the spacecraft), warm-started from each spacecraft's
previous solution shifted by one step. When the waypoint changes (or at the first step) the
initial guess is an arc on the sphere of the current radius from ``p`` towards the new waypoint
(``initial_guess="arc"``; a spacecraft exactly opposite its goal otherwise sits on a stationary
point of the keep-out problem), or the current state held (``"hold"``).

Solvers: ``"ipopt"`` (default, MUMPS: every NLP solved to convergence, as in pereira2022 §5.2,
which solves it "resorting to the open-source tool for nonlinear optimization, CasADi" without
naming the solver, ipopt being CasADi's NLP solver of reference; the reproduction
``satenv/bench/reproductions/pereira2022_servicing.py`` keeps it), ``"fatrop"``
(structure-exploiting; the NLP is already in its stage-wise form) or ``"rti"`` (real-time iteration,
below). ipopt gets the Gauss-Newton matrix of the cost residuals (plus the path
rows' curvature) as its Hessian (``hessian="gauss-newton"``, the default) instead of the exact
Hessian of the Lagrangian (``"exact"``), whose second derivatives of the RK4 attitude step and of
eq. 43-49 cost 20x the constraint evaluation: more iterations, each cheaper, the same optimum.
Every solve goes through :func:`satenv.baselines.base.guarded_solve`: an
exception, a status other than success / acceptable, a wrong-shaped or non-finite point, a variable
outside its bounds (input box, velocity bounds) or a constraint row violated by more than
``NLP_CONSTRAINT_TOL`` is a failure (``info["solver_status"]`` says which). A failed solve applies the
next input of the spacecraft's last successful plan while one remains, else the brake-and-hold
action :meth:`NMPC.safe_action` (zero thrust is not safe here: the §5.2 spacecraft start on the
keep-out sphere and drift into it), and is counted in ``info["fallbacks"]``. ``info`` also keeps
``"solve_ms"`` (wall time of every ``act``), ``"agent_solve_ms"`` (every NLP solve), ``"iterations"``,
``"statuses"``.

Real-time iteration (``solver="rti"``, acados-style): one QP per spacecraft and decision instead of
an NLP. The NLP above is linearised about the spacecraft's previous plan shifted by one step: the
model's Jacobians ``A_k, B_k`` and the cost residuals' Jacobians at every stage (one gcc-compiled
CasADi function mapped over the horizon), the Gauss-Newton Hessian ``2 J^T J``; the states are
condensed out (``dx_k = Phi_k du + phi_k``, ``phi`` carrying the shifted plan's defects; the Hessian
by a backward recursion over the stages, O(N^2)), leaving the 6N input steps with the input box as
bounds and as rows the velocity / rate bounds and the keep-out and collision rows linearised at the
plan's positions (tangent half-spaces: inside the true feasible sets, as ``|p|^2`` is convex). DAQP
(dual active set, :class:`satenv.baselines._qp.DenseQP`) solves it, starting from the spacecraft's
previous QP's active set moved one stage on (about 15 active-set changes instead of 45). A cold
decision (the first, or a new waypoint with the arc guess) is a full ipopt solve; a failed QP
(through :func:`guarded_solve`) is counted in ``info["rti_fallbacks"]`` and ``info["solver_failures"]``
and ipopt solves the decision from the same shifted plan. ``info`` adds ``"qp_ms"`` (every QP step),
``"rti_steps"`` and ``"nlp_solves"``. At a KKT point of the NLP the QP's step is zero
(``tests/test_nmpc_rti.py``); on §5.2 (seed 900000, 1200 steps) it flies the same episode as ipopt
to within 0.02 % in RMSE, with 2.5 % less delta-v and a 3.5 % smaller final error, at 1.5 ms per
spacecraft decision against ipopt's 9 (``satenv.bench.perf.experts.closed_loop_vs_ipopt``).
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from satenv.baselines._qp import QP_INFINITY, QP_ROW_TOL, BufferedFunction, DenseQP
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
from satenv.dynamics import cw_continuous, cw_matrices
from satenv.dynamics.attitude import thruster_matrices
from satenv.envs.servicing_v0 import unpack_global_state
from satenv.perturbations import nominal

__all__ = ["NMPC", "NMPCConfig", "attitude_reference_sym", "build_model", "quaternion_cost_terms"]

_SOLVERS = ("ipopt", "ipopt-jit", "fatrop", "rti")
QUATERNION_ERRORS = ("sign-free", "signed")
"""``NMPCConfig.quaternion_error`` choices: ours (``1 - |eta~|``) and eq. 39 as printed (``1 - eta~``)."""
_OK = {"Solve_Succeeded", "Solved_To_Acceptable_Level", "success"}


def build_model(scenario, rk4_steps: int = 1):
    """CasADi functions of eq. 35: ``(f(x, u) -> x_dot, F(x, u) -> x_next)`` over one T_s.

    ``F`` advances the translation with the exact zero-order-hold CW matrices of
    ``satenv.dynamics.cw_matrices`` (the acceleration ``F_t u``, or ``R(q_k) F_t u`` for body-fixed
    thrusters, held over the step as in the env) and the attitude (eq. 10-17) with ``rk4_steps``
    RK4 steps. ``f`` is the continuous right-hand side (for tests).
    """
    import casadi as ca

    n = scenario.mean_motion
    a_c, _ = cw_continuous(n)
    a_d, b_d = cw_matrices(n, scenario.dt)
    f_t, f_r = thruster_matrices(scenario.dimensions)
    j_f = np.array(scenario.inertia)
    j_l = np.array(scenario.object_inertia)
    j_f_inv = np.linalg.inv(j_f)
    w_l = np.array([0.0, 0.0, n])
    lead = np.linalg.solve(j_l, np.cross(w_l, j_l @ w_l))       # J_l^-1 S(w_l) J_l w_l (0 if J_l = c I)
    jf, jf_inv = ca.DM(j_f), ca.DM(j_f_inv)

    def rot(q):   # R(q) = I + 2 eta S(eps) + 2 S(eps)^2: body -> LVLH (attitude.quat_to_matrix)
        eta, eps = q[0], q[1:4]
        s_eps = ca.skew(eps)
        return ca.SX.eye(3) + 2 * eta * s_eps + 2 * ca.mtimes(s_eps, s_eps)

    def coupling(q, w):   # eq. 13-15 terms that involve the orbital rate: C_r w + E_r - (J w) x w
        eta, eps = q[0], q[1:4]
        ex, ey, ez = eps[0], eps[1], eps[2]
        # R^fb_lb [0, 0, n] = n * (third row of R(q))^T (the orbital rate in body axes)
        w_lf = n * ca.vertcat(2 * (ex * ez - eta * ey), 2 * (ey * ez + eta * ex),
                              1 - 2 * (ex * ex + ey * ey))
        d = (-ca.mtimes(jf, ca.cross(w_lf, w)) - ca.cross(w_lf, ca.mtimes(jf, w))
             + ca.cross(ca.mtimes(jf, w_lf), w) - ca.cross(w_lf, ca.mtimes(jf, w_lf)))
        if np.any(lead != 0):
            d = d + ca.mtimes(jf, ca.mtimes(rot(q).T, ca.DM(lead)))
        return d

    def att_rhs(q, w, tau):   # eq. 10 and J w_dot = (J w) x w + tau (+ coupling passed in tau)
        eta, eps = q[0], q[1:4]
        q_dot = 0.5 * ca.vertcat(-ca.dot(eps, w), eta * w + ca.cross(eps, w))
        return q_dot, ca.mtimes(jf_inv, ca.cross(ca.mtimes(jf, w), w) + tau)

    x = ca.SX.sym("x", 13)
    u = ca.SX.sym("u", 6)
    p, v, q, w = x[0:3], x[3:6], x[6:10], x[10:13]
    force = ca.mtimes(ca.DM(f_t), u)
    acc = force if scenario.thrust_frame == "lvlh" else ca.mtimes(rot(q), force)
    tau = ca.mtimes(ca.DM(f_r), u)
    q_dot, w_dot = att_rhs(q, w, tau + coupling(q, w))
    v_dot = ca.mtimes(ca.DM(a_c[3:, :]), ca.vertcat(p, v)) + acc
    f = ca.Function("f", [x, u], [ca.vertcat(v, v_dot, q_dot, w_dot)], ["x", "u"], ["x_dot"])

    x6_next = ca.mtimes(ca.DM(a_d), x[0:6]) + ca.mtimes(ca.DM(b_d), acc)
    h = scenario.dt / rk4_steps
    qa, wa = q, w
    for _ in range(rk4_steps):
        tau_k = tau + coupling(qa, wa)        # orbital-rate coupling held over the RK4 step
        k1q, k1w = att_rhs(qa, wa, tau_k)
        k2q, k2w = att_rhs(qa + h / 2 * k1q, wa + h / 2 * k1w, tau_k)
        k3q, k3w = att_rhs(qa + h / 2 * k2q, wa + h / 2 * k2w, tau_k)
        k4q, k4w = att_rhs(qa + h * k3q, wa + h * k3w, tau_k)
        qa = qa + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q)
        wa = wa + h / 6 * (k1w + 2 * k2w + 2 * k3w + k4w)
    big_f = ca.Function("F", [x, u], [ca.vertcat(x6_next, qa, wa)], ["x", "u"], ["x_next"])
    return f, big_f


def attitude_reference_sym(scenario, p, v, q, min_sine: float = 0.1):
    """Eq. 43-49 in CasADi: ``(q_d, omega_d)`` as expressions of the stage's ``p``, ``v``, ``q``.

    The same frame as :func:`satenv.dynamics.attitude.pointing_frame` (with its ``min_sine``
    switch to the LVLH axis least aligned with ``k_d``), ``q_d`` by Shepperd's method (branches by
    ``if_else``; a branch change flips the sign of ``q_d`` only, which the sign-free error of
    :func:`quaternion_cost_terms` does not see), ``omega_d = R(q)^T R_d omega^d_fo,d`` (eq. 49
    with ``n_f = n_l``, eq. 45-47 with ``t_dot = -v``).
    """
    import casadi as ca

    def unit(a):
        return a / ca.sqrt(ca.sumsqr(a))

    t = ca.DM(scenario.pointing_target) - p
    tn = ca.sqrt(ca.sumsqr(t))
    k = t / tn
    ref = ca.DM(scenario.pointing_reference)
    c = ca.cross(k, ref)
    ak = [ca.fabs(k[0]), ca.fabs(k[1]), ca.fabs(k[2])]
    e = [ca.DM([1.0, 0, 0]), ca.DM([0, 1.0, 0]), ca.DM([0, 0, 1.0])]
    least = ca.if_else(ca.logic_and(ak[0] <= ak[1], ak[0] <= ak[2]), e[0],
                       ca.if_else(ak[1] <= ak[2], e[1], e[2]))
    c = ca.if_else(ca.sqrt(ca.sumsqr(c)) / float(np.linalg.norm(scenario.pointing_reference)) < min_sine,
                   ca.cross(k, least), c)
    j = unit(c)
    i = ca.cross(j, k)
    r = ca.horzcat(i, j, k)
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    cands = []
    for b, diag in enumerate((tr, r[0, 0], r[1, 1], r[2, 2])):
        s = 2 * ca.sqrt(ca.fmax(1 + (tr if b == 0 else 2 * diag - tr), 1e-12))
        if b == 0:
            cand = [s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
        elif b == 1:
            cand = [(r[2, 1] - r[1, 2]) / s, s / 4, (r[1, 0] + r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s]
        elif b == 2:
            cand = [(r[0, 2] - r[2, 0]) / s, (r[1, 0] + r[0, 1]) / s, s / 4, (r[2, 1] + r[1, 2]) / s]
        else:
            cand = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] + r[1, 2]) / s, s / 4]
        cands.append(ca.vertcat(*cand))
    d = [tr, r[0, 0], r[1, 1], r[2, 2]]
    q_01 = ca.if_else(d[0] >= d[1], cands[0], cands[1])
    d_01 = ca.fmax(d[0], d[1])
    q_23 = ca.if_else(d[2] >= d[3], cands[2], cands[3])
    d_23 = ca.fmax(d[2], d[3])
    q_d = ca.if_else(d_01 >= d_23, q_01, q_23)
    t_dot = -v
    w_frame = ca.vertcat(-ca.dot(t_dot, j) / tn, ca.dot(t_dot, i) / tn, 0)
    eta, eps = q[0], q[1:4]
    s_eps = ca.skew(eps)
    rot = ca.DM.eye(3) + 2 * eta * s_eps + 2 * ca.mtimes(s_eps, s_eps)       # R(q): body -> LVLH
    w_d = ca.mtimes(rot.T, ca.mtimes(r, w_frame))
    return q_d, w_d


def quaternion_cost_terms(q, q_d, signed: bool = False):
    """``[1 - |eta~|, eps~]`` of ``q~ = q (x) q_d_bar`` (eq. 39), the same for ``q_d`` and ``-q_d``;
    ``signed``: ``[1 - eta~, eps~]`` as eq. 39 prints it (``-q_d`` is then the worst attitude)."""
    import casadi as ca

    eta_e = ca.dot(q, q_d)
    eps_e = q_d[0] * q[1:4] - q[0] * q_d[1:4] - ca.cross(q[1:4], q_d[1:4])
    return ca.vertcat(1 - (eta_e if signed else ca.fabs(eta_e)), eps_e)


NLP_CONSTRAINT_TOL = 1e-2
"""Largest accepted violation of an NLP constraint row by a returned point (ipopt's
``acceptable_constr_viol_tol``); bounds on the variables are checked to 1e-6 (relative)."""


@dataclass(frozen=True)
class NMPCConfig:
    """Settings of :class:`NMPC` (pereira2022 §5.2: N = 30; the rest are our choices).

    Args:
        horizon: N, prediction steps (<= 200; was the servicing scenario's ``horizon``).
        solver: ``"ipopt"`` (the reference, and the paper reproduction's), ``"ipopt-jit"`` (ipopt on
            gcc-compiled problem functions: the same iterates to round-off; compiled once per
            process), ``"fatrop"`` or ``"rti"`` (one DAQP QP per decision about the shifted plan,
            ipopt for cold decisions and failed QPs; module docstring); max_iter, tol: the NLP
            solver's iteration limit and tolerance.
        order: ``"sequential"`` (Gauss-Seidel) or ``"jacobi"``.
        initial_guess: ``"arc"`` or ``"hold"`` (module docstring); preview: the waypoint schedule
            over the horizon instead of the current waypoint.
        keepout_margin, separation_margin [m]: added to the keep-out / separation radii.
        bound_margin: relative tightening of the velocity / angular-velocity bounds (< 1).
        rk4_steps: attitude RK4 steps per T_s (<= 100); formulation: ``"sx"`` or ``"mx"``.
        terminal_attitude_weight: multiplier of the attitude weights (Q_q, Q_w) on ``x_N`` (ours,
            100 by default; 0 is eq. 39 as published).
        hessian: ``"gauss-newton"`` (ipopt solvers only): ``2 J^T J`` of the cost residuals plus
            the path rows' exact curvature, without the dynamics' and the attitude reference's
            second derivatives; ``"exact"``: the solver's Hessian of the Lagrangian (the
            reference); ``None`` (default): Gauss-Newton for ipopt, exact for fatrop. The same
            optimum (the Hessian shapes the steps, not the KKT point: first controls within 4e-7 N
            at ``tol=1e-8`` on recorded §5.2 problems), 1.5-1.9x faster per solve.
        solver_options: extra CasADi ``nlpsol`` options (a dict with string keys).
        seed: unused (the NMPC is deterministic); accepted for the common policy signature.
        solve_time_limit: wall-time limit [s] of one solve (None: none); a solve over it is a
            flagged failure like any other (``satenv.baselines.base.guarded_solve``): a stall guard, the
            median ipopt solve is 20-40 ms; ipopt's own max_wall_time is set to it.
        quaternion_error: ``"sign-free"`` (default, ours: ``1 - |eta~|``, blind to the sign of
            ``q_d``) or ``"signed"`` (``1 - eta~`` as eq. 39 prints it).
    """

    horizon: int = 30
    solver: str = "ipopt"
    order: str = "sequential"
    initial_guess: str = "arc"
    preview: bool = False
    keepout_margin: float = 1e-3
    separation_margin: float = 1e-3
    bound_margin: float = 1e-4
    rk4_steps: int = 1
    max_iter: int = 200
    tol: float = 1e-6
    formulation: str = "sx"
    terminal_attitude_weight: float = 100.0
    hessian: str | None = None
    solver_options: dict | None = None
    seed: int | None = None
    solve_time_limit: float | None = 10.0
    quaternion_error: str = "sign-free"

    def __post_init__(self) -> None:
        rules: dict[str, Any] = {
            "quaternion_error": partial(choice, choices=QUATERNION_ERRORS),
            "solve_time_limit": time_limit,
            "horizon": partial(integer, high=MAX_HORIZON), "max_iter": integer,
            "rk4_steps": partial(integer, high=100),
            "solver": partial(choice, choices=_SOLVERS),
            "order": partial(choice, choices=("sequential", "jacobi")),
            "initial_guess": partial(choice, choices=("arc", "hold")),
            "formulation": partial(choice, choices=("sx", "mx")), "preview": flag,
            "keepout_margin": partial(number, zero_ok=True),
            "separation_margin": partial(number, zero_ok=True),
            "bound_margin": partial(number, zero_ok=True, high=0.999999), "tol": number,
            "terminal_attitude_weight": partial(number, zero_ok=True),
        }
        if self.seed is not None:
            rules["seed"] = partial(integer, low=0, high=2**63 - 1)
        if self.hessian is not None:
            rules["hessian"] = partial(choice, choices=("exact", "gauss-newton"))
        validate(self, "NMPC", rules)
        if self.hessian == "gauss-newton" and self.solver == "fatrop":
            raise BaselineError("NMPC option hessian='gauss-newton' needs an ipopt solver "
                                "('ipopt' or 'ipopt-jit'), got solver='fatrop'")
        opts = self.solver_options
        if opts is not None and (not isinstance(opts, dict) or not all(isinstance(k, str) for k in opts)):
            raise BaselineError(f"NMPC option solver_options must be a dict with string keys, got {opts!r}")


class NMPC(Baseline):
    """Cooperative NMPC of pereira2022 §4 (see the module docstring).

    Privileged: it reads the env's true global state (``env.state()``: every spacecraft's state,
    the current waypoints and the time) and the scenario, not the observations.

    Args:
        env: a ``servicing_v0`` env.
        config: an :class:`NMPCConfig` (default: N = 30, ipopt); ``**options`` replace fields.
    """

    name = "nmpc"
    env_ids = ("servicing_v0",)
    cheap = False

    def __init__(self, env: Any, config: NMPCConfig | None = None, **options: Any) -> None:
        check_env(type(self), env)
        cfg = self.cfg = config_from_options(NMPCConfig, options, "NMPC", base=config)
        sc = nominal(env).scenario
        self.env = env
        self.scenario = sc
        self.agents = list(env.possible_agents)
        self.m = len(self.agents)
        self.N = cfg.horizon
        self.solver = "ipopt" if cfg.solver == "rti" else cfg.solver     # the NLP's solver
        self.order = cfg.order
        self.initial_guess = cfg.initial_guess
        self.preview = cfg.preview
        self.keepout = sc.keepout_radius + cfg.keepout_margin
        self.separation = sc.separation_radius + cfg.separation_margin
        self.u_max = np.asarray(sc.u_max, dtype=float)
        self.v_lim = sc.v_max * (1.0 - cfg.bound_margin)
        self.w_lim = sc.omega_max * (1.0 - cfg.bound_margin)
        self.rk4_steps = cfg.rk4_steps
        self.formulation = cfg.formulation
        self.terminal_attitude_weight = cfg.terminal_attitude_weight
        self.signed_quaternion_error = cfg.quaternion_error == "signed"
        self.hessian = cfg.hessian or ("exact" if cfg.solver == "fatrop" else "gauss-newton")
        self._f, self._F = build_model(sc, self.rk4_steps)
        self._a_cw = cw_continuous(sc.mean_motion)[0]
        self._j_f = np.array(sc.inertia)
        self._alloc = np.linalg.inv(np.vstack(thruster_matrices(sc.dimensions)))
        self._build(cfg.max_iter, cfg.tol, dict(cfg.solver_options or {}))
        self.info: dict[str, Any] = {}
        self.reset()

    # ------------------------------------------------------------------ NLP
    def _build(self, max_iter: int, tol: float, extra: dict) -> None:
        import casadi as ca

        sc, n_h, m = self.scenario, self.N, self.m
        nx, nu = 13, 6
        sym = ca.MX if self.formulation == "mx" else ca.SX
        xs = [sym.sym(f"x{k}", nx) for k in range(n_h + 1)]
        us = [sym.sym(f"u{k}", nu) for k in range(n_h)]
        x_init = sym.sym("x_init", nx)
        p_d = sym.sym("p_d", 3, n_h)
        others = sym.sym("others", 3, n_h * max(m - 1, 0))

        def path(x, k):   # constraints on x_k, k = 1..N
            p = x[0:3]
            rows = [ca.sumsqr(p)]
            for j in range(m - 1):
                rows.append(ca.sumsqr(p - others[:, j * n_h + k - 1]))
            return rows

        cost = 0
        res = []                                           # sqrt-weighted residuals: cost = |res|^2
        g, lbg, ubg = [], [], []
        n_path = 1 + (m - 1)
        path_lb = [self.keepout**2] + [self.separation**2] * (m - 1)
        for k in range(n_h):
            x, u = xs[k], us[k]
            stage_cost, stage_res = self._stage_terms(x, u, p_d[:, k])
            cost += stage_cost
            res.append(stage_res)
            g.append(xs[k + 1] - self._F(x, u))           # dynamics first in each stage (fatrop)
            lbg += [0.0] * nx
            ubg += [0.0] * nx
            if k == 0:
                g.append(x - x_init)
                lbg += [0.0] * nx
                ubg += [0.0] * nx
            else:
                g += path(x, k)
                lbg += path_lb
                ubg += [np.inf] * n_path
        if self.terminal_attitude_weight > 0:           # terminal attitude cost (ours; not in eq. 39)
            terminal_cost, terminal_res = self._terminal_terms(xs[n_h])
            cost += terminal_cost
            res.append(terminal_res)
        g += path(xs[n_h], n_h)
        lbg += path_lb
        ubg += [np.inf] * n_path

        w_vars = []
        lbx, ubx = [], []
        big = np.inf
        x_lb = np.r_[[-big] * 3, [-self.v_lim] * 3, [-big] * 4, [-self.w_lim] * 3]
        for k in range(n_h + 1):
            w_vars.append(xs[k])
            if k == 0:
                lbx.append(np.full(nx, -big))
                ubx.append(np.full(nx, big))
            else:
                lbx.append(x_lb)
                ubx.append(-x_lb)
            if k < n_h:
                w_vars.append(us[k])
                lbx.append(-self.u_max)
                ubx.append(self.u_max)
        params = ca.vertcat(x_init, ca.vec(p_d), ca.vec(others))
        nlp = {"x": ca.vertcat(*w_vars), "f": cost, "g": ca.vertcat(*g), "p": params}
        if self.solver.startswith("ipopt"):
            opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                    "ipopt.max_iter": int(max_iter), "ipopt.tol": float(tol),
                    "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-3,
                    "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6}
            if self.cfg.solve_time_limit is not None:
                opts["ipopt.max_wall_time"] = float(self.cfg.solve_time_limit)
        else:
            opts = {"print_time": False, "structure_detection": "auto", "expand": True,
                    "fatrop.print_level": 0, "fatrop.max_iter": int(max_iter), "fatrop.tol": float(tol),
                    "fatrop.mu_init": 1e-3}
        if self.solver == "fatrop":
            opts["equality"] = [bool(lo == hi) for lo, hi in zip(lbg, ubg, strict=True)]
        if self.solver == "ipopt-jit":
            opts.update(JIT_OPTIONS)
        self._lbx = np.concatenate(lbx)
        self._ubx = np.concatenate(ubx)
        self._lbg = np.asarray(lbg, dtype=float)
        self._ubg = np.asarray(ubg, dtype=float)
        self._nw = self._lbx.size
        self._ng = self._lbg.size
        stride = nx + nu
        self._x_idx = np.array([k * stride + np.arange(nx) for k in range(n_h + 1)])   # (N+1, 13)
        self._u_idx = np.array([k * stride + nx + np.arange(nu) for k in range(n_h)])  # (N, 6)
        # constraint rows: stage k = [dynamics (13), init (13) if k == 0 else path(x_k)], path(x_N)
        dyn, pth, row = [], [], 0
        for k in range(n_h):
            dyn.append(row + np.arange(nx))
            row += nx
            if k == 0:
                self._init_rows = row + np.arange(nx)
                row += nx
            else:
                pth.append(row + np.arange(n_path))
                row += n_path
        pth.append(row + np.arange(n_path))
        self._dyn_rows = np.array(dyn)            # (N, 13): x_{k+1} - F(x_k, u_k)
        self._path_rows = np.array(pth)           # (N, n_path): path constraints on x_1 .. x_N
        if self.hessian == "gauss-newton":
            opts["hess_lag"] = self._gauss_newton_hessian(nlp, ca.vertcat(*res))
        opts.update(extra)
        key = ("nmpc", repr(sc), repr(dataclasses.replace(self.cfg, seed=None, solver=self.solver)), m)
        self._nlp = nlpsol_cached(key, lambda: ca.nlpsol("servicing_nmpc", self.solver.removesuffix("-jit"),
                                                         nlp, opts))
        if self.cfg.solver == "rti":
            self._rti = [BufferedFunction(f) for f in nlpsol_cached(("nmpc-rti", *key[1:]), self._rti_functions)]
            self._qp = DenseQP()
            self._rti_sizes = np.cumsum([0, nx, nx * nx, nx * nu, 19, 19 * nx, 19 * nu])
            self._rti_bound_states = np.array([3, 4, 5, 10, 11, 12])
            self._rti_limits = np.tile(np.r_[[self.v_lim] * 3, [self.w_lim] * 3], n_h)
            self._rti_u_box = np.tile(self.u_max, n_h)
            self._rti_shifts: dict[tuple[int, int], np.ndarray] = {}

    def _stage_terms(self, x: Any, u: Any, p_d: Any) -> tuple[Any, Any]:
        """Stage cost of eq. 39 at ``(x_k, u_k)`` for the waypoint ``p_d`` and its sqrt-weighted
        residuals (cost = ``|res|^2``, 19 rows: position, velocity, quaternion, rate, input)."""
        import casadi as ca

        sc = self.scenario
        qp, qv = ca.DM(sc.position_weight), ca.DM(sc.velocity_weight)
        qq, qw, hh = ca.DM(sc.quaternion_weight), ca.DM(sc.omega_weight), ca.DM(sc.input_weight)
        q_d, w_d = attitude_reference_sym(sc, x[0:3], x[3:6], x[6:10])   # eq. 43-49
        ep, ev, ew = x[0:3] - p_d, x[3:6] - ca.DM(sc.desired_velocity), x[10:13] - w_d
        qe = quaternion_cost_terms(x[6:10], q_d, self.signed_quaternion_error)
        cost = (ca.dot(qp, ep**2) + ca.dot(qv, ev**2) + ca.dot(qq, qe**2)
                + ca.dot(qw, ew**2) + ca.dot(hh, u**2))
        res = ca.vertcat(ca.sqrt(qp) * ep, ca.sqrt(qv) * ev, ca.sqrt(qq) * qe, ca.sqrt(qw) * ew, ca.sqrt(hh) * u)
        return cost, res

    def _terminal_terms(self, x: Any) -> tuple[Any, Any]:
        """The terminal attitude cost at ``x_N`` (ours) and its residuals (7 rows)."""
        import casadi as ca

        sc = self.scenario
        qq, qw = ca.DM(sc.quaternion_weight), ca.DM(sc.omega_weight)
        q_d, w_d = attitude_reference_sym(sc, x[0:3], x[3:6], x[6:10])
        qe, ew = quaternion_cost_terms(x[6:10], q_d, self.signed_quaternion_error), x[10:13] - w_d
        cost = self.terminal_attitude_weight * (ca.dot(qq, qe**2) + ca.dot(qw, ew**2))
        c = float(np.sqrt(self.terminal_attitude_weight))
        return cost, ca.vertcat(c * ca.sqrt(qq) * qe, c * ca.sqrt(qw) * ew)

    def _gauss_newton_hessian(self, nlp: dict, res: Any) -> Any:
        """``hess_lag`` for ipopt: ``lam_f 2 J^T J`` (``J`` the Jacobian of the cost residuals, cost
        = ``|res|^2``) plus the exact Hessian of the path rows (``2 lam I`` on the positions); the
        curvature of the dynamics and of the attitude reference is left out."""
        import casadi as ca

        w = nlp["x"]
        sym = ca.MX if isinstance(w, ca.MX) else ca.SX
        lam_f, lam_g = sym.sym("lam_f"), sym.sym("lam_g", self._ng)
        rows = self._path_rows.ravel()
        jac = ca.jacobian(res, w)
        h = lam_f * 2 * ca.mtimes(jac.T, jac) + ca.hessian(ca.dot(lam_g[rows], nlp["g"][rows]), w)[0]
        return ca.Function("nlp_hess_l", [w, nlp["p"], lam_f, lam_g], [ca.triu(h)],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])

    def _rti_functions(self) -> tuple[Any, Any]:
        """The linearisation of one RTI step: ``stage(x, u, p_d)`` mapped over the N stages, each
        column ``[F, vec dF/dx, vec dF/du, res, vec dres/dx, vec dres/du]``, and ``terminal(x_N)``
        ``[res_N, vec dres_N/dx]`` (the terminal attitude residuals; empty without them). The stage
        function is compiled with gcc once per process (a few seconds; 75x faster than the
        interpreted one, whose Jacobians of eq. 43-49 took most of a decision)."""
        import casadi as ca

        x, u, p_d = ca.SX.sym("x", 13), ca.SX.sym("u", 6), ca.SX.sym("p_d", 3)
        x_next = self._F(x, u)
        res = self._stage_terms(x, u, p_d)[1]
        stage = ca.Function("nmpc_rti_stage", [x, u, p_d], [ca.densify(ca.vertcat(
            x_next, ca.vec(ca.jacobian(x_next, x)), ca.vec(ca.jacobian(x_next, u)),
            res, ca.vec(ca.jacobian(res, x)), ca.vec(ca.jacobian(res, u))))], JIT_OPTIONS)
        res_n = self._terminal_terms(x)[1] if self.terminal_attitude_weight > 0 else ca.SX(0, 1)
        terminal = ca.Function("nmpc_rti_terminal", [x], [ca.densify(ca.vertcat(res_n, ca.vec(ca.jacobian(res_n, x))))])
        return stage.map(self.N), terminal

    def _rti_qp(self, x0: np.ndarray, xg: np.ndarray, ug: np.ndarray, goal_path: np.ndarray,
                others: list[np.ndarray]) -> tuple[np.ndarray, ...]:
        """The condensed QP of one RTI step about the guess ``(xg, ug)`` (module docstring):
        ``(H, f, A, lo, hi, lb, ub, Phi, phi)`` over the input steps ``du`` (6N), with the state
        steps ``dx_k = Phi_k du + phi_k``.

        The Gauss-Newton Hessian is condensed by the backward recursion
        ``Z_N = Q_N Phi_N``, ``Z_k = Q_k Phi_k + A_k' Z_{k+1}`` (``Q_k = Jx_k' Jx_k``): its block row
        ``i`` is ``B_i' Z_{i+1}`` plus the state-input cross terms, O(N^2) instead of the O(N^3)
        product of the stacked residual Jacobian with itself."""
        n_h, nx, nu = self.N, 13, 6
        nv = nu * n_h
        stage, terminal = self._rti
        out = stage(xg[:-1].T, ug.T, goal_path.T)[0].T                     # (N, rows)
        sizes = self._rti_sizes
        part = [out[:, a:b] for a, b in zip(sizes[:-1], sizes[1:], strict=True)]
        a_k = part[1].reshape(n_h, nx, nx).transpose(0, 2, 1)             # column-major vec
        b_k = part[2].reshape(n_h, nu, nx).transpose(0, 2, 1)
        jrx = part[4].reshape(n_h, nx, 19).transpose(0, 2, 1)
        jru = part[5].reshape(n_h, nu, 19).transpose(0, 2, 1)
        defect = part[0] - xg[1:]                                         # F(x_k, u_k) - x_{k+1}
        phi_m = np.zeros((n_h + 1, nx, nv))
        phi = np.zeros((n_h + 1, nx))
        for k in range(n_h):
            cols = nu * k
            np.matmul(a_k[k], phi_m[k, :, :cols], out=phi_m[k + 1, :, :cols])
            phi_m[k + 1, :, cols:cols + nu] = b_k[k]
            phi[k + 1] = a_k[k] @ phi[k] + defect[k]
        c = part[3] + (jrx @ phi[:n_h, :, None])[..., 0]                 # residuals at du = 0
        jrx_t = jrx.transpose(0, 2, 1)
        q_k = jrx_t @ jrx                                                   # (N, 13, 13)
        s_k = jrx_t @ jru                                                   # (N, 13, 6)
        q_phi = q_k @ phi_m[:n_h]                                           # Q_k Phi_k
        gx = (jrx_t @ c[..., None])[..., 0]                                 # Jx_k' c_k
        jru_t = jru.transpose(0, 2, 1)
        gu = (jru_t @ c[..., None])[..., 0]                                 # Ju_k' c_k
        term = terminal(xg[-1])[0].ravel()
        z = np.zeros((nx, nv))
        zg = np.zeros(nx)
        if term.size:
            n_t = term.size // (1 + nx)
            j_n = term[n_t:].reshape(nx, n_t).T
            c_n = term[:n_t] + j_n @ phi[n_h]
            z = j_n.T @ (j_n @ phi_m[n_h])
            zg = j_n.T @ c_n
        half = np.empty((n_h, nu, nv))                                     # block rows of H / 2
        grad = np.empty((n_h, nu))
        for k in range(n_h - 1, -1, -1):                                   # z = Z_{k+1}
            half[k] = b_k[k].T @ z
            grad[k] = b_k[k].T @ zg
            z = q_phi[k] + a_k[k].T @ z
            zg = gx[k] + a_k[k].T @ zg
        half = half.reshape(nv, nv)
        cross = (s_k.transpose(0, 2, 1) @ phi_m[:n_h]).reshape(nv, nv)      # S_k' Phi_k
        half += cross + cross.T
        r_blocks = jru_t @ jru
        diag = np.arange(nv).reshape(n_h, nu)
        half[diag[:, :, None], diag[:, None, :]] += r_blocks
        hess = half + half.T                                                # 2 J'J, symmetric
        grad = 2.0 * (grad + gu).ravel()
        # velocity and rate bounds on x_1..x_N, then the keep-out and collision rows linearised
        # at the guess's positions (tangent half-spaces: inside the true feasible set)
        idx = self._rti_bound_states
        rows = np.empty((self._rti_rows(len(others)), nv))
        n_b = nu * n_h
        rows[:n_b] = phi_m[1:, idx].reshape(-1, nv)
        base = (xg[1:, idx] + phi[1:, idx]).ravel()
        lim = self._rti_limits
        lo, hi = [-lim - base], [lim - base]
        centres = [np.zeros((n_h, 3))] + list(others)
        radii = [self.keepout] + [self.separation] * len(others)
        for j, (ctr, r) in enumerate(zip(centres, radii, strict=True)):
            d = xg[1:, :3] - ctr
            rows[n_b + j * n_h:n_b + (j + 1) * n_h] = 2.0 * (d[:, None, :] @ phi_m[1:, :3])[:, 0]
            lo.append(r**2 - np.sum(d * d, axis=1) - 2.0 * np.sum(d * phi[1:, :3], axis=1))
            hi.append(np.full(n_h, QP_INFINITY))
        u_box = self._rti_u_box
        return (hess, grad, rows, np.concatenate(lo), np.concatenate(hi),
                -u_box - ug.ravel(), u_box - ug.ravel(), phi_m, phi)

    def _rti_rows(self, n_others: int) -> int:
        """Rows of the RTI QP: 6 velocity / rate bounds per stage, a keep-out and ``n_others``
        collision rows per stage."""
        return self.N * (6 + 1 + n_others)

    def _rti_shift(self, age: int, n_others: int) -> np.ndarray:
        """DAQP's warm start of a plan ``age`` steps older than the previous QP's: each constraint
        of the new QP (input bounds, then rows by group, stage-major) takes the active state of the
        previous QP's same constraint ``age`` stages later (the last stage's beyond the horizon)."""
        key = (age, n_others)
        if key not in self._rti_shifts:
            n_h, nu = self.N, 6
            stage = np.minimum(np.arange(n_h) + age, n_h - 1)
            bounds = (stage[:, None] * nu + np.arange(nu)).ravel()
            groups = [n_h * nu + (stage[:, None] * 6 + np.arange(6)).ravel()]
            for j in range(1 + n_others):
                groups.append(n_h * nu + n_h * 6 + j * n_h + stage)
            self._rti_shifts[key] = np.concatenate([bounds, *groups]).astype(np.intp)
        return self._rti_shifts[key]

    def _rti_step(self, i: int, x0: np.ndarray, goal_path: np.ndarray,
                  others: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """One RTI decision of spacecraft ``i``: the QP about its shifted previous plan, solved by
        DAQP through :func:`guarded_solve`; the new plan, or ``None`` when the QP failed."""
        w0, _ = self._initial_guess(i, x0, goal_path[0])
        xg, ug = w0[self._x_idx], w0[self._u_idx]
        t0 = time.perf_counter()
        h, f, a, lo, hi, lb, ub, phi_m, phi = self._rti_qp(x0, xg, ug, goal_path, others)
        shift = self._rti_shift(self._step - self._plans[i]["t0"], len(others))
        du = guarded_solve(self.info, lambda: self._qp.solve(h, f, a, lo, hi, lb, ub, owner=i, shift=shift),
                           shape=(f.size,), lower=lb, upper=ub, fallback=False, tol=QP_ROW_TOL,
                           violation=lambda d: row_violation(a @ d, lo, hi), violation_tol=QP_ROW_TOL,
                           time_limit=self.cfg.solve_time_limit)
        self.info["qp_ms"].append((time.perf_counter() - t0) * 1e3)
        if du is None:
            self.info["rti_fallbacks"] += 1
            return None
        us = ug + du.reshape(self.N, 6)
        xs = xg + phi_m @ du + phi
        xs[0] = x0
        self._plans[i] = {"x": xs, "u": us, "t0": self._step, "duals": None}
        self._last_goal[i] = goal_path[0].copy()
        return us[0], xs[:, :3]

    def _cold(self, i: int, goal: np.ndarray) -> bool:
        """No plan to warm-start from: the first decision, or a new waypoint with the arc guess."""
        changed = self._last_goal[i] is None or not np.allclose(self._last_goal[i], goal)
        return self._plans[i] is None or (changed and self.initial_guess == "arc")

    # ------------------------------------------------------------------ policy API
    def reset(self, seed: int | None = None) -> None:
        self.info = new_info(solve_ms=[], agent_solve_ms=[], iterations=[], statuses=Counter(),
                             fallback_steps=[], qp_ms=[], rti_steps=0, rti_fallbacks=0, nlp_solves=0)
        self._plans: list[dict[str, Any] | None] = [None] * self.m
        if self.cfg.solver == "rti":
            self._qp.forget()
        self._last_goal: list[np.ndarray | None] = [None] * self.m
        self._step = 0

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        start = time.perf_counter()
        sc = self.scenario
        x, goals, t = unpack_global_state(self.env.state(), self.m)
        step = int(round(t / sc.dt))
        # published plans, shifted to the current step (positions k = 0..N)
        self._step = step
        shifted = [self._shifted_positions(i) for i in range(self.m)]
        fresh: list[np.ndarray | None] = [None] * self.m
        u_out = np.zeros((self.m, 6))
        for i in range(self.m):
            others = []
            for j in range(self.m):
                if j == i:
                    continue
                pj = fresh[j] if (self.order == "sequential" and fresh[j] is not None) else shifted[j]
                others.append(pj[1:] if pj is not None else np.tile(x[j, :3], (self.N, 1)))
            goal_path = self._goal_path(i, goals[i], step)
            u_out[i], fresh[i] = self._solve_agent(i, x[i], goal_path, others)
        self.info["solve_ms"].append((time.perf_counter() - start) * 1e3)
        act = np.clip(u_out / self.u_max, -1.0, 1.0)
        return {a: act[self.agents.index(a)].astype(np.float32) for a in observations}

    # ------------------------------------------------------------------ internals
    def _goal_path(self, i: int, goal: np.ndarray, step: int) -> np.ndarray:
        if not self.preview:
            return np.tile(goal, (self.N, 1))
        wp = self.scenario.waypoint_array()
        return wp[self.scenario.phase(step + np.arange(self.N)), i]

    def _shifted_positions(self, i: int) -> np.ndarray | None:
        plan = self._plans[i]
        if plan is None:
            return None
        idx = np.minimum(np.arange(self.N + 1) + self._step - plan["t0"], self.N)
        return plan["x"][idx, :3]

    def _arc_guess(self, x0: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """States (N+1, 13) along a great-circle arc from p towards the goal (outside the keep-out)."""
        sc = self.scenario
        p0 = x0[:3]
        r0 = max(np.linalg.norm(p0), self.keepout + 0.05)
        a = p0 / np.linalg.norm(p0)
        b = goal / max(np.linalg.norm(goal), 1e-9)
        ang = np.arccos(np.clip(a @ b, -1, 1))
        perp = b - (a @ b) * a
        if np.linalg.norm(perp) < 1e-6:      # goal opposite (or equal): pick a tie-break plane
            for cand in (np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0])):
                perp = cand - (cand @ a) * a
                if np.linalg.norm(perp) > 0.1:
                    break
        perp /= np.linalg.norm(perp)
        speed = 0.5 * sc.v_max
        t = np.arange(self.N + 1) * sc.dt
        s = np.minimum(speed * t / r0, ang)                     # arc angle travelled
        pos = r0 * (np.cos(s)[:, None] * a + np.sin(s)[:, None] * perp)
        vel = np.gradient(pos, sc.dt, axis=0)
        guess = np.tile(x0, (self.N + 1, 1))
        guess[:, :3] = pos
        guess[:, 3:6] = np.clip(vel, -self.v_lim, self.v_lim)
        guess[0] = x0
        guess[:, 10:13] = 0.0
        guess[0, 10:13] = x0[10:13]
        return guess

    def _initial_guess(self, i: int, x0: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, dict]:
        plan = self._plans[i]
        if not self._cold(i, goal):
            age = self._step - plan["t0"]
            idx = np.minimum(np.arange(self.N + 1) + age, self.N)
            xg = plan["x"][idx].copy()
            ug = plan["u"][np.minimum(np.arange(self.N) + age, self.N - 1)].copy()
            xg[0] = x0
            duals = self._shift_duals(plan["duals"], age) if plan["duals"] is not None else {}
            return self._pack(xg, ug), duals
        if self.initial_guess == "arc":
            xg = self._arc_guess(x0, goal)
        else:
            xg = np.tile(x0, (self.N + 1, 1))
        return self._pack(xg, np.zeros((self.N, 6))), {}

    def _shift_duals(self, duals: dict[str, np.ndarray], age: int) -> dict[str, np.ndarray]:
        """Multipliers of a plan computed ``age`` steps ago, moved to the current stages."""
        kx = np.minimum(np.arange(self.N + 1) + age, self.N)
        ku = np.minimum(np.arange(self.N) + age, self.N - 1)
        lam_x = np.zeros(self._nw)
        lam_x[self._x_idx] = duals["lam_x"][self._x_idx[kx]]
        lam_x[self._u_idx] = duals["lam_x"][self._u_idx[ku]]
        lam_x[self._x_idx[0]] = 0.0
        lam_g = np.zeros(self._ng)
        lam_g[self._dyn_rows] = duals["lam_g"][self._dyn_rows[ku]]
        lam_g[self._path_rows] = duals["lam_g"][self._path_rows[ku]]
        lam_g[self._init_rows] = duals["lam_g"][self._init_rows]
        return {"lam_x": lam_x, "lam_g": lam_g}

    def _pack(self, xg: np.ndarray, ug: np.ndarray) -> np.ndarray:
        w = np.zeros(self._nw)
        w[self._x_idx] = xg
        w[self._u_idx] = ug
        return w

    def _solve_agent(self, i: int, x0: np.ndarray, goal_path: np.ndarray,
                     others: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray | None]:
        if self.cfg.solver == "rti" and not self._cold(i, goal_path[0]):
            t0 = time.perf_counter()
            step = self._rti_step(i, x0, goal_path, others)
            if step is not None:
                self.info["rti_steps"] += 1
                self.info["agent_solve_ms"].append((time.perf_counter() - t0) * 1e3)
                self.info["iterations"].append(1)
                self.info["statuses"]["rti"] += 1
                return step
        self.info["nlp_solves"] += 1
        if self.cfg.solver == "rti":
            self._qp.forget(i)                   # the next QP starts after this NLP's plan, cold
        w0, duals = self._initial_guess(i, x0, goal_path[0])
        oth = np.concatenate(others, axis=0).T if others else np.zeros((3, 0))
        params = np.concatenate([x0, goal_path.T.ravel(order="F"), oth.ravel(order="F")])
        args = {"x0": w0, "p": params, "lbx": self._lbx, "ubx": self._ubx,
                "lbg": self._lbg, "ubg": self._ubg}
        if duals:
            args["lam_x0"], args["lam_g0"] = duals["lam_x"], duals["lam_g"]
        t0 = time.perf_counter()
        out: dict[str, Any] = {}
        w = guarded_solve(self.info, lambda: self._run_nlp(args, out), shape=(self._nw,),
                          lower=self._lbx, upper=self._ubx, fallback=False,
                          violation=lambda _: row_violation(out["g"], self._lbg, self._ubg),
                          violation_tol=NLP_CONSTRAINT_TOL, time_limit=self.cfg.solve_time_limit)
        stats = out.get("stats", {})
        self.info["agent_solve_ms"].append((time.perf_counter() - t0) * 1e3)
        self.info["iterations"].append(int(stats.get("iter_count", -1)) if stats else -1)
        self.info["statuses"][out.get("status", self.info["solver_status"])] += 1
        self._last_goal[i] = goal_path[0].copy()
        if w is not None:
            sol = out["sol"]
            xs, us = w[self._x_idx], w[self._u_idx]
            self._plans[i] = {"x": xs, "u": us, "t0": self._step,
                              "duals": {"lam_x": np.asarray(sol["lam_x"]).ravel(),
                                        "lam_g": np.asarray(sol["lam_g"]).ravel()}}
            return us[0], xs[:, :3]
        # fallback: the next input of the last successful plan, else brake and hold
        record_fallback(self.info, self.info["solver_status"])
        self.info["fallback_steps"].append((i, self.info["solver_status"]))
        plan = self._plans[i]
        if plan is not None and self._step - plan["t0"] < self.N:
            return plan["u"][self._step - plan["t0"]].copy(), None
        self._plans[i] = None
        return self.safe_action(x0), None

    def _run_nlp(self, args: dict[str, Any], out: dict[str, Any]) -> tuple[np.ndarray, bool, str]:
        """One CasADi solve; keeps the solution, its stats and constraint values in ``out``."""
        sol = self._nlp(**args)
        stats = self._nlp.stats()
        status = str(stats.get("return_status", "unknown"))
        out.update(sol=sol, stats=stats, status=status, g=np.asarray(sol["g"]).ravel())
        return np.asarray(sol["x"]).ravel(), bool(stats.get("success", False)) or status in _OK, status

    def safe_action(self, x: np.ndarray) -> np.ndarray:
        """Brake and hold: cancel the CW drift, damp v and omega, push out of the keep-out.

        The six inputs realising the force/torque pair through ``[F_t; F_r]^-1`` (lvlh thrust),
        scaled down uniformly into the input box.
        """
        p, v, w = x[:3], x[3:6], x[10:13]
        a = -self._a_cw[3:] @ x[:6] - 1.0 * v
        r = np.linalg.norm(p)
        if r < self.keepout + 0.5:
            a += 2.0 * (self.keepout + 0.5 - r) * p / max(r, 1e-9)
        if self.scenario.thrust_frame == "body":
            from satenv.dynamics.attitude import quat_to_matrix

            a = quat_to_matrix(x[6:10]).T @ a
        tau = -1.0 * self._j_f @ w
        u = self._alloc @ np.concatenate([a, tau])
        peak = np.max(np.abs(u) / self.u_max)
        return u / peak if peak > 1.0 else u
