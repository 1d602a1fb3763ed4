"""Artificial-potential-field baseline for satellite-cluster reconfiguration (li2022 §4.3).

li2022 compares its RDMPC with the APF controller of Hwang et al. (2022) but does not print that
controller's equations or gains, so this is a standard APF, documented here. Per satellite i
(LVLH accelerations, ``e_i = q_i - q_id``, ``p_i`` its velocity)::

    u_att = sat_{att_fraction u_max}( -k_att e_i min(1, d_att / ||e_i||) - k_damp p_i )
    u_i   = sat_{u_max}( u_att - f_CW(x_i) + sum_b rep_b )

The attraction is a quadratic potential (conic beyond ``d_att``) with damping; it is limited to
``att_fraction`` (70 %) of the thrust so that the repulsion can always override it — li2022 §4.3
notes that with bounded thrust "the parameters of the attractive potential field cannot be set too
large", otherwise the repulsion cannot guarantee collision avoidance. ``-f_CW`` cancels the
Clohessy–Wiltshire drift (``cw_compensation``).

The bodies b are the satellite's graph neighbours (li2022 §2.3), the obstacle and the target
spacecraft. With ``c = ||q_i - q_b|| - d_b`` the clearance to the safety distance ``d_b``
(``2 r_s``, ``r_s + r_o``, ``r_s + r_t``), ``n`` the unit vector from b to i and
``v_c = -(p_i - p_b) . n`` the closing speed::

    rep_b = m_b (n + k_swirl t),
    m_b   = k_rep (1/c - 1/rho_b) / c^2 [c < rho_b]  +  k_close max(0, v_c - sqrt(2 a_brake c)) [c < rho_brake]

(FIRAS repulsion, plus a braking term that keeps the closing speed under the stopping curve
with deceleration ``a_brake = brake_fraction u_max`` (over a longer range, as it does not bias the
rest positions), plus a tangential "swirl" ``t`` — the
component of ``-e_i`` orthogonal to ``n``, normalised — that lets a satellite slide around a body
standing between it and its target instead of stalling in the APF's local minimum). The clearance
is clipped below at ``c_min``. The steady-state error under a disturbance ``w`` is about
``||w|| / k_att`` (no integral action), so the APF is less accurate than the tube RDMPC, as li2022
reports.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import partial
from typing import Any

import numpy as np

from satenv.baselines.base import (
    Baseline,
    check_env,
    config_from_options,
    flag,
    guarded_solve,
    new_info,
    number,
    time_limit,
    validate,
)
from satenv.cluster_graph import nearest_neighbour_graph, neighbour_lists
from satenv.dynamics import cw_continuous, saturate_norm
from satenv.neighbours import DENSE_MAX
from satenv.perturbations import nominal

__all__ = ["APF", "APFConfig"]


@dataclass(frozen=True)
class APFConfig:
    """Gains of :class:`APF` (SI units; module docstring for the law).

    Args:
        k_att [1/s^2], d_att [m]: attraction stiffness and the distance beyond which it is conic.
        k_damp [1/s]: velocity damping; att_fraction: cap of the attraction (fraction of u_max).
        k_rep [m^4/s^2]: FIRAS repulsion gain; k_close [1/s]: closing-speed braking gain;
        brake_fraction: a_brake / u_max of the stopping curve;
        k_swirl: tangential fraction of the repulsion.
        rho_pair, rho_obstacle, rho_target [m]: FIRAS influence ranges beyond the safety distances.
        rho_brake [m]: range (clearance) within which the closing-speed braking term acts.
        c_min [m]: smallest clearance used in the repulsion.
        cw_compensation: cancel the CW natural dynamics (feed-forward).
        solve_time_limit: wall-time limit [s] of one solve (None: none); a solve over it is a
            flagged failure like any other (``satenv.baselines.base.guarded_solve``): a stall guard, the
            law takes microseconds.
    """

    k_att: float = 4e-3
    d_att: float = 63.0
    k_damp: float = 0.126
    att_fraction: float = 0.7
    k_rep: float = 700.0
    k_close: float = 0.5
    brake_fraction: float = 0.5
    k_swirl: float = 1.0
    rho_pair: float = 150.0
    rho_obstacle: float = 300.0
    rho_target: float = 90.0
    rho_brake: float = 400.0
    c_min: float = 1.0
    cw_compensation: bool = True
    solve_time_limit: float | None = 1.0

    def __post_init__(self) -> None:
        nonneg = ("k_close", "k_swirl", "k_damp", "k_rep")
        rules = {f.name: partial(number, zero_ok=f.name in nonneg) for f in fields(self)
                 if f.name not in ("cw_compensation", "solve_time_limit")}
        rules["att_fraction"] = rules["brake_fraction"] = partial(number, high=1.0)
        rules["cw_compensation"] = flag
        rules["solve_time_limit"] = time_limit
        validate(self, "APF", rules)


class APF(Baseline):
    """Artificial potential field controller for ``satenv.cluster_v0`` (module docstring).

    Privileged: it reads the env's true states (``env.state()``), the allocated targets
    (``env.targets()``), the obstacle state (``env.obstacle_state()``) and the scenario, not the
    observations.

    Args:
        env: a ``cluster_v0`` env.
        config: an :class:`APFConfig` (default: the gains above); ``**options`` replace fields.

    Safe action: an APF law that yields a non-finite acceleration commands zero thrust for that
    step (``info["fallbacks"]``, ``info["solver_status"]``).
    """

    name = "apf"
    env_ids = ("cluster_v0",)

    def __init__(self, env: Any, config: APFConfig | None = None, **options: Any) -> None:
        check_env(type(self), env)
        self.cfg = config_from_options(APFConfig, options, "APF", base=config)
        sc = nominal(env).scenario
        self.env = env
        self.sc = sc
        self.agents = list(env.possible_agents)
        self.m = len(self.agents)
        self.f_rows = cw_continuous(sc.orbit.n)[0][3:, :]
        self.info: dict[str, Any] = new_info()

    def reset(self, seed: int | None = None) -> None:
        self.info = new_info()

    def _repulsion(self, q, p, qb, pb, d_safe, rho, e) -> np.ndarray:
        """Repulsive accelerations (M, 3) from bodies at ``qb`` (M, K, 3) (``inf`` = absent)."""
        cfg = self.cfg
        diff = q[:, None, :] - qb                                    # (M, K, 3) body -> sat
        dist = np.linalg.norm(diff, axis=-1)
        reach = max(rho, cfg.rho_brake)
        active = np.isfinite(dist) & (dist - d_safe < reach)
        if not np.any(active):
            return np.zeros_like(q)
        safe_dist = np.where(active, dist, 1.0)
        n = np.where(active[..., None], diff / safe_dist[..., None], 0.0)
        c = np.maximum(np.where(active, dist - d_safe, reach), cfg.c_min)
        firas = np.where(c < rho, cfg.k_rep * (1.0 / c - 1.0 / rho) / c**2, 0.0)
        closing = -np.einsum("mkd,mkd->mk", p[:, None, :] - np.where(active[..., None], pb, 0.0), n)
        allowed = np.sqrt(2.0 * cfg.brake_fraction * self.sc.u_max * c)
        brake = np.where(c < cfg.rho_brake, cfg.k_close * np.maximum(0.0, closing - allowed), 0.0)
        mag = np.where(active, firas + brake, 0.0)
        # tangential direction: the part of -e orthogonal to n (slide around the body)
        goal = -e[:, None, :]
        tang = goal - np.einsum("mkd,mkd->mk", goal, n)[..., None] * n
        tn = np.linalg.norm(tang, axis=-1, keepdims=True)
        tang = np.where(tn > 1e-9, tang / np.maximum(tn, 1e-9), 0.0)
        return np.sum(mag[..., None] * (n + cfg.k_swirl * tang), axis=1)

    def accelerations(self) -> np.ndarray:
        """The APF accelerations (M, 3) [m/s^2] for the env's current state (saturated; zero
        thrust when the law is not finite)."""
        u = guarded_solve(self.info, lambda: (self._law(), True, "ok"), shape=(self.m, 3),
                          time_limit=self.cfg.solve_time_limit)
        return np.zeros((self.m, 3)) if u is None else saturate_norm(u, self.sc.u_max)

    def _law(self) -> np.ndarray:
        """The unsaturated APF acceleration (M, 3) [m/s^2]."""
        cfg, sc, env = self.cfg, self.sc, self.env
        x = env.state()[: 6 * self.m].reshape(self.m, 6)
        q, p = x[:, :3], x[:, 3:]
        e = q - env.targets()
        dist = np.linalg.norm(e, axis=-1, keepdims=True)
        u = -cfg.k_att * e * np.minimum(1.0, cfg.d_att / np.maximum(dist, 1e-12)) - cfg.k_damp * p
        u = saturate_norm(u, cfg.att_fraction * sc.u_max)
        if cfg.cw_compensation:
            u -= x @ self.f_rows.T
        qb, pb = self._neighbour_states(q, p)
        u += self._repulsion(q, p, qb, pb, sc.pair_distance, cfg.rho_pair, e)
        q_o, p_o = env.obstacle_state()
        u += self._repulsion(q, p, np.broadcast_to(q_o, (self.m, 1, 3)),
                             np.broadcast_to(p_o, (self.m, 1, 3)), sc.obstacle_distance,
                             cfg.rho_obstacle, e)
        q_r = np.asarray(sc.target_spacecraft, dtype=float)
        u += self._repulsion(q, p, np.broadcast_to(q_r, (self.m, 1, 3)), np.zeros((self.m, 1, 3)),
                             sc.target_distance, cfg.rho_target, e)
        return u

    def _neighbour_states(self, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions (``inf`` = no link) and velocities ``(M, K, 3)`` of each satellite's graph
        neighbours: all ``M`` satellites masked by the adjacency up to ``DENSE_MAX`` satellites,
        else the padded neighbour lists (cost proportional to the links)."""
        sc = self.sc
        if self.m <= DENSE_MAX:
            adj = nearest_neighbour_graph(q, sc.n_neighbours, sc.comm_range)
            qb = np.where(adj[..., None], q[None, :, :], np.inf)            # (M, M, 3)
            return qb, np.broadcast_to(p[None, :, :], qb.shape)
        idx = neighbour_lists(q[None], sc.n_neighbours, sc.comm_range)[0]   # (M, D), -1 = none
        qb = np.where(idx[..., None] >= 0, q[idx], np.inf)
        return qb, p[idx]

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        u = self.accelerations() / self.sc.u_max
        return {a: u[i] for i, a in enumerate(self.agents)}
