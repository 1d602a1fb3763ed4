"""Satellite-cluster reconfiguration scenarios (li2022 §4), SI units.

Ten satellites of 50 kg with 1 N thrusters fly relative to a *virtual* reference satellite at the
origin of its LVLH frame (x radial, y along-track, z orbit normal) and must reach target points
spread on a 300 m sphere around a target spacecraft at ``q_r = [-200, -200, -200] m`` while a
space obstacle crosses the cluster on a straight LVLH line from ``[600, 0, 0] m`` at
``[-0.4, 0.4, 0.4] m/s``. Presets: ``"li2022-case1"`` (Table 2, concentrated start) and
``"li2022-case2"`` (Table 3, dispersed start); both start at rest, targets from Table 4.

Choices the paper leaves open (documented here, overridable):

* **Chief orbit.** li2022 gives none; the virtual reference satellite is on a 500 km circular
  orbit inclined 45 deg (``altitude``, ``inclination``), the truth model is J2 + drag
  (``dynamics="j2_drag"``, exponential atmosphere, equal ballistic coefficients).
* **Disturbance units.** §4 writes ``w = w_bar [sin(0.02t + pi/3), sin(0.02t - 2pi/3),
  sin(0.02t + pi/2)]`` with ``w_bar = 0.1``. li2022 adds ``w`` to the "control force" ``u``
  (eq. 4) and requires ``w_bar < sup ||u - f||`` (eq. 7), i.e. ``w`` is measured like ``u``, in
  newtons: we read ``w_bar = 0.1 N`` on a 50 kg satellite, an acceleration of 0.002 m/s^2 (10 %
  of the 0.02 m/s^2 thrust authority). 0.1 m/s^2 is impossible: it is five times what a 1 N
  thruster can give a 50 kg satellite. Each component is bounded by ``w_bar``, so
  ``sup ||w|| = 1.68 w_bar`` (:attr:`ClusterScenario.disturbance_bound`).
* **Safety distances.** Satellites must stay ``2 r_s = 200 m`` apart; eq. (31) keeps a
  satellite ``r_s + r_o = 400 m`` from the obstacle (``r_o = 300 m`` is the obstacle's safety
  radius, added to the satellite's ``r_s``). li2022 gives no size for the target spacecraft (its
  constraint set (36) does not even list it); we keep satellites ``r_s + r_t`` from it with
  ``target_radius = r_t = 0``: the satellite's own 100 m safety radius, the target treated as a
  point. The targets lie 300 m from it. With ``r_t = 100 m`` (a 200 m keep-out) the satellites
  that reach their targets first, 200 m apart on the 300 m sphere, and the keep-out leave no
  passage for the others (only 95 m between the keep-out and the parked ring): in our case-1 run
  the tube RDMPC then left 4 of 10 satellites trapped or looping for the whole 2000 s.
* **Obstacle and target spacecraft** move kinematically in the LVLH frame (straight line at
  constant velocity; fixed), as the paper describes them; they are not propagated with orbital
  dynamics.
* **Decision period and physics step.** ``dt = 5 s`` is the DMPC sampling period Δt; the physics
  (and an inner-loop controller such as the tube controller κ) runs every ``physics_dt``.

Random episodes (``randomize=True``), drawn from the env's seed:

* initial states: every satellite's preset position plus ``U(-s, s)`` per axis
  (``s = random_position_spread``), at rest, redrawn (up to 1000 times) until all safety
  distances hold with a 10 m margin; with ``random_start="slots"`` (for easier tasks) satellite
  ``i`` starts at the episode's target slot ``i`` instead of its preset position (the offsets are
  drawn first, then the slots from a copy of the generator, which the reset then draws again);
* target slots: the T targets are drawn one by one uniformly on the sphere of radius
  ``random_target_radius`` (300 m, as li2022's Table 4 points) around the target spacecraft,
  each redrawn (up to 1000 times) until it is at least ``2 r_s`` + 10 m from the ones before.

Swarms of any size up to ``satenv.scenarios._fields.MAX_AGENTS`` come from :func:`swarm`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from satenv.dynamics import MODELS, R_EARTH, Orbit
from satenv.scenarios import _fields

__all__ = ["ClusterScenario", "PRESETS", "LI2022_TARGETS", "resolve_scenario", "sample_initial_state",
           "sample_targets", "sphere_points", "swarm"]

LI2022_TARGETS: tuple[tuple[float, float, float], ...] = (
    (-189.9, -11.8, -433.5), (-118.7, 85.5, -156.7), (-103.4, -470.2, -112.5),
    (-310.7, -112.9, 64.8), (-16.1, -174.3, 35.5), (-393.8, -403.2, -94.4),
    (-476.1, -83.1, -189.2), (-100.3, -343.3, -443.9), (-394.8, -292.6, -408.4),
    (94.2, -235.2, -247.2),
)
"""li2022 Table 4: target positions in the LVLH frame [m]."""

CASE1_POSITIONS: tuple[tuple[float, float, float], ...] = (
    (946.1, 1025.3, 666.3), (628.1, 973.3, 625.6), (801.3, 501.1, 825.7),
    (525.5, 734.1, 901.6), (981.6, 960.1, 977.1), (803.4, 707.3, 1085.3),
    (669.3, 1028.2, 944.6), (937.3, 727.1, 543.4), (632.3, 656.5, 596.7),
    (1075.9, 687.1, 833.6),
)
"""li2022 Table 2: initial positions of case 1 (concentrated) [m]."""

CASE2_POSITIONS: tuple[tuple[float, float, float], ...] = (
    (490.6, 560.7, 805.9), (856.3, 1070.5, 318.5), (512.7, 969.1, 1501.6),
    (1262.7, 442.7, 667.7), (1033.4, 439.1, 1417.3), (1619.1, 900.2, 1311.2),
    (424.5, 1382.5, 888.1), (1566.1, 1163.7, 622.3), (1112.2, 1682.3, 891.4),
    (1119.9, 1385.1, 1572.2),
)
"""li2022 Table 3: initial positions of case 2 (dispersed) [m]."""

DISTURBANCES = ("sinusoid", "random", "none")
ALLOCATIONS = ("hungarian", "fixed")
RANDOM_STARTS = ("preset", "slots")


def _rows(value: Any, name: str, min_rows: int = 1) -> tuple[tuple[float, float, float], ...]:
    arr = _fields.array(value, name)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < min_rows:
        raise ValueError(f"{name} must be a (K, 3) array with K >= {min_rows} (one [x, y, z] row per "
                         f"point, metres), got shape {arr.shape}")
    return _fields.nested(arr)


def _vec3(value: Any, name: str) -> tuple[float, float, float]:
    return _fields.vector(value, name, 3)


_number = _fields.number


def _integer(value: Any, name: str, minimum: int) -> int:
    return _fields.integer(value, name, minimum=minimum)


def _sinusoid_norm_max() -> float:
    """``sup_t ||[sin(a + pi/3), sin(a - 2pi/3), sin(a + pi/2)]||`` (= 1.6801...)."""
    a = np.linspace(0.0, 2.0 * np.pi, 200_001)
    return float(np.sqrt(np.max(2.0 * np.sin(a + np.pi / 3) ** 2 + np.cos(a) ** 2)))


SINUSOID_NORM_MAX = _sinusoid_norm_max()


@dataclass(frozen=True)
class ClusterScenario:
    """Parameters of a cluster-reconfiguration scenario (frozen, validated; SI units).

    Args:
        name: preset name (informational).
        initial_positions: (M, 3) satellite positions [m] (LVLH, relative to the reference).
        initial_velocities: (M, 3) [m/s]; ``None`` means at rest.
        targets: (T, 3) target points [m], T >= M (li2022 Table 4).
        target_spacecraft: q_r [m], the spacecraft the cluster gathers around.
        obstacle_position, obstacle_velocity: the obstacle's LVLH position at t = 0 [m] and its
            constant LVLH velocity [m/s].
        sat_radius: r_s [m]; satellites must stay 2 r_s apart.
        obstacle_radius: r_o [m]; satellites must stay r_s + r_o from the obstacle (eq. 31).
        target_radius: r_t [m]; satellites must stay r_s + r_t from the target spacecraft.
        comm_range: r_c [m]; n_neighbours: N_a (see :mod:`satenv.cluster_graph`).
        obs_neighbours: ``None`` (default): the observation's neighbour slots are the graph's
            (``min(n_neighbours, M - 1)``); an int ``K``: always ``K`` slots, the ``K`` nearest
            other satellites within ``comm_range``, zero-padded (a layout independent of ``M``;
            ``satenv.envs.cluster_v0``).
        mass: satellite mass [kg].
        u_max: acceleration authority [m/s^2], a bound on the norm of the commanded acceleration
            (li2022: T_max / m = 1 N / 50 kg = 0.02 m/s^2; :attr:`thrust_max` is ``u_max mass``).
        disturbance: ``"sinusoid"`` (li2022 §4), ``"random"`` (uniform in the ball of radius
            ``disturbance_force / mass``, drawn from the env's generator every physics step) or
            ``"none"``; disturbance_force: w_bar [N] (module docstring).
        altitude [m], inclination [rad]: the circular orbit of the virtual reference satellite.
        dynamics: truth model (``satenv.dynamics.MODELS``).
        dt: decision period Δt [s]; physics_dt: physics / inner-loop step [s] (divides dt).
        max_steps: episode length in decisions (truncation).
        allocation: ``"hungarian"`` (li2022 §3.3) or ``"fixed"`` (satellite i -> target i).
        reallocate_every: re-run the allocation every K decisions (0: only at reset).
        terminate_on_collision: a safety-distance violation ends the episode.
        max_distance: the allowed region, a ball around the reference satellite [m].
        randomize: draw initial positions and target slots from the env's seed (module docstring).
        random_position_spread [m], random_target_radius [m]: see the module docstring.
        random_start: where the random starts are centred: ``"preset"`` (default) the preset
            positions, ``"slots"`` the episode's target slots (module docstring).
        reward_distance_scale [m], reward_control_weight, collision_penalty: reward terms
            (``satenv.envs.cluster_v0``).
        success_tol: an episode succeeds when every satellite ends within this distance of its
            allocated target [m] (:func:`satenv.metrics.success`).
        collision_voids_success: a safety-distance violation makes the episode a failure.
    """

    name: str
    initial_positions: tuple[tuple[float, float, float], ...]
    initial_velocities: tuple[tuple[float, float, float], ...] | None = None
    targets: tuple[tuple[float, float, float], ...] = LI2022_TARGETS
    target_spacecraft: tuple[float, float, float] = (-200.0, -200.0, -200.0)
    obstacle_position: tuple[float, float, float] = (600.0, 0.0, 0.0)
    obstacle_velocity: tuple[float, float, float] = (-0.4, 0.4, 0.4)
    sat_radius: float = 100.0
    obstacle_radius: float = 300.0
    target_radius: float = 0.0
    comm_range: float = 1000.0
    n_neighbours: int = 4
    obs_neighbours: int | None = None
    mass: float = 50.0
    u_max: float = 0.02
    disturbance: str = "sinusoid"
    disturbance_force: float = 0.1
    altitude: float = 500e3
    inclination: float = math.radians(45.0)
    dynamics: str = "j2_drag"
    dt: float = 5.0
    physics_dt: float = 0.25
    max_steps: int = 400
    allocation: str = "hungarian"
    reallocate_every: int = 0
    terminate_on_collision: bool = True
    max_distance: float = 10_000.0
    randomize: bool = False
    random_position_spread: float = 50.0
    random_target_radius: float = 300.0
    random_start: str = "preset"
    reward_distance_scale: float = 1000.0
    reward_control_weight: float = 0.01
    collision_penalty: float = 10.0
    success_tol: float = 1.0
    collision_voids_success: bool = True

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}")
        s(self, "initial_positions", _rows(self.initial_positions, "initial_positions"))
        m = len(self.initial_positions)
        if self.initial_velocities is not None:
            vel = _rows(self.initial_velocities, "initial_velocities")
            if len(vel) != m:
                raise ValueError(f"initial_velocities must have {m} rows (one per satellite), got {len(vel)}")
            s(self, "initial_velocities", vel)
        s(self, "targets", _rows(self.targets, "targets"))
        if len(self.targets) < m:
            raise ValueError(f"need at least one target per satellite: {m} satellites, "
                             f"{len(self.targets)} targets")
        for name in ("target_spacecraft", "obstacle_position", "obstacle_velocity"):
            s(self, name, _vec3(getattr(self, name), name))
        for name in ("sat_radius", "comm_range", "mass", "u_max", "dt", "physics_dt",
                     "max_distance", "reward_distance_scale", "random_target_radius", "success_tol"):
            s(self, name, _number(getattr(self, name), name))
        for name in ("obstacle_radius", "target_radius", "disturbance_force", "random_position_spread",
                     "reward_control_weight", "collision_penalty", "inclination"):
            s(self, name, _number(getattr(self, name), name, allow_zero=True))
        if self.inclination > math.pi:
            raise ValueError(f"inclination must be in [0, pi] rad, got {self.inclination!r} "
                             "(use math.radians for degrees)")
        s(self, "altitude", _number(self.altitude, "altitude (m above R_EARTH)"))
        s(self, "n_neighbours", _integer(self.n_neighbours, "n_neighbours", 0))
        s(self, "obs_neighbours", _fields.obs_neighbours(self.obs_neighbours))
        s(self, "max_steps", _fields.steps(self.max_steps, "max_steps"))
        s(self, "reallocate_every", _integer(self.reallocate_every, "reallocate_every", 0))
        ratio = _fields.derived(lambda: self.dt / self.physics_dt, "the physics steps per decision "
                                "dt / physics_dt", f"dt = {self.dt!r}, physics_dt = {self.physics_dt!r}")
        if ratio > _fields.MAX_SUBSTEPS + 0.5:
            raise _fields.SatenvError(
                f"dt / physics_dt = {ratio:.6g} physics steps per decision exceeds the cap "
                f"MAX_SUBSTEPS = {_fields.MAX_SUBSTEPS} (one env step would take too long); "
                f"raise physics_dt or lower dt (dt = {self.dt!r} s, physics_dt = {self.physics_dt!r} s)")
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(f"physics_dt must divide dt: dt = {self.dt} s, physics_dt = "
                             f"{self.physics_dt} s gives {ratio:.6g} physics steps per decision")
        if self.dynamics not in MODELS:
            raise ValueError(f"dynamics must be one of {list(MODELS)}, got {self.dynamics!r}")
        if self.disturbance not in DISTURBANCES:
            raise ValueError(f"disturbance must be one of {list(DISTURBANCES)}, got {self.disturbance!r}")
        if self.random_start not in RANDOM_STARTS:
            raise _fields.SatenvError(f"random_start must be one of {list(RANDOM_STARTS)}, got {self.random_start!r}")
        if self.allocation not in ALLOCATIONS:
            raise ValueError(f"allocation must be one of {list(ALLOCATIONS)}, got {self.allocation!r}")
        for name in ("terminate_on_collision", "randomize", "collision_voids_success"):
            s(self, name, _fields.flag(getattr(self, name), name))
        _fields.states_in_region(self.initial_array(), "initial_positions / initial_velocities",
                                 self.max_distance)
        _fields.at_most(self.random_position_spread, "random_position_spread", self.max_distance,
                        "max_distance")
        for name in ("target_spacecraft", "obstacle_position"):
            _fields.at_most(float(np.linalg.norm(getattr(self, name))), f"|{name}| [m]",
                            self.max_distance, "max_distance")
        _fields.at_most(float(np.abs(self.targets_array()).max()), "the largest targets coordinate [m]",
                        self.max_distance, "max_distance")
        _fields.at_most(float(np.linalg.norm(self.obstacle_velocity)), "|obstacle_velocity| [m/s]",
                        _fields.MAX_RELATIVE_SPEED, "MAX_RELATIVE_SPEED")
        _fields.derived(lambda: self.thrust_max, "the thrust authority u_max * mass",
                        f"u_max = {self.u_max!r}, mass = {self.mass!r}")
        _fields.orbit_step(_fields.derived(lambda: self.orbit.n, "the mean motion of the reference orbit",
                                           f"altitude = {self.altitude!r}"), self.dt,
                           f"altitude = {self.altitude!r}")

    # ---- what SatParallelEnv needs -------------------------------------------------------------
    @property
    def n_agents(self) -> int:
        return len(self.initial_positions)

    @property
    def thrust_max(self) -> float:
        """Thrust authority ``T_max = u_max mass`` [N] (a bound on the thrust norm)."""
        return self.u_max * self.mass

    @property
    def thrust_mode(self) -> str:
        return "norm"

    # ---- derived quantities ------------------------------------------------------------------
    @property
    def substeps(self) -> int:
        """Physics steps per decision ``dt / physics_dt``."""
        return int(round(self.dt / self.physics_dt))

    @property
    def orbit(self) -> Orbit:
        """The circular orbit of the virtual reference satellite (the LVLH origin)."""
        return Orbit.circular(R_EARTH + self.altitude, i=self.inclination)

    @property
    def disturbance_amplitude(self) -> float:
        """w_bar as an acceleration ``disturbance_force / mass`` [m/s^2] (0 without disturbance)."""
        return 0.0 if self.disturbance == "none" else self.disturbance_force / self.mass

    @property
    def disturbance_bound(self) -> float:
        """``sup ||w||`` [m/s^2]: 1.68 w_bar for the sinusoid (componentwise amplitude), w_bar
        for the random ball, 0 without disturbance."""
        amp = self.disturbance_amplitude
        return amp * SINUSOID_NORM_MAX if self.disturbance == "sinusoid" else amp

    @property
    def pair_distance(self) -> float:
        """Minimum satellite-satellite distance ``2 r_s`` [m]."""
        return 2.0 * self.sat_radius

    @property
    def obstacle_distance(self) -> float:
        """Minimum satellite-obstacle distance ``r_s + r_o`` [m] (eq. 31)."""
        return self.sat_radius + self.obstacle_radius

    @property
    def target_distance(self) -> float:
        """Minimum satellite-target-spacecraft distance ``r_s + r_t`` [m]."""
        return self.sat_radius + self.target_radius

    def initial_array(self) -> np.ndarray:
        """Initial states (M, 6) [m, m/s]."""
        x = np.zeros((self.n_agents, 6))
        x[:, :3] = self.initial_positions
        if self.initial_velocities is not None:
            x[:, 3:] = self.initial_velocities
        return x

    def targets_array(self) -> np.ndarray:
        return np.array(self.targets, dtype=float)

    def obstacle_at(self, t) -> np.ndarray:
        """Obstacle position(s) at time(s) ``t`` [s]: ``(*t.shape, 3)``."""
        t = np.asarray(t, dtype=float)
        return np.asarray(self.obstacle_position) + t[..., None] * np.asarray(self.obstacle_velocity)

    def with_overrides(self, **overrides) -> ClusterScenario:
        """A validated copy with fields replaced; unknown names raise ``ValueError``."""
        known = {f.name for f in fields(self)}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ValueError(f"unknown cluster scenario parameter(s) {bad}; valid names: {sorted(known)}")
        if "initial_positions" in overrides and "initial_velocities" not in overrides:
            positions = overrides["initial_positions"]
            n_new = np.shape(positions)[0] if np.ndim(positions) == 2 else None
            if self.initial_velocities is not None and n_new != self.n_agents:
                overrides["initial_velocities"] = None
        return replace(self, **overrides)


PRESETS: dict[str, ClusterScenario] = {
    "li2022-case1": ClusterScenario(name="li2022-case1", initial_positions=CASE1_POSITIONS),
    "li2022-case2": ClusterScenario(name="li2022-case2", initial_positions=CASE2_POSITIONS),
}
"""li2022 §4.1: case 1 (Table 2) and case 2 (Table 3)."""

DEFAULT_PRESET = "li2022-case1"


def sphere_points(n: int, radius: float, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    """``n`` nearly evenly spread points ``(n, 3)`` on a sphere (the Fibonacci lattice: neighbours
    about ``3.4 radius / sqrt(n)`` apart)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - math.sqrt(5.0)) * k
    return np.asarray(centre, dtype=float) + radius * np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


