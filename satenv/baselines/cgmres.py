"""Centralised NMPC solved by Ohtsuka's continuation/GMRES method (C/GMRES), kannan2022 §5.

The controller of kannan2022 (Ohtsuka 2004, "A continuation/GMRES method for fast computation of
nonlinear receding horizon control", Automatica 40(4)) for the three spacecraft of
``satenv.formation_v0``, centralised (one problem over all spacecraft).

Optimal control problem (continuous time, horizon ``T(t) = T_f (1 - exp(-alpha t))``)::

    min  int_t^{t+T} L(x, w, v) dtau          (no terminal cost: kannan2022 eq. 12)
    s.t. dx/dtau = A_c x + B_c u_max w         (CW, eqs. 2-5, block-diagonal over spacecraft)
         w_j^2 + v_j^2 - 1 = 0                 (input bound |u_j| <= u_max with dummy input v_j)
    L = 1/2 sum_i (e_i/L)^T diag(q_i) (e_i/L) + 1/2 r |w|^2 - r_v sum_j v_j

with ``w = u / u_max`` the normalised input (= the env action), ``e_i`` the cost (33)/(34)
position error of spacecraft i and its weights ``q_i``, ``r`` from the scenario
(:mod:`satenv.scenarios.formation`). ``thrust_mode="norm"`` uses one constraint
``|w_i|^2 + v_i^2 = 1`` per spacecraft instead. The dummy-input penalty ``r_v`` (Ohtsuka's
device to pick ``v > 0`` and keep the Jacobian regular) acts near ``w = 0`` like an extra input
weight ``r_v / 2``; both solvers below solve exactly this problem.

The horizon is discretised with ``N`` forward-Euler steps ``dtau = T / N``. The unknown is the
stacked sequence ``U = [w_i, v_i, mu_i]_{i=0..N-1}`` (``mu`` the constraint multipliers) and the
optimality conditions are ``F(U, x, t) = [H_w, H_v, C]_i = 0`` with the Hamiltonian
``H = L + lambda^T f + mu^T C``, states by a forward sweep and costates by the backward sweep
``lambda_N = 0, lambda_i = lambda_{i+1} + H_x dtau`` (these are exactly the KKT conditions of the
discretised NLP, see :meth:`FormationOCP.solve_ipopt`). ``f``, ``H_x`` and ``H_z`` come from
CasADi (one compiled ``F`` graph, evaluated through its buffer interface).

Continuation: instead of solving ``F = 0`` at every sample, ``U`` is integrated so that
``dF/dt = -zeta F``: ``F_U dU/dt = -zeta F - F_x dx/dt - F_t``, solved by GMRES (``kmax``
Arnoldi steps, restarted from the previous ``dU/dt``) with the matrix-free forward differences
``F_U w ~ (F(U + h w, x + h dx, t + h) - F(U, x + h dx, t + h)) / h``; then
``U <- U + dU/dt * dt``. The first sample starts at ``T = 0``, where ``F = 0`` is solved by
Newton's method (:meth:`FormationOCP.refine`).

Safety (the shared guard :func:`satenv.baselines.base.guarded_solve` around the Newton restart and every
continuation step): an exception, a wrong-shaped or non-finite update, a GMRES solve that leaves more
than ``fallback_tol`` of the right-hand side unresolved, or an optimality residual ``|F|`` above
``max_residual`` is a failure: the controller commands zero thrust for that step (kannan2022 §3:
``u = 0`` is always admissible), counts it in ``info["fallbacks"]`` (why: ``info["solver_status"]``)
and restarts the continuation from ``T = 0`` at the next sample.
The applied input is clipped to ``[-1, 1]``.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import casadi as ca
import numpy as np

from satenv.baselines.base import (
    MAX_HORIZON,
    Baseline,
    check_env,
    config_from_options,
    guarded_solve,
    integer,
    new_info,
    number,
    time_limit,
    validate,
)
from satenv.dynamics import cw_continuous
from satenv.perturbations import nominal

__all__ = ["CGMRES", "CGMRESConfig", "FormationOCP", "gmres"]


class _BufferedFunction:
    """Fast numpy evaluation of a CasADi ``Function`` with dense inputs and one output."""

    def __init__(self, fun: ca.Function) -> None:
        self._buf, self._eval = fun.buffer()
        self._args = [np.zeros(fun.nnz_in(i)) for i in range(fun.n_in())]
        self._out = np.zeros(fun.nnz_out(0))
        for i, arg in enumerate(self._args):
            self._buf.set_arg(i, memoryview(arg))
        self._buf.set_res(0, memoryview(self._out))

    def __call__(self, *args) -> np.ndarray:
        for dst, src in zip(self._args, args, strict=True):
            dst[...] = src
        self._eval()
        return self._out.copy()


def gmres(matvec, b: np.ndarray, x0: np.ndarray, kmax: int) -> tuple[np.ndarray, float]:
    """``kmax`` steps of GMRES for ``A x = b`` from ``x0`` (modified Gram-Schmidt, Givens).

    Returns the solution and the relative residual ``|b - A x| / |b|`` (0 when ``b = 0``).
    """
    bnorm = float(np.linalg.norm(b))
    if bnorm == 0.0:
        return np.zeros_like(b), 0.0
    r = b - matvec(x0)
    beta = float(np.linalg.norm(r))
    if beta == 0.0 or not math.isfinite(beta):
        return x0, beta / bnorm
    n = b.size
    kmax = max(1, min(int(kmax), n))
    v = np.zeros((kmax + 1, n))
    h = np.zeros((kmax + 1, kmax))
    cs, sn = np.zeros(kmax), np.zeros(kmax)
    g = np.zeros(kmax + 1)
    g[0] = beta
    v[0] = r / beta
    used = 0
    for k in range(kmax):
        w = matvec(v[k])
        for i in range(k + 1):
            h[i, k] = w @ v[i]
            w -= h[i, k] * v[i]
        wnorm = float(np.linalg.norm(w))
        h[k + 1, k] = wnorm
        for i in range(k):  # previous rotations on the new column
            hi = h[i, k]
            h[i, k] = cs[i] * hi + sn[i] * h[i + 1, k]
            h[i + 1, k] = -sn[i] * hi + cs[i] * h[i + 1, k]
        denom = math.hypot(h[k, k], h[k + 1, k])
        if denom == 0.0 or not math.isfinite(denom):
            break
        cs[k], sn[k] = h[k, k] / denom, h[k + 1, k] / denom
        h[k, k], h[k + 1, k] = denom, 0.0
        g[k + 1] = -sn[k] * g[k]
        g[k] = cs[k] * g[k]
        used = k + 1
        if wnorm <= 1e-14 * beta or abs(g[k + 1]) <= 1e-14 * bnorm:
            break
        v[k + 1] = w / wnorm
    if used == 0:
        return x0, beta / bnorm
    y = np.linalg.solve(np.triu(h[:used, :used]), g[:used])
    return x0 + v[:used].T @ y, float(abs(g[used]) / bnorm)


class FormationOCP:
    """The kannan2022 NMPC problem of a formation scenario in Ohtsuka's form (module docstring).

    Args:
        scenario: a :class:`satenv.scenarios.formation.FormationScenario`.
        horizon_steps: N, Euler steps over the horizon.
        dummy_weight: r_v, weight of the dummy inputs' linear penalty.
    """

    def __init__(self, scenario: Any, horizon_steps: int = 30, dummy_weight: float = 0.1) -> None:
        self.scenario = scenario
        self.N = int(horizon_steps)
        self.r_v = float(dummy_weight)
        m = scenario.n_agents
        self.m, self.nx, self.nu = m, 6 * m, 3 * m
        self.nc = self.nu if scenario.thrust_mode == "box" else m
        self.nz = self.nu + 2 * self.nc
        self.dim = self.N * self.nz
        a_c, b_c = cw_continuous(scenario.mean_motion)
        self.a = np.kron(np.eye(m), a_c)
        self.b = np.kron(np.eye(m), b_c) * scenario.u_max
        # cost error e = E p - c (p the stacked positions), normalised by L
        ecal = np.eye(self.nu)
        fol = scenario.follows()
        for i in np.flatnonzero(fol):
            ecal[3 * i:3 * i + 3, 3 * scenario.leader:3 * scenario.leader + 3] -= np.eye(3)
        self.ecal = ecal / scenario.length_scale
        self.c = self.ecal @ scenario.target_positions().ravel()
        self.q = scenario.error_weights().ravel()
        self.r = float(scenario.input_weight)
        self._nlp_key: tuple | None = None
        self._build()

    # ------------------------------------------------------------------ symbolic model
    def _symbols(self):
        x = ca.SX.sym("x", self.nx)
        w = ca.SX.sym("w", self.nu)
        v = ca.SX.sym("v", self.nc)
        return x, w, v

    def _positions(self, x):
        return ca.vertcat(*[x[6 * i:6 * i + 3] for i in range(self.m)])

    def _stage_cost(self, x, w, v):
        e = ca.DM(self.ecal) @ self._positions(x) - ca.DM(self.c)
        return 0.5 * ca.dot(ca.DM(self.q) * e, e) + 0.5 * self.r * ca.dot(w, w) - self.r_v * ca.sum1(v)

    def _constraint(self, w, v):
        if self.nc == self.nu:
            return w**2 + v**2 - 1.0
        return ca.vertcat(*[ca.sumsqr(w[3 * i:3 * i + 3]) for i in range(self.m)]) + v**2 - 1.0

    def _dynamics(self, x, w):
        return ca.DM(self.a) @ x + ca.DM(self.b) @ w

    def _build(self) -> None:
        x, w, v = self._symbols()
        mu = ca.SX.sym("mu", self.nc)
        lam = ca.SX.sym("lam", self.nx)
        f = self._dynamics(x, w)
        c = self._constraint(w, v)
        ham = self._stage_cost(x, w, v) + ca.dot(lam, f) + ca.dot(mu, c)
        f_fun = ca.Function("f", [x, w], [f])
        hx = ca.Function("Hx", [x, w, v, mu, lam], [ca.gradient(ham, x)])
        hz = ca.Function("Hz", [x, w, v, mu, lam], [ca.vertcat(ca.gradient(ham, w), ca.gradient(ham, v), c)])
        u_all = ca.SX.sym("U", self.dim)
        x0 = ca.SX.sym("x0", self.nx)
        horizon = ca.SX.sym("T")
        dtau = horizon / self.N
        parts = [self._split(u_all[i * self.nz:(i + 1) * self.nz]) for i in range(self.N)]
        xs = [x0]
        for wi, _, _ in parts:
            xs.append(xs[-1] + f_fun(xs[-1], wi) * dtau)
        lam_next = ca.SX.zeros(self.nx)  # no terminal cost
        res = [None] * self.N
        for i in reversed(range(self.N)):
            wi, vi, mi = parts[i]
            res[i] = hz(xs[i], wi, vi, mi, lam_next)
            lam_next = lam_next + hx(xs[i], wi, vi, mi, lam_next) * dtau
        self.residual_function = ca.Function("F", [u_all, x0, horizon], [ca.vertcat(*res)])
        self._residual = _BufferedFunction(self.residual_function)
        self._f = _BufferedFunction(f_fun)

    def _split(self, z):
        nu, nc = self.nu, self.nc
        return z[:nu], z[nu:nu + nc], z[nu + nc:]

    # ------------------------------------------------------------------ numeric interface
    def residual(self, u_seq: np.ndarray, x: np.ndarray, horizon: float) -> np.ndarray:
        """Optimality residual ``F(U, x, T)`` (dim,)."""
        return self._residual(u_seq, x, horizon)

    def dynamics(self, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """``dx/dt`` of the prediction model (nx,) under normalised inputs ``w`` (nu,)."""
        return self._f(x, w)

    def initial_guess(self) -> np.ndarray:
        """``U`` with zero inputs, dummies 1 and multipliers ``r_v / 2`` (exact at ``T = 0``)."""
        z = np.concatenate([np.zeros(self.nu), np.ones(self.nc), np.full(self.nc, self.r_v / 2)])
        return np.tile(z, self.N)

    def first_input(self, u_seq: np.ndarray) -> np.ndarray:
        """The normalised input ``w_0`` (nu,) of a sequence ``U``."""
        return np.asarray(u_seq[:self.nu])

    def refine(self, u_seq: np.ndarray, x: np.ndarray, horizon: float, *, tol: float = 1e-9,
               max_iter: int = 50, kmax: int | None = None, fd_step: float = 1e-7) -> tuple[np.ndarray, float]:
        """Newton's method on ``F(U, x, T) = 0`` with matrix-free GMRES; returns (U, |F|)."""
        u_seq = np.array(u_seq, dtype=float)
        kmax = self.dim if kmax is None else kmax
        fval = self.residual(u_seq, x, horizon)
        for _ in range(max_iter):
            if np.linalg.norm(fval) <= tol:
                break
            base = fval

            def matvec(d, u_seq=u_seq, base=base):
                return (self.residual(u_seq + fd_step * d, x, horizon) - base) / fd_step

            step, _ = gmres(matvec, -fval, np.zeros_like(u_seq), kmax)
            u_seq = u_seq + step
            fval = self.residual(u_seq, x, horizon)
        return u_seq, float(np.linalg.norm(fval))

    def solve_ipopt(self, x: np.ndarray, horizon: float, guess: np.ndarray | None = None,
                    tol: float = 1e-10, print_level: int = 0) -> dict[str, Any]:
        """Solve the same discretised problem as an NLP with CasADi + ipopt.

        Variables ``w_i, v_i`` (``v >= 0``), states by the same Euler recursion (single shooting),
        objective ``sum_i L(x_i, w_i, v_i) dtau``, equality constraints ``C(w_i, v_i) = 0``.
        Returns ``{"U": (dim,) with mu_i = lam_g / dtau, "w0": first input, "success", "time_s",
        "status"}``.
        """
        key = ("ipopt", float(tol), int(print_level))
        if self._nlp_key != key:
            self._build_nlp(tol, print_level)
            self._nlp_key = key
        nu, nc, n = self.nu, self.nc, self.N
        if guess is None:
            guess = self.initial_guess()
        z = guess.reshape(n, self.nz)
        x_init = np.concatenate([z[:, :nu].ravel(), np.maximum(z[:, nu:nu + nc], 1e-6).ravel()])
        lam_init = (z[:, nu + nc:] * horizon / n).ravel()
        start = time.perf_counter()
        sol = self._solver(x0=x_init, p=np.concatenate([x, [horizon]]), lbx=self._lbx, ubx=self._ubx,
                           lbg=0.0, ubg=0.0, lam_g0=lam_init)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        var = np.asarray(sol["x"]).ravel()
        lam_g = np.asarray(sol["lam_g"]).ravel()
        w = var[:n * nu].reshape(n, nu)
        v = var[n * nu:].reshape(n, nc)
        dtau = horizon / n
        mu = lam_g.reshape(n, nc) / dtau if dtau > 0 else np.full((n, nc), self.r_v / 2)
        u_seq = np.concatenate([w, v, mu], axis=1).ravel()
        return {"U": u_seq, "w0": w[0].copy(), "success": bool(stats["success"]),
                "status": stats["return_status"], "time_s": elapsed}

    def _build_nlp(self, tol: float, print_level: int) -> None:
        nu, nc, n = self.nu, self.nc, self.N
        w_all = ca.SX.sym("w", n * nu)
        v_all = ca.SX.sym("v", n * nc)
        p = ca.SX.sym("p", self.nx + 1)
        x, dtau = p[:self.nx], p[self.nx] / n
        obj, g = 0, []
        for i in range(n):
            wi, vi = w_all[i * nu:(i + 1) * nu], v_all[i * nc:(i + 1) * nc]
            obj += self._stage_cost(x, wi, vi) * dtau
            g.append(self._constraint(wi, vi))
            x = x + self._dynamics(x, wi) * dtau
        nlp = {"x": ca.vertcat(w_all, v_all), "f": obj, "g": ca.vertcat(*g), "p": p}
        opts = {"ipopt.tol": tol, "ipopt.print_level": print_level, "print_time": False,
                "ipopt.sb": "yes", "ipopt.max_iter": 500}
        self._solver = ca.nlpsol("kannan2022_ocp", "ipopt", nlp, opts)
        self._lbx = np.concatenate([np.full(n * nu, -np.inf), np.zeros(n * nc)])
        self._ubx = np.full(n * (nu + nc), np.inf)


