"""platoon_v0 — leader–follower spacecraft platooning (pereira2023; pereira2022 §3/§5.1).

``satenv.envs.platoon_v0.parallel_env(**kwargs)`` returns a PettingZoo ``ParallelEnv``;
``env(**kwargs)`` the AEC version; ``raw_env(**kwargs)`` the raw AEC env (no wrappers), as
PettingZoo names it.

N active followers ``follower_1 … follower_N`` fly relative to a passive leader at the origin of
its LVLH frame (x radial, y along-track, z orbit normal) on a circular orbit of radius
``orbit_radius``. They communicate over a graph (``topology``: ``"PLF"``, ``"BDL"``, ``"TPLF"``
or an adjacency matrix, see :mod:`satenv.graph`) and should reach the formation in which every
neighbourhood error ``E_f = sum_{i in N_f}(x_f - x_i) + g_f x_f`` (pereira2023 eq. 9) equals its
target ``E_f* = (L_bar x*)_f`` — ``(g_f + d_f) E_d`` for pereira2023, the chain spacing
``x_f - x_{f-1} = E_d`` for pereira2022 (:class:`satenv.scenarios.platoon.PlatoonScenario`).

Arguments (keywords; all optional)
----------------------------------
``preset``        ``"pereira2023"`` (default: Table I exactly — 4 followers, ||r_l|| = 6621 km,
                  T_s = 0.1 s, n_k = 180, u_max = 6 m/s^2, v_max = 20 m/s, r_f = 3 m) or
                  ``"pereira2022"`` (§5.1: 2 followers + leader, y_d = [0, -10, 0] per pair,
                  keep-out r_delta = 6 m, LOS cone c_x = c_z = 1, port [2, 2, 4] m).
``render_mode``   ``None``, ``"rgb_array"`` or ``"human"`` (matplotlib 3-D positions + trails).
any field of ``PlatoonScenario`` overrides the preset, e.g. ``topology="BDL"``,
``dynamics="cw" | "nonlinear" | "j2" | "j2_drag"`` (truth model from ``satenv.dynamics``),
``randomize=True`` (random initial states, distribution in :mod:`satenv.scenarios.platoon`),
``initial_state``, ``max_steps``, ``dt``, ``u_max`` [m/s^2, per axis], ``terminate_on_collision``,
``reward_scale``, ``success_tol`` (1 m), ``collision_voids_success`` …
Unknown keywords raise ``SatenvError`` (a ``ValueError``).
``reset(seed=..., options={"initial_state": array (N, 6)})`` starts from a given state.

Spaces (per agent; float32)
---------------------------
Action ``Box(-1, 1, (3,))``: LVLH acceleration ``u = a * u_max`` (per-axis box, eq. 39).

Observation ``Box(-inf, inf, (15 + 7 (N - 1),))``, normalised with ``L = 50 m``, ``V = 10 m/s``:

=========  =======================================================================
entries    meaning
=========  =======================================================================
0–5        tracking error ``E_f - E_f*`` (position / L, velocity / V)
6–11       own state ``x_f`` relative to the leader (position / L, velocity / V)
12         ``g_f`` (1: hears the leader)
13         ``(g_f + d_f) / N``
14         fraction of the episode remaining ``1 - t / n_k``
15 …       one slot of 7 per other follower j (ascending index, self skipped):
           ``[mask, (x_j - x_f) / (L, V)]`` with mask = 1 iff f hears j, slot zeroed
           otherwise (padded and masked to a fixed size)
=========  =======================================================================

``state()`` returns the global state: the N follower states flattened ``(6 N,)`` float64.

Reward (per follower, mirrors the paper's stage cost eq. 14)
------------------------------------------------------------
``r_f = -alpha_f (e^T Q e + u^T W u) / reward_scale - collision_penalty * collision_f
- violation_penalty * violations_f`` with ``e = E_f - E_f*`` after the step, ``u`` the applied
acceleration, ``Q = diag(state_weight)``, ``W = diag(input_weight)``.

``reward="training"`` (the default of a training task's env, :mod:`satenv.tasks`) replaces this
with the training reward of :mod:`satenv.rewards` (progress toward the target, a bonus inside the
success tolerance, a success bonus, penalties for collision, violation and leaving the region);
``reward="paper"`` (the default) keeps it. Under either, the infos carry ``safety_cost`` (1.0 on
a collision or a hard-bound violation of the agent in the step, else 0.0).

Termination / truncation
------------------------
Terminated (all agents) when two bodies collide (distance < r_i + r_j, the leader included,
radii ``follower_radius`` / ``leader_radius``; only if ``terminate_on_collision``) or a follower
leaves the ball of radius ``max_distance`` around the leader. Truncated at ``max_steps``.
Note: the pereira2023 Table I formation itself puts bodies closer than ``2 r_f`` (PLF: 1 m
between followers 3 and 4; BDL: followers 1/4 and 2/3 coincide), so the ``"pereira2023"``
preset sets ``terminate_on_collision=False`` (as the paper's simulation) and reports the
collisions; ``formation="chain"`` (followers 8 m apart) is the collision-free variant. For the
same reason a collision voids success only where the target formation is collision-free
(``collision_voids_success`` is derived from the geometry unless given).

Infos (per agent, SI units)
---------------------------
``state`` (6,), ``accel`` (3,) applied [m/s^2], ``delta_v`` [m/s] this step,
``tracking_error`` (6,) ``E_f - E_f*`` (what the paper's RMSE/FOE measure),
``neighbourhood_error`` (6,) ``E_f``, ``min_separation`` [m] to any other body,
``collision`` (bool), ``violations`` (int) this step — velocity bound (40) on the velocity part
of ``E_f`` (``|.| > (g_f + d_f) v_max``), and when configured the minimum tracking error (41),
the keep-out sphere (eq. 31) and the LOS cone (eq. 34) of the follower's target–chaser pair —,
``cost`` = ``collision + violations`` (float).

Version History
---------------
* v0: initial release.
* v0 (unreleased changes, still v0): one env surface across satenv — ``n_steps`` renamed
  ``max_steps``; new ``success_tol`` and ``collision_voids_success``; ``state_space``,
  ``observation_spaces`` / ``action_spaces`` dicts, ``metadata["render_fps"]`` from ``dt``;
  ``raw_env`` is the raw AEC env; base class ``SatParallelEnv`` (was ``FormationEnv``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pettingzoo import AECEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from satenv.dynamics import Orbit, RelativeModel, delta_v
from satenv.envs.base import BatchedCore, SatParallelEnv, StepResult, resolve_preset
from satenv.neighbours import DENSE_MAX, nearest, norm3
from satenv.scenarios.platoon import (
    PRESETS,
    PlatoonScenario,
    resolve_scenario,
    sample_initial_state,
)

__all__ = ["METHODS", "PlatoonCore", "PlatoonEnv", "env", "parallel_env", "raw_env", "POS_SCALE", "VEL_SCALE"]

POS_SCALE = 50.0
"""Observation position scale L [m]."""
VEL_SCALE = 10.0
"""Observation velocity scale V [m/s]."""


METHODS = ("auto", "kernel", "dense", "sparse")
"""How :class:`PlatoonCore` evaluates a step: ``"dense"`` (affine maps of the whole state) and
``"sparse"`` (neighbour gathers and a neighbour search) are the numpy reference, ``"kernel"`` the
compiled kernel of :mod:`satenv.envs._platoon_kernel` (numba; any N: above its ``SWEEP_MIN``
followers a sort-and-sweep nearest-follower search replaces all pairs); ``"auto"`` takes the
kernel when numba is installed and the scenario has none of the optional pereira2022
constraints, else dense up to ``DENSE_MAX`` followers and sparse above."""


def _kernel_module(scenario: PlatoonScenario, method: str, n: int) -> Any:
    """The kernel module if ``method`` selects it (``None`` otherwise)."""
    if method in ("dense", "sparse"):
        return None
    extras = scenario.min_error_constraint or scenario.keepout_radius > 0 or scenario.los_slopes is not None
    if method == "auto" and extras:
        return None
    if extras:
        raise ValueError("method='kernel' does not evaluate the optional constraints "
                         "(min_error_constraint, keepout_radius, los_slopes); use 'dense' or 'sparse'")
    try:
        from satenv.envs import _platoon_kernel
    except ImportError:
        if method == "kernel":
            raise ValueError("method='kernel' needs numba (pip install numba)") from None
        return None
    return _platoon_kernel


FUSED_CW_MAX_BATCH = 16
"""Largest batch whose CW step runs in the compiled kernel module (measured: 20 vs 24 us per
step at 1 copy, equal at 64, 15 % slower than numpy's BLAS products at 1024-4096)."""


class PlatoonCore(BatchedCore):
    """Batched platoon physics and task logic (``B`` copies, ``N`` followers)."""

    state_dim = 6
    action_dim = 3

    def __init__(self, scenario: PlatoonScenario, batch: int = 1, method: str = "auto") -> None:
        super().__init__(scenario, batch)
        n = self.n_agents
        self.topology = scenario.graph
        self.lbar = np.asarray(self.topology.augmented_laplacian)
        self.adj = np.asarray(self.topology.adjacency, dtype=float)
        self.gains = self.topology.gains.astype(float)
        self.target = scenario.desired_neighbourhood_error()  # (N, 6)
        self.orbit = Orbit.circular(scenario.orbit_radius, i=scenario.inclination, mu=scenario.mu)
        self.model = RelativeModel(scenario.dynamics, self.orbit, scenario.dt)
        self.q = np.asarray(scenario.state_weight)
        self.w = np.asarray(scenario.input_weight)
        self.alpha = np.asarray(scenario.alpha)
        # neighbour lists (ascending index, padded with the follower itself and mask 0)
        heard = [np.flatnonzero(self.adj[f]) for f in range(n)]
        k = max(len(h) for h in heard)
        self._nbr = np.array([np.r_[h, np.full(k - len(h), f)] for f, h in enumerate(heard)],
                             dtype=np.int64).reshape(n, k)
        self._nbr_mask = (np.arange(k) < np.array([len(h) for h in heard])[:, None]).astype(float)
        # observation slots: source follower and mask of slot s of follower f
        if scenario.neighbour_slots:
            self._slot_src, self._slot_mask = self._nbr, self._nbr_mask
        else:  # one slot per other follower j (ascending, self skipped), mask a_fj
            others = np.array([[j for j in range(n) if j != f] for f in range(n)],
                              dtype=np.int64).reshape(n, n - 1)
            self._slot_src, self._slot_mask = others, np.take_along_axis(self.adj, others, 1)
        self.obs_dim = 15 + 7 * self._slot_src.shape[1]
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self._kernel = _kernel_module(scenario, method, n)
        self.method = "kernel" if self._kernel is not None else (
            method if method != "auto" else ("dense" if n <= DENSE_MAX else "sparse"))
        self.dense = self.method == "dense"
        r_f = scenario.follower_radius
        self._contact = (scenario.leader_radius + r_f, 2 * r_f)
        self.x = np.zeros((self.batch, n, 6))
        self.chief = np.tile(self.model.initial_chief(), (self.batch, 1))
        self.accel = np.zeros((self.batch, n, 3))
        self._scale = np.array([POS_SCALE] * 3 + [VEL_SCALE] * 3)
        self._vbound = self.gains * scenario.v_max
        self._neg_reward_gain = -self.alpha / scenario.reward_scale
        self._obs_offset = self._observation_offset()
        # the compiled CW step (kernel path, small batches: it saves numpy's per-call overhead,
        # while BLAS is faster from ~64 copies; the model's numpy step is its reference)
        self._cw_step = (self.model.linear_step_matrices()
                         if self._kernel is not None and self.batch <= FUSED_CW_MAX_BATCH else None)
        if self._kernel is not None:  # the kernels' constant arguments (packed: fewer to pass)
            self._table = np.hstack([self.gains[:, None], self._vbound[:, None],
                                     np.broadcast_to(self._neg_reward_gain, (n,))[:, None], self.target,
                                     self._nbr_mask]).astype(float)
            self._params = np.r_[self.q, self.w, self._contact, scenario.max_distance, scenario.dt,
                                 scenario.collision_penalty, scenario.violation_penalty,
                                 float(scenario.terminate_on_collision), self._scale,
                                 scenario.max_steps, 1.0].astype(float)
        if self.dense:
            # one product gives E (first N rows, eq. 9) and the position of f minus that of each
            # other body (the leader first, then the other followers in ascending order)
            pair_op = np.zeros((n, n, n))
            pair_op[:, 0] = np.eye(n)
            for f in range(n):
                pair_op[f, np.arange(1, n), f] = 1.0
                pair_op[f, np.arange(1, n), np.delete(np.arange(n), f)] = -1.0
            self._linear_op = np.vstack([self.lbar, pair_op.reshape(n * n, n)])
            self._pair_contact = np.r_[self._contact[0], np.full(n - 1, self._contact[1])]
            self._obs_map = self._observation_map()

    def _observation_offset(self) -> np.ndarray:
        """The state-independent part ``(N, obs_dim)`` of the observation (module docstring)."""
        n = self.n_agents
        offset = np.zeros((n, self.obs_dim))
        offset[:, 0:6] = -self.target / self._scale
        offset[:, 12] = self.topology.pinning
        offset[:, 13] = self.gains / n
        offset[:, 14] = 1.0
        offset[:, 15::7] = self._slot_mask
        return offset

    def _observation_map(self) -> np.ndarray:
        """The dense path's observation is affine in the state: ``obs = x.ravel() @ map + offset
        - t / n_k`` (entry 14); ``map`` is ``(6 N, N obs_dim)``."""
        n, d = self.n_agents, self.obs_dim
        inv = np.diag(1.0 / self._scale)                          # (6, 6)
        a = np.zeros((n, d, n, 6))                                 # obs[f, k] = a[f, k, j, c] x[j, c]
        for f in range(n):
            a[f, 0:6] = np.einsum("j,kc->kjc", self.lbar[f], inv)  # (E_f - E_f*) / scale
            a[f, 6:12, f] = inv                                    # x_f / scale
            for s, (j, on) in enumerate(zip(self._slot_src[f], self._slot_mask[f], strict=True)):
                if on:                                             # masked slot: (x_j - x_f) / scale
                    a[f, 16 + 7 * s:22 + 7 * s, j] += inv
                    a[f, 16 + 7 * s:22 + 7 * s, f] -= inv
        return a.reshape(n * d, n * 6).T.copy()

    # ------------------------------------------------------------------ episode
    def sample_initial_state(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.scenario.randomize:
            return np.stack([sample_initial_state(self.scenario, rng) for _ in range(n)])
        return np.tile(self.scenario.initial_array(), (n, 1, 1))

    def reset(self, x0, idx=None, rng=None):
        x0 = np.asarray(x0, dtype=float)
        sel = slice(None) if idx is None else idx
        if self._kernel is not None:   # it hands out self.x itself as the state info: copy on write
            self.x = self.x.copy()
        self.x[sel] = x0
        self.t[sel] = 0
        self.chief[sel] = self.model.initial_chief()
        self.accel[sel] = 0.0
        evaluate = self._evaluate if self._kernel is None else self._evaluate_kernel
        return evaluate(np.ascontiguousarray(self.x[sel]), np.ascontiguousarray(self.accel[sel]))[0]

    def step(self, accel, rng=None) -> StepResult:
        accel = self._advance(accel)
        if self._kernel is not None:
            info, rewards, terminated, _, finite = self._evaluate_kernel(self.x, accel)
            return StepResult(rewards, terminated, info, finite)
        info, stage, far = self._evaluate(self.x, accel)
        sc = self.scenario
        rewards = stage * self._neg_reward_gain
        rewards -= sc.collision_penalty * info["collision"]
        rewards -= sc.violation_penalty * info["violations"]
        if sc.terminate_on_collision:
            far |= info["collision"]
        terminated = far.any(axis=-1)
        return StepResult(rewards, terminated, info)

    def step_observe(self, accel, rng=None) -> tuple[StepResult, np.ndarray]:
        if self._kernel is None:
            return super().step_observe(accel, rng)
        accel = self._advance(accel)
        info, rewards, terminated, obs, finite = self._evaluate_kernel(self.x, accel, observe=True)
        return StepResult(rewards, terminated, info, finite), obs

    def _advance(self, accel) -> np.ndarray:
        """The physics of :meth:`step`; returns the inputs as a contiguous float array."""
        accel = np.ascontiguousarray(accel, dtype=float)
        if self._cw_step is not None and accel.shape == self.x.shape[:-1] + (3,):
            x_next, chief_next = np.empty_like(self.x), np.empty_like(self.chief)
            self._kernel.cw_step(self.x, accel, self.chief, *self._cw_step, x_next, chief_next)
            self.x, self.chief = x_next, chief_next
        else:
            self.x, self.chief = self.model.step(self.x, accel, self.chief)
        self.accel = accel
        self.t += 1
        return accel

    # ------------------------------------------------------------------ quantities
    def _evaluate(self, x: np.ndarray, accel: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """The info arrays of states ``x`` under ``accel``, the stage cost ``e^T Q e + u^T W u``
        ``(B, N)`` and which followers are beyond ``max_distance`` ``(B, N)``."""
        sc = self.scenario
        err_raw, sep, lead = self._geometry(x)
        err = err_raw - self.target
        collision = (lead < self._contact[0]) | (sep < self._contact[1])
        viol = np.abs(err_raw[..., 3:]).max(axis=-1) > self._vbound  # velocity bound (40)
        if sc.min_error_constraint or sc.keepout_radius > 0 or sc.los_slopes is not None:
            viol = viol + self._extra_violations(x, err_raw)
        stage = (err * err) @ self.q + (accel * accel) @ self.w
        info = {
            "state": x.copy(),
            "accel": accel.copy(),
            "delta_v": delta_v(accel, sc.dt),
            "tracking_error": err,
            "neighbourhood_error": err_raw,
            "min_separation": np.minimum(lead, sep),
            "collision": collision,
            "violations": viol.astype(np.int64),
            "cost": np.add(collision, viol, dtype=float),
        }
        return info, stage, lead > sc.max_distance

    def _evaluate_kernel(self, x: np.ndarray, accel: np.ndarray, observe: bool = False,
                         t: np.ndarray | None = None) -> tuple:
        """:meth:`_evaluate` and the rewards of :meth:`step` by the compiled kernel: the info
        arrays, rewards ``(B, N)``, terminations ``(B,)``, if ``observe`` the observations (all
        new arrays but the state info, which is ``x``: the core never writes into it) and which
        copies are all finite ``(B,)`` (:attr:`StepResult.finite`); ``t`` the copies' step counts
        (default: every copy's)."""
        b, n = x.shape[:2]
        out = (np.empty((b, n, 6)), np.empty((b, n, 6)), np.empty((b, n)), np.empty((b, n), bool),
               np.empty((b, n), np.int64), np.empty((b, n)), np.empty((b, n)), np.empty((b, n)),
               np.empty(b, bool), np.empty(b, bool))
        obs = np.empty((b, n, self.obs_dim) if observe else (0, 0, 0), np.float32)
        self._kernel.evaluate(x, accel, self._table, self._nbr, self._params, out,
                              self.t if t is None else t, self._obs_offset,
                              self._slot_src, obs)
        err_raw, err, min_sep, collision, viol, cost, dv, rewards, terminated, finite = out
        finite = finite if self._params[23] else None
        info = {"state": x, "accel": accel.copy(), "delta_v": dv, "tracking_error": err,
                "neighbourhood_error": err_raw, "min_separation": min_sep, "collision": collision,
                "violations": viol, "cost": cost}
        return info, rewards, terminated, obs, finite

    @property
    def fused_check(self) -> bool:
        """Whether the compiled kernel checks that its outputs are finite in its own pass
        (:attr:`StepResult.finite`; on by default). Off, the env's :class:`StepGuard` checks
        instead; ``satenv.bench.perf`` turns it off (and that guard) to time the check."""
        return self._kernel is not None and bool(self._params[23])

    @fused_check.setter
    def fused_check(self, on: bool) -> None:
        if self._kernel is None:
            raise ValueError(f"fused_check needs the compiled kernel; this core's method is {self.method!r}")
        self._params[23] = 1.0 if on else 0.0

    def _geometry(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Neighbourhood errors ``E`` (eq. 9) ``(B, N, 6)``, each follower's distance to the nearest
        other follower ``(B, N)`` (``inf`` alone) and to the leader ``(B, N)``."""
        n = self.n_agents
        if self.dense:
            y = self._linear_op @ x
            diff = y[:, n:, :3]                                  # (B, N*N, 3) to every other body
            dist = norm3(diff).reshape(x.shape[0], n, n)
            sep = dist[..., 1:].min(axis=-1) if n > 1 else np.full(dist.shape[:2], np.inf)
            return y[:, :n], sep, dist[..., 0]
        err = self._geometry_error(x)
        pos = x[..., :3]
        sep = nearest(pos, 1)[0][..., 0]
        return err, sep, norm3(pos)

    def _extra_violations(self, x: np.ndarray, err_raw: np.ndarray) -> np.ndarray:
        """Violations of the optional constraints: minimum tracking error (41), keep-out sphere
        (eq. 31) and LOS cone (eq. 34) of each target–chaser pair ``(f - 1, f)``."""
        sc = self.scenario
        viol = np.zeros(x.shape[:2], dtype=np.int64)
        if sc.min_error_constraint:
            viol += np.linalg.norm(err_raw[..., :3], axis=-1) < self.gains * sc.follower_radius
        prev = np.concatenate([np.zeros_like(x[:, :1]), x[:, :-1]], axis=1)
        p = (x - prev)[..., :3]
        if sc.keepout_radius > 0:
            viol += np.linalg.norm(p - np.asarray(sc.keepout_center), axis=-1) < sc.keepout_radius
        if sc.los_slopes is not None:
            cx, cz = sc.los_slopes
            xr, yr, zr = sc.port
            inside = ((p[..., 1] <= -yr) & (cx * np.abs(p[..., 0]) + p[..., 1] <= cx * xr)
                      & (cz * np.abs(p[..., 2]) + p[..., 1] <= cz * zr))
            viol += ~inside
        return viol

    def observe_copies(self, idx: np.ndarray) -> np.ndarray:
        if self._kernel is None:
            return self.observe()[idx]
        return self._evaluate_kernel(self.x[idx], self.accel[idx], observe=True, t=self.t[idx])[3]

    def observe(self) -> np.ndarray:
        b, n = self.batch, self.n_agents
        if self._kernel is not None:
            return self._evaluate_kernel(self.x, self.accel, observe=True)[3]  # the infos cost little
        if self.dense:
            obs = (self.x.reshape(b, -1) @ self._obs_map).reshape(b, n, self.obs_dim)
            obs += self._obs_offset
        else:  # neighbour gathers: cost proportional to the slots
            x = self.x / self._scale
            obs = np.empty((b, n, self.obs_dim))
            obs[...] = self._obs_offset
            err = self._geometry_error(self.x) / self._scale
            obs[..., 0:6] += err
            obs[..., 6:12] = x
            slots = obs[..., 15:].reshape(b, n, -1, 7)
            rel = x[:, self._slot_src] - x[:, :, None]
            rel *= self._slot_mask[..., None]
            slots[..., 1:] = rel
        obs[..., 14] -= (self.t / self.scenario.max_steps)[:, None]
        return obs.astype(np.float32)

    def _geometry_error(self, x: np.ndarray) -> np.ndarray:
        """Neighbourhood errors ``E`` (eq. 9) from neighbour gathers ``(B, N, 6)``."""
        err = x * self.gains[:, None]
        gathered = x[:, self._nbr]
        gathered *= self._nbr_mask[..., None]
        err -= gathered.sum(axis=2)
        return err

    def global_state(self) -> np.ndarray:
        return self.x.reshape(self.batch, -1).copy()

    def render_scene(self, b: int = 0) -> dict[str, Any]:
        sc = self.scenario
        spheres = [(p, sc.follower_radius, f"follower_{i + 1}") for i, p in enumerate(self.x[b, :, :3])]
        spheres.append((np.zeros(3), sc.leader_radius, "leader"))
        if sc.keepout_radius > 0:
            prev = np.vstack([np.zeros(3), self.x[b, :-1, :3]])
            spheres += [(p + np.asarray(sc.keepout_center), sc.keepout_radius, "keep-out")
                        for p in prev]
        return {
            "positions": self.x[b, :, :3].copy(),
            "labels": [f"f{i + 1}" for i in range(self.n_agents)],
            "targets": sc.desired_states()[:, :3],
            "spheres": spheres,
            "title": f"platoon_v0 ({sc.name}, {self.topology.name})  t = {self.t[b] * sc.dt:.1f} s",
        }


class PlatoonEnv(SatParallelEnv):
    """The platoon ``ParallelEnv`` (see the module docstring)."""

    metadata = {**SatParallelEnv.metadata, "name": "platoon_v0"}
    core_class = PlatoonCore
    agent_prefix = "follower"

    def __init__(self, preset: str = "pereira2023", render_mode: str | None = None, reward: str = "paper",
                 **kwargs) -> None:
        scenario = resolve_preset("platoon_v0", preset, PRESETS, resolve_scenario, kwargs)
        super().__init__(scenario, render_mode=render_mode, reward=reward)
        self.topology = scenario.graph


def parallel_env(**kwargs) -> PlatoonEnv:
    """The PettingZoo ``ParallelEnv`` (keyword arguments: module docstring)."""
    return PlatoonEnv(**kwargs)


def raw_env(**kwargs) -> AECEnv:
    """The raw AEC env (``parallel_to_aec_wrapper``, no further wrappers)."""
    return parallel_to_aec_wrapper(PlatoonEnv(**kwargs))


def env(**kwargs) -> AECEnv:
    """The AEC env: :func:`raw_env` with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcingWrapper(raw_env(**kwargs))