SWARM_COVERAGE = 0.3
"""Largest share of the target sphere covered by the random slots' 2 r_s + 10 m exclusion discs
in :func:`swarm` (the sequential draw of :func:`sample_targets` succeeds easily below it)."""


def swarm(n: int, *, gap: float = 1200.0, spread: float = 50.0, **overrides: Any) -> dict[str, Any]:
    """Keyword arguments of ``cluster_v0`` for a swarm of ``n`` satellites (``1 <= n <= 1024``).

    The ``"li2022-case1"`` preset's physics (satellites, obstacle, target spacecraft,
    disturbance, J2 + drag) with ``n`` satellites and ``n`` target slots, allocated with the
    Hungarian algorithm at reset:

    * target slots on a sphere around the target spacecraft whose radius grows with ``n`` so that
      the slots' exclusion discs cover at most :data:`SWARM_COVERAGE` of it (300 m, li2022's,
      up to 9 satellites; 3.07 km for 1024); evenly spread (:func:`sphere_points`) without
      ``randomize``, drawn at random on every reset with it;
    * starts evenly spread on the concentric sphere ``gap`` metres farther out (outside the
      obstacle's keep-out at t = 0), each moved by ``U(-spread, spread)`` per axis on every
      reset (``randomize=True``), at rest.

    ``overrides`` replace any of these (any scenario field, e.g. ``dynamics="cw"``,
    ``randomize=False``). The APF and tube-RDMPC baselines run on it unchanged.

    >>> env = satenv.make("cluster_v0", **swarm(256))
    """
    n = _fields.integer(n, "swarm size n", maximum=_fields.MAX_AGENTS, why="MAX_AGENTS")
    base = PRESETS[DEFAULT_PRESET]
    centre = np.asarray(base.target_spacecraft)
    slot = base.pair_distance + 10.0                       # sample_targets' smallest slot gap
    radius = max(base.random_target_radius, 0.25 * slot * math.sqrt(n / SWARM_COVERAGE))
    kwargs = {"preset": DEFAULT_PRESET,
              "initial_positions": _fields.nested(sphere_points(n, radius + float(gap), centre)),
              "targets": _fields.nested(sphere_points(n, radius, centre)),
              "random_target_radius": radius, "random_position_spread": float(spread),
              "randomize": True}
    return {**kwargs, **overrides}


