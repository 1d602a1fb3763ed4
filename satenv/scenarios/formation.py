"""Connected in-plane formation scenarios of kannan2022 (§5), SI units.

Three spacecraft ``sat_1 … sat_3`` move in the LVLH (Hill) frame of a virtual centre on a circular
orbit of mean motion ``n0`` (x radial, y along-track, z orbit normal; CW eqs. 2-4) and must reach
a predefined connected network formation.

Each agent either has an **absolute goal** position (``goals[i]``), or — leader–follower mode —
it follows the ``leader`` agent at the offset ``offsets[i]`` (its target is
``p_leader + offsets[i]``). The leader must have an absolute goal.

Presets (the paper gives no weights, horizon, sampling time, duration or network range; every
such value is our choice: dt = 0.01 s — C/GMRES is a sampled continuation method whose tracking
error grows with dt —, 2000 steps = 20 s, ``position_weight = 1``, ``input_weight = 0.1``,
``offset_weight = 10`` (K_1 = K_2 of eq. 34), delta = 150 m):

* ``"kannan2022-position"`` (§5.1, Fig. 2-4): all start at ``[0, 0, 0]``, goals
  ``[100, 100, 100]``, ``[100, 200, 100]``, ``[100, 300, 100]`` m; cost (33).
* ``"kannan2022-collision"`` (§5.2, Fig. 5-7): only sat_2's goal ``[100, 100, 100]`` is known;
  sat_1 and sat_3 follow sat_2 with ``y_1 - y_2 = +10 m`` and ``y_2 - y_3 = +10 m`` and the same
  x and z (cost (34)); final configuration ``[100, 110, 100]``, ``[100, 100, 100]``,
  ``[100, 90, 100]`` as in the text of §5.2. ``K = 10`` (not 1) because with ``K = 1`` sat_1
  lags sat_2 along y and passes within 3 m of it; with ``K = 10`` the 10 m spacing and the
  ordering ``y_1 > y_2 > y_3`` hold through the manoeuvre (the paper's "collision avoidance"). The paper's formula reads
  ``e_y = y_2 - y_1 - 10`` for sat_1, which would put sat_1 at y = 90; we follow the figure
  captions (sat_1 reaches y = 110) and note the sign discrepancy.

Units of the input bound: the paper writes ``-50 <= u <= 50`` without a unit; in CW eqs. (2)-(4)
``u`` is an acceleration and positions are in metres, so ``u_max = 50 m/s^2`` per axis (box) —
about 5 g, far beyond real formation-flying thrusters: the paper's scenario is a numerical
example, and manoeuvres of a few hundred metres take seconds.

Cost weights (normalised, used by :class:`satenv.baselines.cgmres.CGMRES` and the env reward): with the
length scale ``L = length_scale`` and ``w = u / u_max``, the stage cost is
``1/2 sum_i (e_i / L)^T diag(q_i) (e_i / L) + 1/2 input_weight |w|^2`` where, per agent, ``e_i``
is the position error to its goal (weights ``position_weight`` on every axis), or for a follower
``p_i - p_leader - offset_i`` with weight ``position_weight`` on x and z and ``offset_weight``
(the paper's ``K_1 = K_2``) on y. In the paper's units this is ``Q = q / L^2`` [1/m^2] and
``R = input_weight / u_max^2`` [s^4/m^2].

Connectivity (§4.3): agents i, j are linked when ``|p_i - p_j| <= connection_range`` (delta);
the env reports whether this proximity graph is connected. The paper gives no delta: 150 m
(ours) keeps both final formations connected (neighbours 100 m / 10 m apart) with margin.

Random initial states (``randomize=True``): the nominal positions plus ``U(-s, s)`` per axis
(``s = random_position_spread``) and velocities ``U(-v, v)`` (``v = random_velocity_spread``);
draws are rejected (up to 1000 times) until the proximity graph is connected and every pair is at
least ``random_min_gap`` apart. With ``random_start="target"`` (for easier tasks) the positions are
drawn around the target formation (:meth:`FormationScenario.target_positions`) instead of the
nominal initial positions; the velocities stay the nominal ones plus ``U(-v, v)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from satenv.dynamics.constants import MU_EARTH, R_EARTH
from satenv.scenarios._fields import (
    SatenvError,
    array,
    at_most,
    derived,
    flag,
    from_preset,
    number,
    obs_neighbours,
    orbit_step,
    spreads_in_region,
    states_in_region,
    steps,
    vector,
)

__all__ = ["FormationScenario", "PRESETS", "RANDOM_STARTS", "resolve_scenario", "sample_initial_state",
           "proximity_components"]

RANDOM_STARTS = ("initial", "target")
"""The values of ``random_start``: the random positions around the nominal start or the target formation."""


@dataclass(frozen=True)
class FormationScenario:
    """Parameters of a kannan2022 formation scenario (frozen, validated; SI units).

    Args:
        name: preset name (informational).
        initial_state: (M, 6) LVLH states ``[x, y, z, vx, vy, vz]`` [m, m/s].
        goals: per agent an absolute goal position (3,) [m], or ``None`` for a follower.
        leader: index (0-based) of the agent the followers follow, ``None`` if every agent has
            a goal.
        offsets: (M, 3) desired ``p_i - p_leader`` of each follower [m] (ignored for agents with
            a goal).
        mean_motion: n0 of the reference orbit [rad/s] (kannan2022 §5: 0.0011).
        dt: decision (sampling) period [s]; max_steps: episode length (truncation).
        u_max: per-axis acceleration limit [m/s^2]; thrust_mode: ``"box"`` or ``"norm"``.
        connection_range: delta, range of the proximity graph [m].
        collision_distance: a pair closer than this collides [m]; 0 disables (the paper starts
            all three spacecraft at the same point).
        max_distance: leaving the ball of this radius around the origin terminates [m].
        terminate_on_collision: end the episode at a collision (a pair closer than
            ``collision_distance``).
        terminate_on_disconnect: end the episode when the proximity graph disconnects.
        dynamics: truth model of the env: ``"cw"``, ``"nonlinear"``, ``"j2"``, ``"j2_drag"``
            (the chief's circular orbit radius follows from ``mean_motion``).
        length_scale: L [m] normalising costs and observations; velocities use
            ``sqrt(L u_max)``.
        position_weight, offset_weight, input_weight: cost weights (module docstring).
        connection_penalty: reward penalty per step for an agent cut off from the network.
        randomize, random_position_spread, random_velocity_spread, random_min_gap: see the
            module docstring.
        random_start: where the random positions are centred: ``"initial"`` (default) the nominal
            initial positions, ``"target"`` the target formation (module docstring).
        success_tol: an episode succeeds when every spacecraft ends within this distance of its
            final position [m] (:func:`satenv.metrics.success`).
        collision_voids_success: a collision flag makes the episode a failure.
        obs_neighbours: ``None`` (default): the observation lists every other spacecraft; an int
            ``K``: ``K`` slots of the nearest others, zero-padded (a layout independent of ``M``;
            ``satenv.envs.formation_v0``).
    """

    name: str
    initial_state: tuple[tuple[float, ...], ...]
    goals: tuple[tuple[float, ...] | None, ...]
    leader: int | None = None
    offsets: tuple[tuple[float, ...], ...] | None = None
    mean_motion: float = 0.0011
    dt: float = 0.01
    max_steps: int = 2000
    u_max: float = 50.0
    thrust_mode: str = "box"
    connection_range: float = 150.0
    collision_distance: float = 0.0
    max_distance: float = 5000.0
    terminate_on_collision: bool = True
    terminate_on_disconnect: bool = False
    dynamics: str = "cw"
    length_scale: float = 100.0
    position_weight: float = 1.0
    offset_weight: float = 1.0
    input_weight: float = 0.1
    connection_penalty: float = 1.0
    randomize: bool = False
    random_position_spread: float = 20.0
    random_velocity_spread: float = 1.0
    random_min_gap: float = 1.0
    random_start: str = "initial"
    success_tol: float = 1.0
    collision_voids_success: bool = True
    obs_neighbours: int | None = None

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}")
        s(self, "max_distance", number(self.max_distance, "max_distance"))
        x0 = states_in_region(self.initial_state, "initial_state (M, 6) LVLH states",
                              self.max_distance)
        m = x0.shape[0]
        s(self, "initial_state", tuple(tuple(float(v) for v in row) for row in x0))
        if not isinstance(self.goals, (tuple, list)) or len(self.goals) != m:
            raise ValueError(f"goals must be a sequence of {m} entries (a position (3,) or None per "
                             f"spacecraft), got {self.goals!r}")
        goals = tuple(None if g is None else vector(g, f"goals[{i}]", 3) for i, g in enumerate(self.goals))
        s(self, "goals", goals)
        if self.leader is not None:
            if isinstance(self.leader, bool) or not isinstance(self.leader, (int, np.integer)) \
                    or not 0 <= self.leader < m:
                raise ValueError(f"leader must be an agent index in [0, {m - 1}] or None, got {self.leader!r}")
            s(self, "leader", int(self.leader))
            if goals[self.leader] is None:
                raise ValueError(f"the leader (agent index {self.leader}) needs an absolute goal; "
                                 "give goals[leader] a position")
        missing = [i for i, g in enumerate(goals) if g is None]
        if missing and self.leader is None:
            raise ValueError(f"agents {missing} have no goal and there is no leader to follow; give "
                             "them goals or set leader=<index> and offsets")
        if self.offsets is None:
            offsets = np.zeros((m, 3))
        else:
            offsets = array(self.offsets, "offsets", (m, 3))
        s(self, "offsets", tuple(tuple(float(v) for v in row) for row in offsets))
        for name in ("mean_motion", "dt", "u_max", "connection_range", "max_distance", "length_scale",
                     "position_weight", "input_weight", "success_tol"):
            s(self, name, number(getattr(self, name), name))
        for name in ("collision_distance", "offset_weight", "connection_penalty",
                     "random_position_spread", "random_velocity_spread", "random_min_gap"):
            s(self, name, number(getattr(self, name), name, allow_zero=True))
        s(self, "max_steps", steps(self.max_steps, "max_steps"))
        if self.thrust_mode not in ("box", "norm"):
            raise ValueError(f"thrust_mode must be 'box' or 'norm', got {self.thrust_mode!r}")
        if self.random_start not in RANDOM_STARTS:
            raise SatenvError(f"random_start must be one of {list(RANDOM_STARTS)}, got {self.random_start!r}")
        if self.dynamics not in ("cw", "nonlinear", "j2", "j2_drag"):
            raise ValueError(f"dynamics must be 'cw', 'nonlinear', 'j2' or 'j2_drag', got {self.dynamics!r}")
        for name in ("terminate_on_collision", "terminate_on_disconnect", "randomize",
                     "collision_voids_success"):
            s(self, name, flag(getattr(self, name), name))
        s(self, "obs_neighbours", obs_neighbours(self.obs_neighbours))
        spreads_in_region(self.random_position_spread, self.random_velocity_spread, self.max_distance)
        inputs = f"mean_motion = {self.mean_motion!r}"
        radius = derived(lambda: (MU_EARTH / self.mean_motion**2) ** (1.0 / 3.0),
                         "the reference orbit radius (mu / mean_motion^2)^(1/3)", inputs)
        at_most(R_EARTH, "the Earth's radius [m]", radius,
                f"the reference orbit radius (mu / mean_motion^2)^(1/3) of {inputs}")
        orbit_step(self.mean_motion, self.dt, inputs)
        derived(lambda: self.velocity_scale, "the velocity scale sqrt(length_scale u_max)",
                f"length_scale = {self.length_scale!r}, u_max = {self.u_max!r}")

    # ---- derived quantities ------------------------------------------------------------------
    @property
    def n_agents(self) -> int:
        return len(self.initial_state)

    @property
    def velocity_scale(self) -> float:
        """V = sqrt(L u_max) [m/s], the velocity scale of observations."""
        return math.sqrt(self.length_scale * self.u_max)

    def initial_array(self) -> np.ndarray:
        return np.array(self.initial_state, dtype=float)

    def follows(self) -> np.ndarray:
        """(M,) bool: True for agents that follow the leader (no absolute goal)."""
        return np.array([g is None for g in self.goals])

    def target_positions(self) -> np.ndarray:
        """(M, 3) final positions implied by the goals (followers: leader goal + offset)."""
        out = np.zeros((self.n_agents, 3))
        for i, g in enumerate(self.goals):
            out[i] = g if g is not None else np.asarray(self.goals[self.leader]) + np.asarray(self.offsets[i])
        return out

    def error_weights(self) -> np.ndarray:
        """(M, 3) per-axis weights q of the normalised position error in the cost."""
        w = np.full((self.n_agents, 3), self.position_weight)
        w[self.follows(), 1] = self.offset_weight
        return w

    def formation_error(self, x: np.ndarray) -> np.ndarray:
        """The cost's position errors ``e_i`` (..., M, 3) of states ``x`` (..., M, 6).

        Agents with a goal: ``p_i - goal_i``; followers: ``p_i - p_leader - offset_i``.
        """
        p = np.asarray(x)[..., :3]
        e = p - self.target_positions()
        fol = self.follows()
        if fol.any():
            lead = p[..., self.leader:self.leader + 1, :] - np.asarray(self.goals[self.leader])
            e = np.where(fol[:, None], e - lead, e)
        return e

    def with_overrides(self, **overrides) -> FormationScenario:
        """A copy with fields replaced; unknown names raise ``ValueError``."""
        known = {f.name for f in fields(self)}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ValueError(f"unknown scenario parameter(s) {bad}; valid names: {sorted(known)}")
        return replace(self, **overrides)


_ORIGIN3 = ((0.0,) * 6,) * 3

PRESETS: dict[str, FormationScenario] = {
    "kannan2022-position": FormationScenario(
        name="kannan2022-position",
        initial_state=_ORIGIN3,
        goals=((100.0, 100.0, 100.0), (100.0, 200.0, 100.0), (100.0, 300.0, 100.0)),
    ),
    "kannan2022-collision": FormationScenario(
        name="kannan2022-collision",
        initial_state=_ORIGIN3,
        goals=(None, (100.0, 100.0, 100.0), None),
        leader=1,
        offsets=((0.0, 10.0, 0.0), (0.0, 0.0, 0.0), (0.0, -10.0, 0.0)),
        offset_weight=10.0,
    ),
}


def resolve_scenario(preset: str = "kannan2022-position", **overrides) -> FormationScenario:
    """``PRESETS[preset]`` with ``overrides`` applied (validated)."""
    return from_preset(PRESETS, preset, "formation", overrides)


def proximity_components(positions: np.ndarray, delta: float) -> np.ndarray:
    """Reachability in the proximity graph (link iff distance <= delta), batched.

    ``positions`` (..., M, 3) -> bool (..., M, M), entry ``[i, j]`` True iff j can be reached
    from i (every node reaches itself). The graph is connected iff all entries are True.
    """
    p = np.asarray(positions, dtype=float)
    m = p.shape[-2]
    dist = np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)
    reach = (dist <= delta) | np.eye(m, dtype=bool)
    for _ in range(max(1, math.ceil(math.log2(max(m, 2))))):
        r = reach.astype(np.int64)
        reach = (r @ r) > 0
    return reach


def sample_initial_state(scenario: FormationScenario, rng: np.random.Generator) -> np.ndarray:
    """Draw an initial state (M, 6) from the documented distribution (module docstring)."""
    nominal = scenario.initial_array()
    if scenario.random_start == "target":
        nominal[:, :3] = scenario.target_positions()
    m = scenario.n_agents
    s, v = scenario.random_position_spread, scenario.random_velocity_spread
    iu = np.triu_indices(m, 1)
    for _ in range(1000):
        x = nominal.copy()
        x[:, :3] += rng.uniform(-s, s, size=(m, 3))
        x[:, 3:] += rng.uniform(-v, v, size=(m, 3))
        pos = x[:, :3]
        dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
        if m > 1 and np.min(dist[iu]) < max(scenario.random_min_gap, scenario.collision_distance):
            continue
        if not proximity_components(pos, scenario.connection_range).all():
            continue
        return x
    raise SatenvError("could not draw a connected, well-separated initial state in 1000 tries; "
                       "reduce random_position_spread or random_min_gap, or increase connection_range")
