"""formation_v0 — reaching a predefined connected spacecraft formation (kannan2022 §5).

``satenv.envs.formation_v0.parallel_env(**kwargs)`` returns a PettingZoo ``ParallelEnv``;
``env(**kwargs)`` the AEC version; ``raw_env(**kwargs)`` the raw AEC env (no wrappers), as
PettingZoo names it.

M spacecraft ``sat_1 … sat_M`` (3 in the presets) fly in the LVLH frame of a virtual centre on a
circular orbit of mean motion ``n0`` (x radial, y along-track, z orbit normal). Each one must reach
an **absolute goal** position, or — leader–follower mode — hold an offset from a leader spacecraft,
while the proximity network (link iff distance <= delta, §4.3) stays connected.

Why a separate env and not presets of ``platoon_v0``: the platoon env flies followers relative to a
passive leader on V-bar with pereira2023's neighbourhood errors over a communication graph;
kannan2022 has no passive leader (the origin is a virtual centre), gives absolute goals, and its
leader–follower variant couples only the y-spacing to one of the controlled spacecraft. Those
errors and the connectivity check do not fit the platoon's task definition.

Arguments (keywords; all optional)
----------------------------------
``preset``        ``"kannan2022-position"`` (default, §5.1: all from [0,0,0] to [100,100,100],
                  [100,200,100], [100,300,100] m) or ``"kannan2022-collision"`` (§5.2: sat_2 to
                  [100,100,100] m, sat_1 / sat_3 at y_2 +/- 10 m with the same x and z).
                  Common values: n0 = 0.0011 rad/s, |u| <= 50 m/s^2 per axis (box), dt = 0.01 s,
                  max_steps = 2000 (20 s), delta = 150 m; the paper gives no sampling time,
                  duration, range or weights: see :mod:`satenv.scenarios.formation` (dt = 0.01 s
                  keeps the C/GMRES continuation error small; for RL a larger ``dt`` may suit).
``render_mode``   ``None``, ``"rgb_array"`` or ``"human"``.
any field of :class:`satenv.scenarios.formation.FormationScenario` overrides the preset, e.g.
``dynamics="cw" | "nonlinear" | "j2" | "j2_drag"``, ``connection_range``, ``max_steps``, ``dt``,
``u_max`` [m/s^2, per axis], ``terminate_on_disconnect=True``, ``collision_distance``,
``terminate_on_collision``, ``randomize=True``, ``goals``, ``success_tol`` (1 m),
``collision_voids_success``, ``obs_neighbours`` (``None`` or ``K`` in ``[1, 64]``: the fixed
observation layout below).
Unknown keywords raise ``SatenvError`` (a ``ValueError``).
``reset(seed=..., options={"initial_state": array (M, 6)})`` starts from a given state.

Spaces (per agent; float32)
---------------------------
Action ``Box(-1, 1, (3,))``: LVLH acceleration ``u = a * u_max`` (per-axis box, kannan2022
``-50 <= u <= 50``).

Observation ``Box(-inf, inf, (6 M + 1,))`` (19 for M = 3), normalised with ``L = length_scale``
(100 m) and ``V = sqrt(L u_max)`` (70.7 m/s):

=========  ==========================================================================
entries    meaning
=========  ==========================================================================
0–2        formation error ``e_i`` / L: ``p_i - goal_i``, or for a follower
           ``p_i - p_leader - offset_i`` (the cost's error, eq. 33/34)
3–5        own velocity / V (the targets are at rest)
6 …        per other agent j (ascending index, self skipped): ``(x_j - x_i)`` / (L, V)
last       1 if the proximity graph is connected, else 0
=========  ==========================================================================

With ``obs_neighbours = K`` (an int, default ``None``) the layout is fixed whatever ``M``:
``7 + 7 K`` entries, ``e_i / L``, ``v_i / V``, the connectivity flag, then ``K`` slots of the
nearest other spacecraft, nearest first, each ``[1, (x_j - x_i) / (L, V)]`` or zeros (flag 0)
beyond ``M - 1`` (for a set encoder, ``satenv.training.set_policy``).

``state()`` returns the global state: the M LVLH states flattened ``(6 M,)`` float64.

Reward (per agent, the normalised stage cost of eq. 33/34)
----------------------------------------------------------
``r_i = -1/2 (e_i/L)^T diag(q_i) (e_i/L) - 1/2 input_weight |u_i/u_max|^2
- connection_penalty * cut_i`` after the step, with ``q_i`` = ``position_weight`` per axis
(followers: ``offset_weight`` on y) and ``cut_i`` = 1 when agent i is outside the largest
connected component of the proximity graph (ties: the component of the lowest index).

``reward="training"`` (the default of a training task's env, :mod:`satenv.tasks`) replaces this
with the training reward of :mod:`satenv.rewards` (progress toward the target, a bonus inside the
success tolerance, a success bonus, penalties for collision, violation and leaving the region);
``reward="paper"`` (the default) keeps it. Under either, the infos carry ``safety_cost`` (1.0 on
a collision or a hard-bound violation of the agent in the step, else 0.0).

Termination / truncation
------------------------
Terminated (all agents) when a spacecraft leaves the ball of radius ``max_distance`` around the
origin, when a pair is closer than ``collision_distance`` (0 by default = never: the paper starts
all three at the same point; only if ``terminate_on_collision``), or — only with
``terminate_on_disconnect`` — when the proximity graph disconnects. Truncated at ``max_steps``.

Infos (per agent, SI units)
---------------------------
``state`` (6,), ``accel`` (3,) applied [m/s^2], ``delta_v`` [m/s] this step,
``tracking_error`` (6,) ``[p_i - p_i*, v_i]`` with ``p_i*`` the final position the paper reports
(followers: leader goal + offset), ``formation_error`` (3,) the cost's ``e_i``,
``min_separation`` [m] to the nearest other spacecraft, ``collision`` (bool),
``connected`` (bool, the whole proximity graph, same for every agent), ``degree`` (int, number
of spacecraft within delta), ``violations`` (int) = ``cut_i``, ``cost`` = ``collision + cut_i``.

Version History
---------------
* v0: initial release.
* v0 (unreleased changes, still v0): one env surface across satenv — new ``terminate_on_collision``
  (default True, the previous behaviour), ``success_tol`` and ``collision_voids_success``;
  ``render_speedup = 0.1``; ``state_space``, ``observation_spaces`` / ``action_spaces`` dicts,
  ``metadata["render_fps"]`` from ``dt``; ``raw_env`` is the raw AEC env; base class
  ``SatParallelEnv`` (was ``FormationEnv``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pettingzoo import AECEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from satenv.dynamics import MU_EARTH, Orbit, RelativeModel, delta_v
from satenv.envs.base import BatchedCore, SatParallelEnv, StepResult, resolve_preset
from satenv.neighbours import DENSE_MAX, nearest, pairs_within
from satenv.scenarios.formation import (
    PRESETS,
    FormationScenario,
    proximity_components,
    resolve_scenario,
    sample_initial_state,
)

__all__ = ["FormationCore", "FormationFlyingEnv", "env", "parallel_env", "raw_env"]


def reference_orbit(scenario: FormationScenario) -> Orbit:
    """The circular orbit of mean motion ``scenario.mean_motion`` (radius ``(mu / n0^2)^(1/3)``)."""
    radius = (MU_EARTH / scenario.mean_motion**2) ** (1.0 / 3.0)
    return Orbit.circular(radius)


class FormationCore(BatchedCore):
    """Batched kannan2022 formation physics and task logic (``B`` copies, ``M`` spacecraft).

    The infos have two paths giving the same numbers (``method``; ``"auto"``: dense up to
    :data:`satenv.neighbours.DENSE_MAX` spacecraft): ``"dense"`` builds the ``M x M`` distances and
    the reachability matrix; ``"sparse"`` finds the nearest spacecraft with an exact k-nearest
    search and the proximity links and components from the pairs within ``connection_range``
    (:func:`satenv.neighbours.pairs_within`, ``scipy.sparse.csgraph.connected_components``). The
    observation lists every other spacecraft (``6 M + 1`` entries), so it stays ``O(M)`` per agent.
    """

    state_dim = 6
    action_dim = 3

    def __init__(self, scenario: FormationScenario, batch: int = 1, method: str = "auto") -> None:
        super().__init__(scenario, batch)
        m = self.n_agents
        if method not in ("auto", "dense", "sparse"):
            raise ValueError(f"method must be 'auto', 'dense' or 'sparse', got {method!r}")
        self.dense = method == "dense" or (method == "auto" and m <= DENSE_MAX)
        self.obs_dim = 6 * m + 1 if scenario.obs_neighbours is None else 7 + 7 * scenario.obs_neighbours
        self.model = RelativeModel(scenario.dynamics, reference_orbit(scenario), scenario.dt)
        self.targets = scenario.target_positions()
        self.weights = scenario.error_weights()
        self.others = np.array([[j for j in range(m) if j != i] for i in range(m)],
                               dtype=np.int64).reshape(m, m - 1)
        self.x = np.zeros((self.batch, m, 6))
        self.chief = np.tile(self.model.initial_chief(), (self.batch, 1))
        self.accel = np.zeros((self.batch, m, 3))
        self._connected = np.ones(self.batch, dtype=bool)

    # ------------------------------------------------------------------ episode
    def sample_initial_state(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.scenario.randomize:
            return np.stack([sample_initial_state(self.scenario, rng) for _ in range(n)])
        return np.tile(self.scenario.initial_array(), (n, 1, 1))

    def reset(self, x0, idx=None, rng=None):
        sel = slice(None) if idx is None else idx
        self.x[sel] = np.asarray(x0, dtype=float)
        self.t[sel] = 0
        self.chief[sel] = self.model.initial_chief()
        self.accel[sel] = 0.0
        info = self._info(self.x[sel], self.accel[sel])
        self._connected[sel] = info["connected"][:, 0]
        return info

    def step(self, accel, rng=None) -> StepResult:
        sc = self.scenario
        accel = np.asarray(accel, dtype=float)
        self.x, self.chief = self.model.step(self.x, accel, self.chief)
        self.accel = accel
        self.t += 1
        info = self._info(self.x, accel)
        self._connected = info["connected"][:, 0].copy()
        e = info["formation_error"] / sc.length_scale
        w = accel / sc.u_max
        rewards = (-0.5 * np.sum(self.weights * e * e, axis=-1)
                   - 0.5 * sc.input_weight * np.sum(w * w, axis=-1)
                   - sc.connection_penalty * info["violations"])
        terminated = (np.linalg.norm(self.x[..., :3], axis=-1) > sc.max_distance).any(axis=-1)
        if sc.terminate_on_collision:
            terminated |= info["collision"].any(axis=-1)
        if sc.terminate_on_disconnect:
            terminated |= ~self._connected
        return StepResult(rewards, terminated, info)

    # ------------------------------------------------------------------ quantities
    def _info(self, x: np.ndarray, accel: np.ndarray) -> dict[str, np.ndarray]:
        sc = self.scenario
        m = self.n_agents
        pos = x[..., :3]
        min_sep, degree, connected, cut = (self._graph_dense if self.dense else self._graph_sparse)(pos)
        collision = min_sep < sc.collision_distance
        tracking = np.concatenate([pos - self.targets, x[..., 3:]], axis=-1)
        return {
            "state": x.copy(),
            "accel": accel.copy(),
            "delta_v": delta_v(accel, sc.dt),
            "tracking_error": tracking,
            "formation_error": sc.formation_error(x),
            "min_separation": min_sep,
            "collision": collision,
            "connected": np.repeat(connected[:, None], m, axis=1),
            "degree": degree.astype(np.int64),
            "violations": cut.astype(np.int64),
            "cost": collision.astype(float) + cut,
        }

    def _graph_dense(self, pos: np.ndarray) -> tuple[np.ndarray, ...]:
        """Nearest-spacecraft distance, proximity degree ``(B, M)``, whether each copy's graph is
        connected ``(B,)`` and who is outside its largest component ``(B, M)``."""
        sc = self.scenario
        b, m = pos.shape[:2]
        dist = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
        degree = (dist <= sc.connection_range).sum(axis=-1) - 1
        dist[:, np.arange(m), np.arange(m)] = np.inf
        min_sep = dist.min(axis=-1) if m > 1 else np.full((b, m), np.inf)
        reach = proximity_components(pos, sc.connection_range)          # (B, M, M)
        connected = reach.all(axis=(1, 2))
        main = np.argmax(reach.sum(axis=-1), axis=-1)                  # first largest component
        cut = ~reach[np.arange(b), main]                               # (B, M)
        return min_sep, degree, connected, cut

    def _graph_sparse(self, pos: np.ndarray) -> tuple[np.ndarray, ...]:
        """:meth:`_graph_dense` from neighbour searches (cost proportional to the links)."""
        b, m = pos.shape[:2]
        min_sep = nearest(pos, 1)[0][..., 0]
        pairs = pairs_within(pos, self.scenario.connection_range)
        degree = np.bincount(pairs.ravel(), minlength=b * m).reshape(b, m)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(b * m, b * m))
        labels = connected_components(graph, directed=False)[1].reshape(b, m)
        size = np.bincount(labels.ravel())[labels]                       # size of each one's component
        main = np.argmax(size, axis=-1)                                  # first largest component
        cut = labels != labels[np.arange(b), main][:, None]
        return min_sep, degree, ~cut.any(axis=-1), cut

    def observe(self) -> np.ndarray:
        sc = self.scenario
        b, m = self.batch, self.n_agents
        if sc.obs_neighbours is not None:
            return self._observe_fixed()
        scale = np.array([sc.length_scale] * 3 + [sc.velocity_scale] * 3)
        obs = np.empty((b, m, self.obs_dim))
        obs[..., 0:3] = sc.formation_error(self.x) / sc.length_scale
        obs[..., 3:6] = self.x[..., 3:] / sc.velocity_scale
        if m > 1:
            rel = (self.x[:, self.others] - self.x[:, :, None]) / scale      # (B, M, M-1, 6)
            obs[..., 6:-1] = rel.reshape(b, m, -1)
        obs[..., -1] = self._connected[:, None]
        return obs.astype(np.float32)

    def _observe_fixed(self) -> np.ndarray:
        """The fixed layout (``obs_neighbours = K``, module docstring): own error and velocity,
        the connectivity flag, then ``K`` slots of the nearest others (zeros beyond ``M - 1``)."""
        sc = self.scenario
        b, m, k = self.batch, self.n_agents, sc.obs_neighbours
        scale = np.array([sc.length_scale] * 3 + [sc.velocity_scale] * 3)
        obs = np.zeros((b, m, self.obs_dim))
        obs[..., 0:3] = sc.formation_error(self.x) / sc.length_scale
        obs[..., 3:6] = self.x[..., 3:] / sc.velocity_scale
        obs[..., 6] = self._connected[:, None]
        order = nearest(self.x[..., :3], k)[1]                                   # (B, M, K), -1 empty
        valid = order >= 0
        nb = np.take_along_axis(self.x[:, None, :, :], np.maximum(order, 0)[..., None], axis=2)
        rel = (nb - self.x[:, :, None, :]) / scale
        slots = np.concatenate([np.ones(valid.shape + (1,)), rel], axis=-1) * valid[..., None]
        obs[..., 7:] = slots.reshape(b, m, 7 * k)
        return obs.astype(np.float32)

    def global_state(self) -> np.ndarray:
        return self.x.reshape(self.batch, -1).copy()

    def render_scene(self, b: int = 0) -> dict[str, Any]:
        sc = self.scenario
        link = "connected" if self._connected[b] else "DISCONNECTED"
        return {
            "positions": self.x[b, :, :3].copy(),
            "labels": [f"sat{i + 1}" for i in range(self.n_agents)],
            "targets": self.targets.copy(),
            "title": f"formation_v0 ({sc.name}) t = {self.t[b] * sc.dt:.2f} s, {link}",
        }


class FormationFlyingEnv(SatParallelEnv):
    """The kannan2022 formation ``ParallelEnv`` (see the module docstring)."""

    metadata = {**SatParallelEnv.metadata, "name": "formation_v0"}
    render_speedup = 0.1  # slow motion: one decision (0.01 s) per frame at 10 fps
    core_class = FormationCore
    agent_prefix = "sat"

    def __init__(self, preset: str = "kannan2022-position", render_mode: str | None = None,
                 reward: str = "paper", **kwargs) -> None:
        scenario = resolve_preset("formation_v0", preset, PRESETS, resolve_scenario, kwargs)
        super().__init__(scenario, render_mode=render_mode, reward=reward)


def parallel_env(**kwargs) -> FormationFlyingEnv:
    """The PettingZoo ``ParallelEnv`` (keyword arguments: module docstring)."""
    return FormationFlyingEnv(**kwargs)


def raw_env(**kwargs) -> AECEnv:
    """The raw AEC env (``parallel_to_aec_wrapper``, no further wrappers)."""
    return parallel_to_aec_wrapper(FormationFlyingEnv(**kwargs))


def env(**kwargs) -> AECEnv:
    """The AEC env: :func:`raw_env` with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcingWrapper(raw_env(**kwargs))