def resolve_scenario(preset: str = DEFAULT_PRESET, **overrides) -> ClusterScenario:
    """``PRESETS[preset]`` with ``overrides`` applied (validated)."""
    return _fields.from_preset(PRESETS, preset, "cluster", overrides)


def safety_ok(scenario: ClusterScenario, positions: np.ndarray, t: float = 0.0, margin: float = 0.0) -> bool:
    """True when ``positions`` (M, 3) satisfy every safety distance at time ``t`` (+ ``margin``)."""
    p = np.asarray(positions, dtype=float)
    m = p.shape[0]
    if m > 1:
        d = np.linalg.norm(p[:, None] - p[None], axis=-1)[np.triu_indices(m, 1)]
        if np.any(d < scenario.pair_distance + margin):
            return False
    if np.any(np.linalg.norm(p - scenario.obstacle_at(t), axis=-1) < scenario.obstacle_distance + margin):
        return False
    return not np.any(np.linalg.norm(p - np.asarray(scenario.target_spacecraft), axis=-1)
                      < scenario.target_distance + margin)


def sample_initial_state(scenario: ClusterScenario, rng: np.random.Generator) -> np.ndarray:
    """Initial states (M, 6): the preset's, or with ``randomize`` a random draw (module docstring)."""
    x = scenario.initial_array()
    s = scenario.random_position_spread
    slots = scenario.random_start == "slots"
    if not scenario.randomize or (s == 0.0 and not slots):
        return x
    if slots:
        x[:, 3:] = 0.0   # at rest around the slots
    for _ in range(1000):
        pos = rng.uniform(-s, s, size=(scenario.n_agents, 3))
        if slots:       # the slots the reset will draw next from ``rng``
            pos += sample_targets(scenario, copy.deepcopy(rng))[: scenario.n_agents]
        else:
            pos += x[:, :3]
        if safety_ok(scenario, pos, 0.0, margin=10.0):
            out = x.copy()
            out[:, :3] = pos
            return out
    raise _fields.SatenvError("could not draw initial positions satisfying the safety distances in 1000 "
                       f"tries with random_position_spread = {s} m; reduce the spread")


def sample_targets(scenario: ClusterScenario, rng: np.random.Generator) -> np.ndarray:
    """Target slots (T, 3) [m]: the scenario's, or with ``randomize`` a random draw (module docstring)."""
    targets = scenario.targets_array()
    if not scenario.randomize:
        return targets
    centre, radius = np.asarray(scenario.target_spacecraft), scenario.random_target_radius
    min_gap = scenario.pair_distance + 10.0
    for k in range(len(targets)):
        for _ in range(1000):
            d = rng.normal(size=3)
            point = centre + radius * d / np.linalg.norm(d)
            if np.all(np.linalg.norm(targets[:k] - point, axis=-1) >= min_gap):
                targets[k] = point
                break
        else:
            raise _fields.SatenvError(f"could not place {len(targets)} target slots {min_gap} m apart on a "
                               f"{radius} m sphere in 1000 tries; increase random_target_radius")
    return targets