@dataclass(frozen=True)
class CGMRESConfig:
    """Settings of :class:`CGMRES` (our choices; kannan2022 gives no solver settings).

    ``T_f = 3 s``, ``N = 30``, ``alpha = 1 /s``, ``zeta = 1/dt``, ``kmax = 20``, ``h = 1e-6``,
    ``r_v = 0.1``: 810 unknowns for three spacecraft (27 per stage).

    Args:
        horizon: T_f [s]; horizon_steps: N, Euler steps over the horizon (<= 200).
        horizon_rate: alpha [1/s] of ``T(t) = T_f (1 - exp(-alpha t))``.
        zeta: continuation stabilisation gain [1/s]; ``None``: ``1 / dt`` of the env.
        kmax: GMRES iterations per update (<= 100000; GMRES also stops at the problem size).
        fd_step: h, forward-difference step; dummy_weight: r_v of the dummy inputs.
        gmres_tol: relative GMRES residual above which an update counts as inexact
            (``info["gmres_inexact"]``; the update is still applied).
        fallback_tol: relative GMRES residual above which the update is rejected (fallback).
        max_residual: |F| above which the continuation is considered diverged (fallback).
        newton_iterations: Newton steps of the restart at ``T = 0`` (:meth:`FormationOCP.refine`).
        solve_time_limit: wall-time limit [s] of one solve (None: none); a solve over it is a
            flagged failure like any other (``satenv.baselines.base.guarded_solve``): a stall guard, a
            continuation update takes milliseconds.
    """

    horizon: float = 3.0
    horizon_steps: int = 30
    horizon_rate: float = 1.0
    zeta: float | None = None
    kmax: int = 20
    fd_step: float = 1e-6
    dummy_weight: float = 0.1
    gmres_tol: float = 1e-2
    fallback_tol: float = 0.5
    max_residual: float = 1e3
    newton_iterations: int = 50
    solve_time_limit: float | None = 5.0

    def __post_init__(self) -> None:
        rules: dict[str, Any] = {name: number for name in (
            "horizon", "horizon_rate", "fd_step", "dummy_weight", "gmres_tol", "fallback_tol",
            "max_residual")}
        rules["horizon_steps"] = partial(integer, high=MAX_HORIZON)
        rules["kmax"] = rules["newton_iterations"] = integer
        rules["solve_time_limit"] = time_limit
        if self.zeta is not None:
            rules["zeta"] = number
        validate(self, "CGMRES", rules)

    def resolved(self, dt: float) -> dict[str, Any]:
        """The settings as a dict with ``zeta`` resolved for the env's ``dt``."""
        out = asdict(self)
        out["zeta"] = 1.0 / dt if self.zeta is None else self.zeta
        return out


