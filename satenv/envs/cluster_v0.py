"""cluster_v0 — satellite-cluster reconfiguration around a target spacecraft (li2022).

``satenv.envs.cluster_v0.parallel_env(**kwargs)`` (or ``satenv.cluster_v0(**kwargs)``) returns a
PettingZoo ``ParallelEnv``; ``env(**kwargs)`` the AEC version; ``raw_env(**kwargs)`` the raw AEC env (no wrappers), as
PettingZoo names it.

M satellites ``sat_1 … sat_M`` (10 in the presets; 50 kg, 1 N thrusters) fly relative to a virtual
reference satellite at the origin of its LVLH frame (x radial, y along-track, z orbit normal) and
must reach target points around a target spacecraft while a space obstacle crosses the cluster.
Targets are allocated with the Hungarian algorithm (:mod:`satenv.allocation`, cost
``alpha ||q_i - q_jd||^2``) at reset and, optionally, every ``reallocate_every`` decisions. The
satellites talk over a time-varying graph: each one to its ``n_neighbours`` nearest within
``comm_range`` (:mod:`satenv.cluster_graph`). Scenario details and the documented choices the
paper leaves open (orbit, disturbance units, keep-out radii): :mod:`satenv.scenarios.cluster`.

Arguments (keywords; all optional)
----------------------------------
``preset``        ``"li2022-case1"`` (default; Table 2 start) or ``"li2022-case2"`` (Table 3).
``render_mode``   ``None``, ``"rgb_array"`` or ``"human"``.
any field of :class:`~satenv.scenarios.cluster.ClusterScenario` overrides the preset, e.g.
``disturbance="none" | "sinusoid" | "random"``, ``disturbance_force`` [N], ``dynamics``,
``dt``, ``physics_dt``, ``max_steps``, ``u_max`` [m/s^2, bound on the norm], ``allocation="fixed"``,
``reallocate_every``, ``terminate_on_collision``, ``randomize=True`` (random initial positions
and target slots from the seed; ``random_position_spread``, ``random_target_radius``,
``random_start="slots"``: starts around the target slots),
``initial_positions`` (any M), ``success_tol`` (1 m), ``collision_voids_success``,
``obs_neighbours`` (``None`` or ``K`` in ``[1, 64]``: the fixed observation layout below).
Unknown keywords raise ``SatenvError`` (a ``ValueError``).
``reset(seed=..., options={"initial_state": array (M, 6)})`` starts from a given state.

Time: one ``step`` is one decision period ``dt`` (Δt = 5 s); inside it the truth dynamics
(default J2 + drag, ``satenv.dynamics.RelativeModel``) and the disturbance run with step
``physics_dt`` (0.25 s). The decoded action is held over the period (zero-order hold).

Inner-loop hook (for controllers that act at the physics rate, e.g. the tube controller κ of
li2022 eq. 13): ``env.set_inner_loop(obj)`` registers an object with a method
``correction(t, x, chief, u_cmd) -> (B, M, 3)`` called at every physics step with the time
``t`` (B,) [s], the states ``x`` (B, M, 6) (the truth; under a navigation-error perturbation the
truth plus the decision's navigation error, ``satenv.perturbations``), the reference satellite's
ECI state ``chief`` (B, 6) and the commanded accelerations ``u_cmd`` (B, M, 3) of the current decision; the
env applies ``saturate_norm(u_cmd + correction, u_max)``. ``reset()`` removes the hook (a
controller registers it again for its episode: ``satenv.baselines.TubeRDMPC`` does so itself).

Spaces (per agent; float32)
---------------------------
Action ``Box(-1, 1, (3,))``: LVLH acceleration ``u = a * u_max`` clipped to the ball
``||u|| <= u_max`` [m/s^2] (li2022: ``T_max / m`` = 1 N / 50 kg = 0.02 m/s^2).

Observation ``Box(-inf, inf, (19 + 7 K,))`` with ``K = min(n_neighbours, M - 1)``, normalised
with ``L = 1000 m`` and ``V = 1 m/s``:

=========  =======================================================================
entries    meaning
=========  =======================================================================
0–2        position error to the allocated target ``(q_i - q_id) / L``
3–5        velocity ``p_i / V`` (the targets are at rest)
6–8        own position ``q_i / L``
9–14       obstacle relative to the satellite ``(q_o - q_i) / L``, ``(p_o - p_i) / V``
15–17      target spacecraft relative to the satellite ``(q_r - q_i) / L``
18         fraction of the episode remaining ``1 - t / max_steps``
19 …       K slots of 7, the graph neighbours nearest first:
           ``[1, (q_j - q_i) / L, (p_j - p_i) / V]``; unused slots are zeros
=========  =======================================================================

With ``obs_neighbours = K`` (an int, default ``None``) the layout is fixed whatever ``M``:
``19 + 7 K`` entries, the same 19 first, then always ``K`` slots of the ``K`` nearest other
satellites within ``comm_range`` (whatever ``n_neighbours``), nearest first, each
``[1, (q_j - q_i) / L, (p_j - p_i) / V]`` or zeros (flag 0) when fewer are in range. A policy on
it flies any team size; a set encoder (``satenv.training.set_policy``) reads the slots as an unordered
set. With ``K = n_neighbours <= M - 1`` it equals the default layout entry for entry.

``state()`` returns the global state ``(6 M + 6,)``: the satellites' states, then the obstacle's
position and velocity.

Reward (per satellite)
----------------------
``r_i = -||q_i - q_id|| / reward_distance_scale - reward_control_weight (||a_i|| / u_max)^2
- collision_penalty * collision_i`` after the step, ``a_i`` the mean applied acceleration.

``reward="training"`` (the default of a training task's env, :mod:`satenv.tasks`) replaces this
with the training reward of :mod:`satenv.rewards` (progress toward the target, a bonus inside the
success tolerance, a success bonus, penalties for collision, violation and leaving the region);
``reward="paper"`` (the default) keeps it. Under either, the infos carry ``safety_cost`` (1.0 on
a collision or a hard-bound violation of the agent in the step, else 0.0).

Termination / truncation
------------------------
Terminated (all agents) when a safety distance is violated at any physics step (only if
``terminate_on_collision``; satellites ``< 2 r_s = 200 m`` apart, ``< r_s + r_o = 400 m`` from the
obstacle or ``< r_s + r_t = 100 m`` from the target spacecraft) or when a satellite leaves the
ball of radius ``max_distance``. Truncated after ``max_steps`` decisions (400, i.e. 2000 s).

Infos (per agent, SI units; distances are minima over the physics steps of the period)
------------------------------------------------------------------------------------
``state`` (6,), ``accel`` (3,) mean applied acceleration [m/s^2], ``delta_v`` [m/s] (sum of
``||u|| physics_dt``), ``thrust_peak`` largest ``||u||`` [m/s^2], ``tracking_error`` (6,)
``x_i - [q_id, 0]``, ``pair_distance`` to the nearest satellite, ``obstacle_distance``,
``target_distance`` (to the target spacecraft), ``min_separation`` (smallest of the three centre
distances), ``collision`` (bool, any safety distance violated), ``violations`` (int, how many of the
three), ``cost`` (float, = violations), ``target_index`` (int, allocated target),
``n_neighbours`` (int, graph degree).

Version History
---------------
* v0: initial release.
* v0 (unreleased changes, still v0): one env surface across satenv — ``thrust_max`` [N] replaced by
  ``u_max`` [m/s^2] (``thrust_max`` is now the derived ``u_max * mass``); new ``randomize`` (random
  initial positions and target slots; ``random_position_spread`` alone no longer randomises); new
  ``success_tol`` and ``collision_voids_success``; ``render_speedup = 50``; ``state_space``,
  ``observation_spaces`` / ``action_spaces`` dicts, ``metadata["render_fps"]`` from ``dt``;
  ``raw_env`` is the raw AEC env; base class ``SatParallelEnv`` (was ``FormationEnv``).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from pettingzoo import AECEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from satenv.allocation import hungarian_assignment
from satenv.cluster_graph import in_range_nearest, nearest_neighbour_graph, pairwise_distances
from satenv.dynamics import (
    BoundedRandomDisturbance,
    RelativeModel,
    saturate_norm,
    sinusoid_disturbance,
)
from satenv.dynamics._checks import as_array, numeric
from satenv.envs.base import BatchedCore, SatenvError, SatParallelEnv, StepResult, resolve_preset
from satenv.neighbours import DENSE_MAX, nearest, norm3
from satenv.scenarios.cluster import (
    DEFAULT_PRESET,
    PRESETS,
    ClusterScenario,
    resolve_scenario,
    sample_initial_state,
    sample_targets,
)

__all__ = ["ClusterCore", "ClusterEnv", "InnerLoop", "POS_SCALE", "VEL_SCALE", "env",
           "own_action_jacobian", "parallel_env", "raw_env"]

POS_SCALE = 1000.0
"""Observation position scale L [m]."""
VEL_SCALE = 1.0
"""Observation velocity scale V [m/s]."""
N_FIXED_OBS = 19
CANDIDATES = 4
"""Neighbour candidates per satellite of the sparse separation search (module docstring of
:class:`ClusterCore`)."""


def own_action_jacobian(obs: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How each satellite's next observation moves with its own acceleration, all else held:
    ``d obs+ / d u`` ``(..., D, 3)`` [per m/s^2] for raw observations ``obs (..., D)`` in the layout of
    the module docstring (the neighbour slots filled now move) and the one-decision input matrix
    ``b (6, 3)`` of ``x+ = A x + b u`` (e.g. :func:`satenv.dynamics.cw_matrices`). Exact for linear
    relative dynamics while the neighbour slots keep their order."""
    obs = numeric(obs, "own_action_jacobian obs")
    b = as_array(b, "own_action_jacobian b", (6, 3), min_ndim=2)
    k = (obs.shape[-1] - N_FIXED_OBS) // 7 if obs.ndim else -1
    if k < 0 or obs.shape[-1] != N_FIXED_OBS + 7 * k or b.ndim != 2:
        raise SatenvError(f"own_action_jacobian needs observations of {N_FIXED_OBS} + 7 K entries and b of "
                          f"shape (6, 3), got {obs.shape} and {b.shape}")
    bq, bp = b[:3] / POS_SCALE, b[3:] / VEL_SCALE
    rows = np.zeros((N_FIXED_OBS, 3))
    rows[0:3], rows[3:6], rows[6:9] = bq, bp, bq            # error to the target, velocity, position
    rows[9:12], rows[12:15], rows[15:18] = -bq, -bp, -bq    # obstacle and target spacecraft, relative
    slot = np.concatenate([np.zeros((1, 3)), -bq, -bp])     # [flag, q_j - q_i, p_j - p_i]
    flags = obs[..., N_FIXED_OBS::7][..., :k, None, None]   # (..., K, 1, 1): filled slots move
    slots = (flags * slot).reshape(*obs.shape[:-1], 7 * k, 3)
    return np.concatenate([np.broadcast_to(rows, (*obs.shape[:-1], N_FIXED_OBS, 3)), slots], axis=-2)


