"""Stateless experts for imitation: the action depends only on the current state.

DAgger asks the expert what it would do in states the learner flew into; a controller that
warm-starts from its own previous plan (``satenv.baselines.DMPC``) answers a different question there
(its shadow plan is not the one it would have had). The experts here re-plan from scratch at
every decision, so a label is a function of the state alone.

:class:`JointPlatoonMPC` — pereira2022 §5.1 (``platoon_v0(preset="pereira2022")``): the joint
problem the convex-step DMPC iterates towards (pereira2022 eq. 25-29), solved in one QP over both
followers' input sequences. Cost: ``sum_j atot alpha_j |Z_j - Y_d|^2_calQ + alpha_j^2
|U_j|^2_calW`` on the pair states ``z_j = x_j - x_{j-1}`` (leader = 0), the prediction
matrices of ``satenv.dynamics``. Constraints on every pair: the input box, the pair velocity box,
the keep-out sphere linearised as its tangent half-space at the current direction (eq. 32-33;
``keepout_margin`` metres added to the radius), the LOS cone (eq. 34); plus (not in the paper) the
keep-out half-space of every follower around the leader. The QP is built and cold-solved with
DAQP; if it fails the LOS rows are dropped, then every state row (input box only), and the
fallback is counted in ``info["fallbacks"]`` as in :mod:`satenv.baselines.dmpc`.

Privileged like the DMPC: it reads ``env.state()``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from satenv.baselines import registry
from satenv.baselines.base import new_info, record_fallback
from satenv.baselines.dmpc import ConvexStepDMPC, DMPCConfig, QPSolver
from satenv.perturbations import nominal

__all__ = ["EXPERTS", "JointPlatoonMPC", "ReplanningTubeRDMPC", "make"]


class JointPlatoonMPC:
    """Centralised, cold-started joint MPC of the pereira2022 §5.1 platoon (module docstring).

    Args:
        env: a ``platoon_v0`` env with ``formation="chain"`` (the pereira2022 preset).
        horizon: prediction horizon N (default: the paper's DMPC, 40).
        keepout_margin: metres added to the keep-out radius in the plan.
        leader_keepout: also keep every follower (not only follower 1) out of the leader's sphere.
        coupling: ``"joint"`` (one QP over all followers) or ``"sequential"`` (follower 1 plans
            its own pair alone, then each follower j plans its pair against follower j-1's
            plan: follower j's action then depends only on the states of followers 1..j, which
            is what its observation holds under the PLF graph).
    """

    name = "joint_mpc"

    def __init__(self, env: Any, horizon: int | None = None, keepout_margin: float = 0.5,
                 leader_keepout: bool = True, coupling: str = "joint", u_scale: float = 1.0):
        if not 0 < u_scale <= 1:
            raise ValueError(f"u_scale must be in (0, 1], got {u_scale!r}")
        if coupling not in ("joint", "sequential"):
            raise ValueError(f"coupling must be 'joint' or 'sequential', got {coupling!r}")
        self.coupling = coupling
        sc = nominal(env).scenario
        if sc.formation != "chain":
            raise ValueError(f"JointPlatoonMPC needs a chain-formation platoon (pereira2022), got "
                             f"formation={sc.formation!r}")
        self.env, self.scenario = env, sc
        cfg = DMPCConfig.for_scenario(sc)
        if horizon is not None:
            cfg = DMPCConfig(**{**cfg.__dict__, "horizon": int(horizon)})
        self.core = ConvexStepDMPC(sc, cfg)          # prediction matrices, weights, pair rows
        self.margin = float(keepout_margin)
        self.leader_keepout = bool(leader_keepout)
        self.m = sc.n_followers
        self.nu = self.core.nu
        self.agents = [f"follower_{i + 1}" for i in range(self.m)]
        self.u_max = float(sc.u_max)
        self.u_plan = float(u_scale) * self.u_max
        self._build()
        self.reset()

    # ------------------------------------------------------------------ construction
    def _pair_map(self, j: int) -> np.ndarray:
        """``D_j`` (nu, m nu): ``U_j - U_{j-1}`` from the stacked inputs (U_0 = 0)."""
        d = np.zeros((self.nu, self.m * self.nu))
        d[:, j * self.nu:(j + 1) * self.nu] = np.eye(self.nu)
        if j >= 1:
            d[:, (j - 1) * self.nu:j * self.nu] = -np.eye(self.nu)
        return d

    def _build(self) -> None:
        c = self.core
        n = self.m * self.nu
        self.D = [self._pair_map(j) for j in range(self.m)]
        h = np.zeros((n, n))
        wdiag = np.tile(np.asarray(self.scenario.input_weight, float), c.horizon)
        for j in range(self.m):
            h += 2 * c.wq[j] * self.D[j].T @ c.btqb @ self.D[j]
            sl = slice(j * self.nu, (j + 1) * self.nu)
            h[sl, sl] += 2 * c.wu[j] * np.diag(wdiag)
        self.H = h
        lb, ub = np.full(n, -self.u_plan), np.full(n, self.u_plan)
        rows_full = self._rows(np.zeros((self.m, 6)), los=True)[0].shape[0]
        rows_nolos = self._rows(np.zeros((self.m, 6)), los=False)[0].shape[0]
        self.qp_full = QPSolver(h, np.zeros((rows_full, n)), lb, ub)
        self.qp_nolos = QPSolver(h, np.zeros((rows_nolos, n)), lb, ub)
        self.qp_box = QPSolver(h, None, lb, ub)
        self.seq = []
        for j in range(self.m):
            hj = 2 * (c.wq[j] * c.btqb + c.wu[j] * np.diag(wdiag))
            g = self._seq_rows(j, np.zeros((self.m, 6)), np.zeros((self.m, self.nu)), True)[0]
            g2 = self._seq_rows(j, np.zeros((self.m, 6)), np.zeros((self.m, self.nu)), False)[0]
            lbj, ubj = np.full(self.nu, -self.u_plan), np.full(self.nu, self.u_plan)
            self.seq.append((QPSolver(hj, np.zeros_like(g), lbj, ubj), QPSolver(hj, np.zeros_like(g2), lbj, ubj),
                             QPSolver(hj, None, lbj, ubj)))

    def _rows(self, z: np.ndarray, los: bool):
        """Constraint rows ``G U in [lo, hi]`` on the stacked inputs for pair states ``z`` (m, 6)."""
        c, sc, hz = self.core, self.scenario, self.core.horizon
        free = np.einsum("ij,mj->mi", c.ca, z)
        g_all, lo_all, hi_all = [], [], []
        for j in range(self.m):
            g, lo, hi = c._pair_rows(z[j], free[j], 1.0, margin=self.margin, los=los)
            g_all.append(g @ self.D[j])
            lo_all.append(lo)
            hi_all.append(hi)
        if self.leader_keepout:
            for j in range(1, self.m):      # follower j+1 (0-based j) relative to the leader
                x0 = z[: j + 1].sum(0)
                off = free[: j + 1].sum(0).reshape(hz, 6)[:, :3]
                d = x0[:3] / max(np.linalg.norm(x0[:3]), 1e-9)
                gsum = sum(self.D[i] for i in range(j + 1))
                cbp = c.cb_p.reshape(hz, 3, self.nu)
                g_all.append(np.einsum("c,kcj->kj", d, cbp) @ gsum)
                lo_all.append(np.full(hz, sc.follower_radius + sc.leader_radius + self.margin) - off @ d)
                hi_all.append(np.full(hz, 1e30))
        return np.vstack(g_all), np.concatenate(lo_all), np.concatenate(hi_all)

    def _seq_rows(self, j: int, x: np.ndarray, u: np.ndarray, los: bool):
        """Rows on follower j's own ``U_j`` given the earlier followers' plans ``u[:j]``."""
        c, sc, hz = self.core, self.scenario, self.core.horizon
        z = x - np.concatenate([np.zeros((1, 6)), x[:-1]], axis=0)
        off = c.ca @ z[j] - (c.cb @ u[j - 1] if j >= 1 else 0.0)
        g, lo, hi = c._pair_rows(z[j], off, 1.0, margin=self.margin, los=los)
        if self.leader_keepout and j >= 1:
            offp = (c.ca @ x[j]).reshape(hz, 6)[:, :3]
            d = x[j, :3] / max(np.linalg.norm(x[j, :3]), 1e-9)
            g = np.vstack([g, np.einsum("c,kcj->kj", d, c.cb_p.reshape(hz, 3, self.nu))])
            lo = np.concatenate([lo, np.full(hz, sc.follower_radius + sc.leader_radius + self.margin) - offp @ d])
            hi = np.concatenate([hi, np.full(hz, 1e30)])
        return g, lo, hi

    def _solve_relaxing(self, qps, f: np.ndarray, rows) -> np.ndarray | None:
        """Solve with every row, then without the LOS rows, then with the input box only
        (``qps`` = (full, no-LOS, box) solvers; ``rows(los)`` gives ``(G, lo, hi)``)."""
        for qp, los in ((qps[0], True), (qps[1], False)):
            g, lo, hi = rows(los)
            qp.update(f, lo, hi, A=g)
            sol = qp.solve(self.info, fallback=False)
            if sol is not None:
                return sol
            self.info["relaxed"] += 1
        qps[2].update(f)
        sol = qps[2].solve(self.info)
        return sol if sol is not None and np.all(np.isfinite(sol)) else None

    def _plan_sequential(self, x: np.ndarray) -> np.ndarray:
        c = self.core
        z = x - np.concatenate([np.zeros((1, 6)), x[:-1]], axis=0)
        u = np.zeros((self.m, self.nu))
        for j in range(self.m):
            off = c.ca @ z[j] - (c.cb @ u[j - 1] if j >= 1 else 0.0)
            f = 2 * c.wq[j] * (c.btq @ (off - c.yd))
            sol = self._solve_relaxing(self.seq[j], f, lambda los, j=j: self._seq_rows(j, x, u, los))
            if sol is None:
                record_fallback(self.info, f"follower {j + 1} QP failed: zero plan")
                sol = np.zeros(self.nu)
            u[j] = np.clip(sol, -self.u_max, self.u_max)
        return u[:, :3].copy()

    # ------------------------------------------------------------------ policy interface
    def reset(self, seed: int | None = None) -> None:
        self.info = new_info()
        self.info["solve_ms"] = []
        self.info["relaxed"] = 0

    def plan(self, x: np.ndarray) -> np.ndarray:
        """The first inputs (m, 3) [m/s^2] of the joint plan for follower states ``x`` (m, 6)."""
        if self.coupling == "sequential":
            return self._plan_sequential(x)
        c = self.core
        z = x - np.concatenate([np.zeros((1, 6)), x[:-1]], axis=0)
        free = np.einsum("ij,mj->mi", c.ca, z)
        f = np.zeros(self.m * self.nu)
        for j in range(self.m):
            f += 2 * c.wq[j] * self.D[j].T @ (c.btq @ (free[j] - c.yd))
        sol = self._solve_relaxing((self.qp_full, self.qp_nolos, self.qp_box), f, lambda los: self._rows(z, los))
        if sol is None:
            record_fallback(self.info, "joint QP failed: zero thrust")
            return np.zeros((self.m, 3))
        return np.clip(sol.reshape(self.m, self.nu)[:, :3], -self.u_max, self.u_max)

    def act(self, observations: dict) -> dict:
        t0 = time.perf_counter()
        x = np.asarray(self.env.state(), dtype=float)[: 6 * self.m].reshape(self.m, 6)
        a = (self.plan(x) / self.u_max).astype(np.float32)
        self.info["solve_ms"].append(1e3 * (time.perf_counter() - t0))
        return {name: a[i] for i, name in enumerate(self.agents) if name in observations}


class ReplanningTubeRDMPC:
    """The li2022 tube-RDMPC's nominal DMPC re-anchored at the true state at every decision.

    ``satenv.baselines.TubeRDMPC`` propagates its own nominal state and corrects the truth towards it
    with the tube controller κ inside the env's physics loop (``env.set_inner_loop``), which a
    learned policy acting once per decision does not have. This expert (``tube=False``) starts
    the nominal at the env's true state before every decision, so its action depends on the
    visited state (and, through the Jacobi exchange, on the plans made from the previous visited
    state), as DAgger needs. Privileged like the tube-RDMPC (``env.state()``, the obstacle).

    Args:
        env: a ``cluster_v0`` env; ``**options``: :class:`satenv.baselines.tube_rdmpc.TubeRDMPCConfig`
            fields (``tube`` is forced to False).
    """

    name = "replanning_tube_rdmpc"

    def __init__(self, env: Any, **options: Any):
        from satenv.baselines.tube_rdmpc import TubeRDMPC

        self.env = env
        self.inner = TubeRDMPC(env, **{**options, "tube": False})
        self.info = self.inner.info

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)
        self.info = self.inner.info

    def act(self, observations: dict) -> dict:
        inner, env = self.inner, self.env
        m = inner.m
        x = np.asarray(env.state(), dtype=float)[: 6 * m].reshape(m, 6)
        if env.inner_loop is not inner.tube:
            env.set_inner_loop(inner.tube)
        inner.tube.sync(x, env.time)             # nominal := truth (κ is off: tube=False)
        inner.expected_time = env.time
        actions = inner.act(observations)
        self.info = inner.info
        return actions


EXPERTS = registry.EXPERTS
"""The stateless experts by name: :data:`satenv.baselines.registry.EXPERTS` (the one controller registry)."""

make = registry.make_expert
"""The expert called ``name`` for ``env``: :func:`satenv.baselines.registry.make_expert`."""