class CGMRES(Baseline):
    """Centralised C/GMRES NMPC for ``satenv.formation_v0`` (module docstring).

    Privileged: it reads the env's true global state (``env.state()``) and the scenario's cost,
    not the observations.

    Args:
        env: the formation env.
        config: a :class:`CGMRESConfig` (default: the settings above); ``**options`` replace
            its fields.

    ``info``: ``fallbacks`` (count), ``solver_status`` (last update), ``fallback`` (last step),
    ``gmres_inexact`` (count), ``solve_ms``, ``residual`` (|F| before each update),
    ``gmres_residual`` (lists per step).
    """

    name = "cgmres"
    env_ids = ("formation_v0",)
    cheap = False

    def __init__(self, env: Any, config: CGMRESConfig | None = None, **options: Any) -> None:
        check_env(type(self), env)
        self.cfg = config_from_options(CGMRESConfig, options, "CGMRES", base=config)
        sc = nominal(env).scenario
        self.options = self.cfg.resolved(sc.dt)
        self.env = env
        self.scenario = sc
        self.agents = list(env.possible_agents)
        self.ocp = FormationOCP(sc, self.cfg.horizon_steps, self.cfg.dummy_weight)
        self.dt = float(sc.dt)
        self.info: dict[str, Any] = {}
        self.reset()

    # ------------------------------------------------------------------ policy API
    def reset(self, seed: int | None = None) -> None:
        """Forget the solution; the next ``act`` restarts the continuation from ``T = 0``."""
        self._u_seq: np.ndarray | None = None
        self._u_dot: np.ndarray | None = None
        self._t = 0.0
        self.info = new_info(fallback=False, gmres_inexact=0, solve_ms=[], residual=[],
                             gmres_residual=[])

    def horizon_at(self, t: float) -> float:
        """Prediction horizon ``T(t)`` [s] at time ``t`` since the (re)start."""
        return self.options["horizon"] * (1.0 - math.exp(-self.options["horizon_rate"] * t))

    @property
    def solution(self) -> np.ndarray | None:
        """The current ``U`` (inputs, dummies, multipliers), ``None`` before the first ``act``."""
        return None if self._u_seq is None else self._u_seq.copy()

    @property
    def time(self) -> float:
        """Time since the continuation (re)started [s] (sets the horizon)."""
        return self._t

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        start = time.perf_counter()
        x = np.asarray(self.env.state(), dtype=float).ravel()
        w = self.update(x)
        self.info["solve_ms"].append((time.perf_counter() - start) * 1e3)
        w = w.reshape(len(self.agents), 3)
        return {a: w[i].astype(np.float32) for i, a in enumerate(self.agents) if a in observations}

    def update(self, x: np.ndarray) -> np.ndarray:
        """One C/GMRES update at state ``x`` (nx,); returns the normalised input to apply (nu,).

        Both solver calls (the Newton restart and the GMRES continuation step) go through
        :func:`satenv.baselines.base.guarded_solve`: an exception, a wrong shape, a non-finite point, a
        GMRES residual above ``fallback_tol`` or an optimality residual ``|F|`` (which contains
        the input-constraint equations) above ``max_residual`` is a failure. The safe action is
        zero thrust (kannan2022 §3: ``u = 0`` is always admissible); the continuation restarts
        from ``T = 0`` at the next sample.
        """
        ocp = self.ocp
        if self._u_seq is None:
            self._t = 0.0
            start = guarded_solve(self.info, lambda: self._restart(x), shape=(ocp.dim,),
                                  time_limit=self.cfg.solve_time_limit)
            if start is None:
                return self._fallback()
            self._u_seq, self._u_dot = start, np.zeros(ocp.dim)
        new = guarded_solve(self.info, lambda: self._continuation_step(x), shape=(ocp.dim,),
                            time_limit=self.cfg.solve_time_limit)
        if new is None:
            return self._fallback()
        self.info["fallback"] = False
        if self.info["gmres_residual"][-1] > self.options["gmres_tol"]:
            self.info["gmres_inexact"] += 1
        self._u_seq, self._u_dot = new, self._pending_u_dot
        self._t += self.dt
        return np.clip(ocp.first_input(new), -1.0, 1.0)

    def _fallback(self) -> np.ndarray:
        self.info["fallback"] = True
        self._u_seq = None  # restart from T = 0 at the next sample
        return np.zeros(self.ocp.nu)

    def _restart(self, x: np.ndarray) -> tuple[np.ndarray, bool, str]:
        """Newton's method on ``F = 0`` at ``T = 0`` from the exact initial guess."""
        u_seq, fnorm = self.ocp.refine(self.ocp.initial_guess(), x, self.horizon_at(0.0),
                                       max_iter=self.cfg.newton_iterations)
        ok = math.isfinite(fnorm) and fnorm <= self.options["max_residual"]
        return u_seq, ok, f"newton |F| {fnorm:.3g}"

    def _continuation_step(self, x: np.ndarray) -> tuple[np.ndarray, bool, str]:
        """``U + dU/dt dt`` with ``dU/dt`` from GMRES on ``F_U dU/dt = -zeta F - F_x x' - F_t``."""
        ocp, o = self.ocp, self.options
        u_seq, t, h = self._u_seq, self._t, o["fd_step"]
        with np.errstate(all="ignore"):
            xdot = ocp.dynamics(x, ocp.first_input(u_seq))
            x1, t1 = x + h * xdot, t + h
            f0 = ocp.residual(u_seq, x, self.horizon_at(t))
            f1 = ocp.residual(u_seq, x1, self.horizon_at(t1))
            rhs = -o["zeta"] * f0 - (f1 - f0) / h
            horizon1 = self.horizon_at(t1)

            def matvec(d):
                return (ocp.residual(u_seq + h * d, x1, horizon1) - f1) / h

            u_dot, rel = gmres(matvec, rhs, self._u_dot, o["kmax"])
            new = u_seq + u_dot * self.dt
        fnorm = float(np.linalg.norm(f0))
        self.info["residual"].append(fnorm)
        self.info["gmres_residual"].append(rel)
        self._pending_u_dot = u_dot
        ok = (math.isfinite(rel) and rel <= o["fallback_tol"]
              and math.isfinite(fnorm) and fnorm <= o["max_residual"])
        return new, ok, f"gmres rel {rel:.3g}, |F| {fnorm:.3g}"