def _kernel_module():
    """:mod:`satenv.envs._cluster_kernel`, or ``None`` without numba."""
    try:
        from satenv.envs import _cluster_kernel
    except ImportError:
        return None
    return _cluster_kernel


class InnerLoop(Protocol):
    """A controller the env calls at every physics step (see the module docstring)."""

    def correction(self, t: np.ndarray, x: np.ndarray, chief: np.ndarray,
                   u_cmd: np.ndarray) -> np.ndarray: ...


class ClusterCore(BatchedCore):
    """Batched cluster physics and task logic (``B`` copies, ``M`` satellites).

    Two paths give the same numbers (``method``; ``"auto"``: dense up to
    :data:`satenv.neighbours.DENSE_MAX` satellites, the li2022 sizes): ``"dense"`` builds the
    ``M x M`` distance matrix at every physics step and the graph as an adjacency matrix;
    ``"sparse"`` costs ``O(M log M)`` per copy: the observation's neighbours come from an exact
    k-nearest search (:func:`satenv.cluster_graph.in_range_nearest`), and the nearest-satellite
    distance over a decision from :data:`CANDIDATES` candidates found once at its start. The
    candidates hold the nearest satellite at every physics step when the gap between the
    first and the last candidate is at least 4 times the largest displacement in the copy over the
    decision (no other satellite can come closer); the copies where that fails are searched again
    at every physics step, so ``pair_distance`` and ``min_separation`` stay exact.

    ``fused`` (default, with numba): a decision's physics steps run in one call of the compiled
    truth kernel, one DOP853 step over the decision (``decision_model``; RK4 physics steps with
    the random disturbance), and the separation minima in one compiled pass (:meth:`_step_fused`,
    when no inner loop is registered), and the dense path's graph and observation are compiled
    (:mod:`satenv.envs._cluster_kernel`), as are its infos, rewards and terminations
    (:func:`satenv.envs._cluster_kernel.decision`). ``fused=False`` is the numpy reference.
    """

    state_dim = 6
    action_dim = 3

    def __init__(self, scenario: ClusterScenario, batch: int = 1, method: str = "auto",
                 fused: bool = True) -> None:
        super().__init__(scenario, batch)
        sc = scenario
        m = self.n_agents
        if method not in ("auto", "dense", "sparse"):
            raise ValueError(f"method must be 'auto', 'dense' or 'sparse', got {method!r}")
        self.dense = method == "dense" or (method == "auto" and m <= DENSE_MAX)
        self.n_slots = min(sc.n_neighbours, m - 1)
        # the observation's neighbour slots: the graph's, or obs_neighbours of them whatever M is
        self.obs_slots = self.n_slots if sc.obs_neighbours is None else sc.obs_neighbours
        self.obs_dim = N_FIXED_OBS + 7 * self.obs_slots
        self.orbit = sc.orbit
        self.model = RelativeModel(sc.dynamics, self.orbit, sc.physics_dt)
        # the fused step's: one DOP853 step over a decision's physics steps (their inputs exactly;
        # RK4 steps for the random disturbance, a new draw at every physics step: satenv.dynamics)
        self.decision_model = (self.model if sc.disturbance == "random" else
                               RelativeModel(sc.dynamics, self.orbit, sc.physics_dt, integrator="dop853"))
        self.all_targets = np.tile(sc.targets_array(), (self.batch, 1, 1))  # (B, T, 3) slots
        self.q_r = np.asarray(sc.target_spacecraft, dtype=float)
        self.p_obs = np.asarray(sc.obstacle_velocity, dtype=float)
        self.x = np.zeros((self.batch, m, 6))
        self.chief = np.tile(self.model.initial_chief(), (self.batch, 1))
        self.assignment = np.tile(np.arange(m), (self.batch, 1))
        self.accel = np.zeros((self.batch, m, 3))
        self.inner_loop: InnerLoop | None = None
        self._random = (BoundedRandomDisturbance(sc.disturbance_amplitude)
                        if sc.disturbance == "random" else None)
        self._own_rng = np.random.default_rng()
        self._kernel = _kernel_module() if fused else None
        self._graph_cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._one_pass = True     # the dense fused step's one compiled pass (False: the numpy glue)
        self._obstacle = (np.asarray(sc.obstacle_position, dtype=float), np.asarray(sc.obstacle_velocity, dtype=float))
        self._limits = np.array([sc.pair_distance, sc.obstacle_distance, sc.target_distance, sc.reward_distance_scale,
                                 sc.reward_control_weight, sc.u_max, sc.collision_penalty, sc.max_distance,
                                 float(sc.terminate_on_collision)], dtype=float)

    # ------------------------------------------------------------------ helpers
    def time(self) -> np.ndarray:
        """Elapsed time of every copy [s] ``(B,)``."""
        return self.t * self.scenario.dt

    def targets(self) -> np.ndarray:
        """Allocated target positions ``(B, M, 3)``."""
        return np.take_along_axis(self.all_targets, self.assignment[..., None], axis=1)

    def obstacle(self, t: np.ndarray | None = None) -> np.ndarray:
        """Obstacle positions ``(B, 3)`` at times ``t`` (default: now)."""
        return self.scenario.obstacle_at(self.time() if t is None else t)

    def graph(self) -> np.ndarray:
        """Communication adjacency ``(B, M, M)`` bool from the current true positions."""
        sc = self.scenario
        return nearest_neighbour_graph(self.x[..., :3], sc.n_neighbours, sc.comm_range)

    def allocate(self, idx=None) -> None:
        sc = self.scenario
        sel = slice(None) if idx is None else idx
        if sc.allocation == "hungarian":
            self.assignment[sel] = hungarian_assignment(self.x[sel, :, :3], self.all_targets[sel])
        else:
            self.assignment[sel] = np.arange(self.n_agents)

    def _distances(self, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per satellite: nearest other satellite, obstacle and target-spacecraft distances."""
        m = self.n_agents
        pos = x[..., :3]
        if not self.dense:
            pair = nearest(pos, 1)[0][..., 0]
        elif m > 1:
            d = pairwise_distances(pos)
            d[..., np.arange(m), np.arange(m)] = np.inf
            pair = d.min(axis=-1)
        else:
            pair = np.full(pos.shape[:-1], np.inf)
        return (pair,) + self._body_distances(pos, t)

    def _body_distances(self, pos: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per satellite: obstacle and target-spacecraft distances."""
        obs = np.linalg.norm(pos - self.scenario.obstacle_at(t)[:, None, :], axis=-1)
        tgt = np.linalg.norm(pos - self.q_r, axis=-1)
        return obs, tgt

    def _pair_minimum(self, path: np.ndarray) -> np.ndarray:
        """Sparse path: each satellite's distance to the nearest other one, minimum over the
        physics-step positions ``path`` ``(S + 1, B, M, 3)`` (the first at the decision's start);
        the candidate search of the class docstring."""
        m = self.n_agents
        if m == 1:
            return np.full(path.shape[1:3], np.inf)
        start, after = path[0], path[1:]
        d0, idx = nearest(start, CANDIDATES)
        idx = idx[..., :m - 1]
        shift = norm3(after - start).max(axis=(0, 2))                              # (B,) largest move
        exact = (idx.shape[-1] == m - 1) | (d0[..., idx.shape[-1] - 1] - d0[..., 0] >= 4 * shift[:, None])
        rows = (idx + (np.arange(idx.shape[0]) * m)[:, None, None]).reshape(-1)
        pair = np.full(start.shape[:2], np.inf)
        for p in after:                                                             # (B, M, 3) each
            cand = p.reshape(-1, 3)[rows].reshape(idx.shape + (3,))
            np.minimum(pair, norm3(cand - p[:, :, None]).min(axis=-1), out=pair)
        redo = np.unique(np.nonzero(~exact)[0])
        if redo.size:
            pair[redo] = np.min([nearest(p[redo], 1)[0][..., 0] for p in after], axis=0)
        return pair

    def _disturbance(self, t: np.ndarray, rng: np.random.Generator | None) -> np.ndarray | float:
        sc = self.scenario
        if sc.disturbance == "sinusoid":
            return sinusoid_disturbance(t, sc.disturbance_amplitude)[:, None, :]
        if sc.disturbance == "random":
            return self._random.sample(rng if rng is not None else self._own_rng, self.x.shape[:-1])
        return 0.0

    def _info(self, sel, accel, dv, peak, pair, obs, tgt) -> dict[str, np.ndarray]:
        sc = self.scenario
        x = self.x[sel]
        err = x.copy()
        err[..., :3] -= np.take_along_axis(self.all_targets[sel], self.assignment[sel][..., None], axis=1)
        flags = np.stack([pair < sc.pair_distance, obs < sc.obstacle_distance,
                          tgt < sc.target_distance], axis=-1)
        viol = flags.sum(axis=-1).astype(np.int64)
        return {
            "state": x.copy(),
            "accel": accel.copy(),
            "delta_v": dv,
            "thrust_peak": peak,
            "tracking_error": err,
            "pair_distance": pair,
            "obstacle_distance": obs,
            "target_distance": tgt,
            "min_separation": np.minimum(np.minimum(pair, obs), tgt),
            "collision": viol > 0,
            "violations": viol,
            "cost": viol.astype(float),
            "target_index": self.assignment[sel].copy(),
            "n_neighbours": self._degrees(x[..., :3]),
        }

    def _degrees(self, pos: np.ndarray) -> np.ndarray:
        """Graph degree of every satellite ``(B, M)`` int (``out + in - mutual`` links of the
        k-nearest lists on the sparse path)."""
        sc = self.scenario
        if self.dense and self._kernel is not None:
            return self._neighbours(pos)[1].copy()   # a new array for the infos (the graph is cached)
        if self.dense:
            adj = nearest_neighbour_graph(pos, sc.n_neighbours, sc.comm_range)
            return adj.sum(axis=-1).astype(np.int64)
        b, m = pos.shape[:2]
        idx = in_range_nearest(pos, sc.n_neighbours, sc.comm_range)[1]
        valid = idx >= 0
        node = (idx + (np.arange(b) * m)[:, None, None])[valid]
        heard = np.bincount(node, minlength=b * m).reshape(b, m)
        back = np.take_along_axis(idx[:, None, :, :], np.maximum(idx, 0)[..., None], axis=2)
        mutual = (back == np.arange(m)[None, :, None, None]).any(axis=-1) & valid  # (B, M, K)
        return (valid.sum(axis=-1) + heard - mutual.sum(axis=-1)).astype(np.int64)

    # ------------------------------------------------------------------ episode
    def sample_initial_state(self, rng: np.random.Generator, n: int) -> np.ndarray:
        sc = self.scenario
        if not sc.randomize or (sc.random_position_spread == 0.0 and sc.random_start == "preset"):
            return np.tile(sc.initial_array(), (n, 1, 1))   # the preset's (no draw), as sample_initial_state returns it
        return np.stack([sample_initial_state(sc, rng) for _ in range(n)])

    def reset(self, x0, idx=None, rng=None):
        x0 = np.asarray(x0, dtype=float)
        sel = slice(None) if idx is None else np.asarray(idx)
        self.x[sel] = x0
        self.t[sel] = 0
        self.chief[sel] = self.model.initial_chief()
        self.accel[sel] = 0.0
        k = self.x[sel].shape[0]
        if self.scenario.randomize:
            rng = rng if rng is not None else self._own_rng
            # a batched reset passes one generator per copy (satenv.vector.CopyGenerators)
            gens = getattr(rng, "generators", None) or [rng] * k
            self.all_targets[sel] = np.stack([sample_targets(self.scenario, g) for g in gens])
        self.allocate(sel)
        zeros = np.zeros((k, self.n_agents))
        pair, obs, tgt = self._distances(self.x[sel], np.zeros(k))
        return self._info(sel, np.zeros((k, self.n_agents, 3)), zeros, zeros.copy(), pair, obs, tgt)

    def step(self, accel, rng=None) -> StepResult:
        if self.inner_loop is None and self._kernel is not None:
            return self._step_fused(np.asarray(accel, dtype=float), rng)[0]
        sc = self.scenario
        accel = np.asarray(accel, dtype=float)
        h, n_sub = sc.physics_dt, sc.substeps
        t0 = self.time()
        shape = self.x.shape[:-1]
        u_sum = np.zeros(accel.shape)
        dv = np.zeros(shape)
        peak = np.zeros(shape)
        pair = np.full(shape, np.inf)
        obs = np.full(shape, np.inf)
        tgt = np.full(shape, np.inf)
        path = None if self.dense else np.empty((n_sub + 1,) + shape + (3,))
        if path is not None:
            path[0] = self.x[..., :3]
        for s in range(n_sub):
            ts = t0 + s * h
            u = accel
            if self.inner_loop is not None:
                u = u + np.asarray(self.inner_loop.correction(ts, self.x, self.chief, accel), dtype=float)
            u = saturate_norm(u, sc.u_max)
            self.x, self.chief = self.model.step(self.x, u + self._disturbance(ts, rng), self.chief)
            un = np.linalg.norm(u, axis=-1)
            u_sum += u
            dv += un * h
            np.maximum(peak, un, out=peak)
            if path is None:
                p, o, g = self._distances(self.x, ts + h)
                np.minimum(pair, p, out=pair)
            else:
                path[s + 1] = self.x[..., :3]
                o, g = self._body_distances(self.x[..., :3], ts + h)
            np.minimum(obs, o, out=obs)
            np.minimum(tgt, g, out=tgt)
        if path is not None:
            pair = self._pair_minimum(path)
        return self._finish(u_sum / n_sub, dv, peak, pair, obs, tgt)

    def step_observe(self, accel, rng=None) -> tuple[StepResult, np.ndarray]:
        """:meth:`step` and :meth:`observe`; on the dense fused path the finiteness check of the
        step covers the observations too (:attr:`StepResult.finite`)."""
        if (self.inner_loop is None and self._kernel is not None and self.dense and self._one_pass
                and self.scenario.obs_neighbours is None):
            res, obs = self._step_fused(np.asarray(accel, dtype=float), rng, observe=True)
            return res, obs
        return super().step_observe(accel, rng)

    def _step_fused(self, accel: np.ndarray, rng, observe: bool = False) -> tuple[StepResult, np.ndarray | None]:
        """:meth:`step` without an inner loop: the command is constant over the decision, so the
        physics steps run in one call of the compiled truth kernel (frames converted once; one
        DOP853 step with the disturbance's staircase inside it integrated exactly) and the
        separation minima in one call of :func:`satenv.envs._cluster_kernel.separations`. The same
        numbers as the physics-step loop to 1e-10 (``tests/test_cluster_kernel.py``). On the dense
        path (``_one_pass``, the default) the infos, rewards, terminations and the finiteness
        check take one compiled pass (:func:`satenv.envs._cluster_kernel.decision`) after the
        separations and (``observe``) the observation, the same numbers as the numpy glue
        (``_one_pass = False``) bit for bit.
        Returns the step and the observations (``None`` unless ``observe``)."""
        sc = self.scenario
        h, n_sub = sc.physics_dt, sc.substeps
        flat = np.ascontiguousarray(accel).reshape(-1, 3)
        u, un = np.empty_like(flat), np.empty(len(flat))
        self._kernel.saturate(flat, float(sc.u_max), u, un)            # saturate_norm, and the norms
        u, un = u.reshape(accel.shape), un.reshape(accel.shape[:-1])
        one_pass = self.dense and self._one_pass and u.shape == (*self.x.shape[:-1], 3)
        # one pass: copies at the same step share their chief's track in the truth kernel when
        # consecutive (a result never depends on which copies share a call), so they are propagated
        # grouped (``order``), the path left in that order (its row r copy order[r]'s positions)
        order = self._grouped_order() if one_pass else None
        pick = slice(None) if order is None else order
        ts = self.time() + h * np.arange(n_sub)[:, None]                       # (S, B)
        common = None   # the sinusoid: one staircase for every satellite (satenv.dynamics._span_kernel)
        if sc.disturbance == "random":     # drawn step by step: the generator's stream as the loop's
            u_steps = u[pick] + np.stack([self._disturbance(t, rng) for t in ts])[:, pick]
        else:
            u_steps = np.broadcast_to(u[pick], (n_sub, *u.shape))
            if sc.disturbance == "sinusoid":   # once per distinct step count (copies in lockstep share it)
                steps, inverse = np.unique(self.t, return_inverse=True)
                common = sinusoid_disturbance(steps * sc.dt + h * np.arange(n_sub)[:, None],
                                              sc.disturbance_amplitude)[:, inverse.reshape(-1)[pick]]
        start = self.x[..., :3]
        x, chief, path = self.decision_model.propagate(self.x[pick], u_steps, self.chief[pick], positions=True,
                                                       common=common)
        if not one_pass:
            self.x, self.chief = x, chief
            pair, obs, tgt = (np.full(self.x.shape[:-1], np.inf) for _ in range(3))
            self._kernel.separations(path, np.arange(self.batch), ts, h, *self._obstacle, self.q_r, self.dense,
                                     pair, obs, tgt)
            if not self.dense:
                pair = self._pair_minimum(np.concatenate([start[None], path]))
            res = self._finish(u, un * (h * n_sub), un, pair, obs, tgt)
            return res, (self.observe() if observe else None)
        if order is None:
            order = np.arange(self.batch)
            self.x, self.chief = x, chief
        else:
            self.x, self.chief = np.empty_like(x), np.empty_like(chief)
            self.x[order], self.chief[order] = x, chief
        b, m = self.x.shape[:2]
        bm = (b, m)
        pair, obs_d, tgt_d = (np.full(bm, np.inf) for _ in range(3))
        self._kernel.separations(path, order, ts, h, *self._obstacle, self.q_r, True, pair, obs_d, tgt_d)
        self._advance(u)
        obs = self._observe(slice(None)) if observe else np.empty((0, m, self.obs_dim), np.float32)
        degree = self._neighbours(self.x[..., :3])[1]       # the graph of the observation (cached)
        err, min_sep, cost, rewards = np.empty((b, m, 6)), np.empty(bm), np.empty(bm), np.empty(bm)
        collision, viol = np.empty(bm, bool), np.empty(bm, np.int64)
        terminated, finite = np.empty(b, bool), np.empty(b, bool)
        self._kernel.decision(self.x, self.all_targets, self.assignment, un, pair, obs_d, tgt_d, self._limits, obs,
                              err, min_sep, collision, viol, cost, rewards, terminated, finite)
        info = {"state": self.x.copy(), "accel": u.copy(), "delta_v": un * (h * n_sub), "thrust_peak": un,
                "tracking_error": err, "pair_distance": pair, "obstacle_distance": obs_d, "target_distance": tgt_d,
                "min_separation": min_sep, "collision": collision, "violations": viol, "cost": cost,
                "target_index": self.assignment.copy(), "n_neighbours": degree.copy()}
        return StepResult(rewards, terminated, info, finite), (obs if observe else None)

    def _grouped_order(self) -> np.ndarray | None:
        """The copies sorted by step count when copies at the same step are not already
        consecutive (else ``None``)."""
        t = self.t
        runs = 1 + np.count_nonzero(t[1:] != t[:-1])
        if runs <= 1 or runs == len(np.unique(t)):
            return None
        return np.argsort(t, kind="stable")

    def _advance(self, accel: np.ndarray) -> None:
        """The decision's count, command and reallocation (when due)."""
        sc = self.scenario
        self.t += 1
        self.accel = accel
        if sc.reallocate_every > 0:
            due = self.t % sc.reallocate_every == 0
            if np.any(due):
                self.allocate(np.nonzero(due)[0])

    def _finish(self, accel, dv, peak, pair, obs, tgt) -> StepResult:
        """The end of a decision: step count, reallocation, infos, rewards, terminations."""
        sc = self.scenario
        self._advance(accel)
        info = self._info(slice(None), self.accel, dv, peak, pair, obs, tgt)
        dist = np.linalg.norm(info["tracking_error"][..., :3], axis=-1)
        rewards = (-dist / sc.reward_distance_scale
                   - sc.reward_control_weight * (np.linalg.norm(self.accel, axis=-1) / sc.u_max) ** 2
                   - sc.collision_penalty * info["collision"])
        terminated = (np.linalg.norm(self.x[..., :3], axis=-1) > sc.max_distance).any(axis=-1)
        if sc.terminate_on_collision:
            terminated |= info["collision"].any(axis=-1)
        return StepResult(rewards, terminated, info)

    # ------------------------------------------------------------------ observations
    def observe(self) -> np.ndarray:
        return self._observe(slice(None))

    def observe_copies(self, idx: np.ndarray) -> np.ndarray:
        return self._observe(idx)

    def _neighbours(self, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compiled dense graph: neighbour slots ``(B, M, K)`` (nearest first, ``-1`` empty) and
        degrees ``(B, M)`` (:func:`satenv.envs._cluster_kernel.neighbours`)."""
        cached = self._graph_cache
        if cached is not None and cached[0].shape == pos.shape and np.array_equal(cached[0], pos):
            return cached[1], cached[2]   # a step's infos and its observation share one graph
        b, m = pos.shape[:2]
        order, degree = np.empty((b, m, self.n_slots), np.int64), np.empty((b, m), np.int64)
        pos = np.ascontiguousarray(pos)
        self._kernel.neighbours(pos, self.n_slots, float(self.scenario.comm_range), order, degree)
        self._graph_cache = (pos.copy(), order, degree)
        return order, degree

    def _fixed_slots(self, q: np.ndarray) -> np.ndarray:
        """The fixed layout's slots (``obs_neighbours = K``): the ``K`` nearest other satellites
        within ``comm_range``, nearest first, ``-1`` for an empty slot ``(B, M, K)``."""
        order = np.full(q.shape[:2] + (self.obs_slots,), -1, np.int64)
        found = in_range_nearest(q, self.obs_slots, self.scenario.comm_range)[1]
        order[..., :found.shape[-1]] = found
        return order

    def _observe(self, sel) -> np.ndarray:
        """Observations of the copies ``sel`` (a slice or indices)."""
        sc = self.scenario
        x, t = self.x[sel], self.t[sel]
        b, m = x.shape[0], self.n_agents
        fixed = sc.obs_neighbours is not None
        if (self.dense or fixed) and self._kernel is not None:
            obs = np.empty((b, m, self.obs_dim), np.float32)
            order = self._fixed_slots(x[..., :3]) if fixed else self._neighbours(x[..., :3])[0]
            self._kernel.observe(np.ascontiguousarray(x), self.all_targets[sel], self.assignment[sel],
                                 self._obstacle[0], self.p_obs, t, float(sc.dt), float(sc.max_steps), self.q_r,
                                 order, POS_SCALE, VEL_SCALE, obs)
            return obs
        q, p = x[..., :3], x[..., 3:]
        obs = np.zeros((b, m, self.obs_dim))
        obs[..., 0:3] = (q - self.targets()[sel]) / POS_SCALE
        obs[..., 3:6] = p / VEL_SCALE
        obs[..., 6:9] = q / POS_SCALE
        obs[..., 9:12] = (self.scenario.obstacle_at(t * sc.dt)[:, None, :] - q) / POS_SCALE
        obs[..., 12:15] = (self.p_obs - p) / VEL_SCALE
        obs[..., 15:18] = (self.q_r - q) / POS_SCALE
        obs[..., 18] = 1.0 - t[:, None] / sc.max_steps
        k = self.obs_slots
        if k > 0 and (fixed or not self.dense):  # the graph's nearest neighbours are the in-range k-nearest
            order = self._fixed_slots(q) if fixed else in_range_nearest(q, sc.n_neighbours, sc.comm_range)[1]
            valid = order >= 0
            nb = np.take_along_axis(x[:, None, :, :], np.maximum(order, 0)[..., None], axis=2)
            rel = (nb - x[:, :, None, :]) / np.array([POS_SCALE] * 3 + [VEL_SCALE] * 3)
            slots = np.concatenate([np.ones(valid.shape + (1,)), rel], axis=-1) * valid[..., None]
            obs[..., N_FIXED_OBS:] = slots.reshape(b, m, 7 * k)
        elif k > 0:
            adj = nearest_neighbour_graph(q, sc.n_neighbours, sc.comm_range)
            d = pairwise_distances(q)
            d = np.where(adj, d, np.inf)
            order = np.argsort(d, axis=-1, kind="stable")[..., :k]          # (B, M, K)
            valid = np.take_along_axis(d, order, axis=-1) < np.inf            # (B, M, K)
            nb = np.take_along_axis(x[:, None, :, :], order[..., None], axis=2)  # (B, M, K, 6)
            rel = (nb - x[:, :, None, :]) / np.array([POS_SCALE] * 3 + [VEL_SCALE] * 3)
            slots = np.concatenate([np.ones(valid.shape + (1,)), rel], axis=-1) * valid[..., None]
            obs[..., N_FIXED_OBS:] = slots.reshape(b, m, 7 * k)
        return obs.astype(np.float32)

    def global_state(self) -> np.ndarray:
        obs_pos = self.obstacle()
        vel = np.broadcast_to(self.p_obs, obs_pos.shape)
        return np.concatenate([self.x.reshape(self.batch, -1), obs_pos, vel], axis=-1)

    def render_scene(self, b: int = 0) -> dict[str, Any]:
        sc = self.scenario
        return {
            "positions": self.x[b, :, :3].copy(),
            "labels": [f"s{i + 1}" for i in range(self.n_agents)],
            "targets": self.targets()[b],
            "spheres": [(self.obstacle()[b], sc.obstacle_distance, "obstacle keep-out"),
                        (self.q_r, sc.target_distance, "target spacecraft keep-out")],
            "title": f"cluster_v0 ({sc.name})  t = {self.time()[b]:.0f} s",
        }


class ClusterEnv(SatParallelEnv):
    """The cluster ``ParallelEnv`` (see the module docstring)."""

    metadata = {**SatParallelEnv.metadata, "name": "cluster_v0"}
    render_speedup = 50.0  # one decision (5 s) per frame at 10 fps
    core_class = ClusterCore
    agent_prefix = "sat"

    def __init__(self, preset: str = DEFAULT_PRESET, render_mode: str | None = None, reward: str = "paper",
                 **kwargs) -> None:
        scenario = resolve_preset("cluster_v0", preset, PRESETS, resolve_scenario, kwargs)
        super().__init__(scenario, render_mode=render_mode, reward=reward)

    def reset(self, seed: int | None = None, options: dict | None = None):
        self.core.inner_loop = None
        return super().reset(seed=seed, options=options)

    # ---- what controllers read -----------------------------------------------------------------
    def set_inner_loop(self, controller: InnerLoop | None) -> None:
        """Register (or remove, with ``None``) the physics-rate controller hook for this episode."""
        if controller is not None and not callable(getattr(controller, "correction", None)):
            raise SatenvError(f"inner loop must have a correction(t, x, chief, u_cmd) method, got "
                              f"{type(controller).__name__}")
        self.core.inner_loop = controller

    @property
    def inner_loop(self) -> InnerLoop | None:
        return self.core.inner_loop

    @property
    def time(self) -> float:
        """Elapsed time of the episode [s]."""
        return float(self.core.time()[0])

    @property
    def assignment(self) -> np.ndarray:
        """Index of the target allocated to each satellite ``(M,)``."""
        return self.core.assignment[0].copy()

    def targets(self) -> np.ndarray:
        """Allocated target positions ``(M, 3)`` [m]."""
        return self.core.targets()[0].copy()

    def obstacle_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The obstacle's current position and velocity (3,), (3,) in LVLH (li2022 Assumption 1)."""
        return self.core.obstacle()[0].copy(), self.core.p_obs.copy()

    def graph(self) -> np.ndarray:
        """Current communication adjacency ``(M, M)`` bool."""
        return self.core.graph()[0]


def parallel_env(**kwargs) -> ClusterEnv:
    """The PettingZoo ``ParallelEnv`` (keyword arguments: module docstring)."""
    return ClusterEnv(**kwargs)


def raw_env(**kwargs) -> AECEnv:
    """The raw AEC env (``parallel_to_aec_wrapper``, no further wrappers)."""
    return parallel_to_aec_wrapper(ClusterEnv(**kwargs))


def env(**kwargs) -> AECEnv:
    """The AEC env: :func:`raw_env` with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcingWrapper(raw_env(**kwargs))
