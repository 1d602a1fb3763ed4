"""On-orbit servicing scenarios (pereira2022 §4, §5.2), SI units.

M spacecraft move around a passive object at the origin of the LVLH frame (x radial, y
along-track, z orbit normal) and point their body z axis at it. Per-agent state (eq. 35):
``[p (3), v (3), q (4), omega (3)]`` — LVLH position/velocity [m, m/s], the unit quaternion
(scalar first) of the body frame relative to the object frame (= LVLH, §4) and the relative
angular velocity in the body frame [rad/s]. Six inputs per agent (eq. 36).

Waypoints (eq. 50): ``waypoints[k]`` (M, 3) is the target of phase k; phase k holds for
``waypoint_times[k-1] < t <= waypoint_times[k]`` (``t = step * dt``).

Random initial states (``randomize=True``): each spacecraft's position is drawn uniformly on the
spherical shell ``keepout + [random_min_gap, random_min_gap + random_shell]`` around the object,
its direction uniform on the sphere, or, when ``random_cone < pi``, uniform on the cap of half-angle
``random_cone`` [rad] around the direction of the spacecraft's first waypoint (starts near the first
target, for easier tasks), velocity ``U(-v, v)`` per axis (``v = random_velocity_spread``), a
uniformly random attitude and ``omega ~ U(-w, w)`` (``w = random_angular_spread``); draws are
rejected until every pair is at least ``r_i + r_j + random_min_gap`` apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from satenv.dynamics import MU_EARTH
from satenv.dynamics.constants import R_EARTH
from satenv.scenarios import _fields
from satenv.scenarios._fields import (
    MAX_SUBSTEPS,
    SatenvError,
    array,
    derived,
    flag,
    from_preset,
    integer,
    nested,
    number,
    states_in_region,
    steps,
)

__all__ = ["PRESETS", "ServicingScenario", "resolve_scenario", "sample_initial_state"]


@dataclass(frozen=True)
class ServicingScenario:
    """Parameters of a servicing scenario (frozen, validated; SI units).

    Args:
        name: preset name (informational).
        initial_position, initial_velocity: (M, 3) LVLH [m, m/s].
        initial_quaternion: (M, 4) scalar-first; normalised on construction (the paper's
            q(0) = [0.37, -0.43, 0.66, 0.47] has norm 0.989).
        initial_angular_velocity: (M, 3) relative angular velocity in the body frame [rad/s].
        waypoints: (P, M, 3) desired positions per phase; waypoint_times: (P-1,) switch times [s].
        desired_velocity: v_d (3,) [m/s] (eq. 39).
        inertia, object_inertia: J_f, J_l (3, 3) [kg m^2] (symmetric positive definite).
        dimensions: [L_x, L_y, L_z] [m] of the thruster layout (eq. 36).
        u_max: per-input bounds ``|u_i| <= u_max_i`` (eq. 36 inputs; the paper's u_max): six
            numbers, or one for all six; ``F_t u`` is an acceleration [m/s^2] and ``F_r u`` a torque
            [N m] (per unit mass, m_f = 1 kg as in eq. 35-36). Stored as a 6-tuple.
        v_max, omega_max: per-axis velocity [m/s] and angular-velocity [rad/s] limits (eq. 42).
        object_radius: r_sigma [m]; spacecraft_radius: r_s = r_i [m] (eq. 40-41).
        pointing_target: t (3,) the LVLH point every spacecraft points at (eq. 43).
        pointing_reference: the auxiliary direction ``a`` fixing the roll about the pointing axis,
            ``j_d = k_d x a`` (see :func:`satenv.dynamics.attitude.pointing_frame`); eq. 44's
            ``a = p`` is degenerate for a target at the object's centre.
        thrust_frame: ``"lvlh"`` — eq. 35 as written, the force ``F_t u`` acts along the LVLH
            axes; ``"body"`` — the thrusters are body-fixed, force ``R(q) F_t u``.
        orbit_radius: ||r_l|| [m] (circular orbit); mu [m^3/s^2].
        dynamics: translational truth model from ``satenv.dynamics``: ``"nonlinear"`` (eq. 4-5,
            default), ``"cw"``, ``"j2"``.
        dt: sampling time T_s [s]; max_steps: episode length (truncation).
        substeps: integration substeps per dt (attitude RK4 and, for ``"body"``, the translation).
        position_weight, velocity_weight, quaternion_weight, omega_weight, input_weight: the
            diagonals of Q_p, Q_v, Q_q, Q_w, H of eq. 39 (the env's reward; the NMPC minimises the
            same cost, its horizon N is ``satenv.baselines.nmpc.NMPCConfig.horizon``).
        max_distance: an episode terminates when a spacecraft is farther than this [m].
        contact_tolerance: distances within this of a limit still count as satisfying eq. 40 /
            41 [m] (float round-off: the §5.2 initial positions and waypoints lie exactly on the
            keep-out sphere |p| = r_sigma + r_s).
        terminate_on_collision: end the episode at a collision (eq. 40 / 41 violated).
        reward_scale, collision_penalty, violation_penalty: reward shaping (env docstring).
        thrust_mode: ``"box"`` (per-input limit; the only mode of this env).
        randomize, random_min_gap, random_shell, random_cone, random_velocity_spread, random_angular_spread:
            random initial states (module docstring); ``random_cone`` in ``(0, pi]`` [rad], ``pi`` (the
            default) draws the start directions on the whole sphere.
        success_tol: an episode succeeds when every spacecraft ends within this distance of its
            final waypoint [m] (:func:`satenv.metrics.success`).
        collision_voids_success: a collision flag makes the episode a failure.
    """

    name: str
    initial_position: Any
    initial_velocity: Any
    initial_quaternion: Any
    initial_angular_velocity: Any
    waypoints: Any
    waypoint_times: Any
    desired_velocity: Any = (0.0, 0.0, 0.0)
    inertia: Any = ((10.0, 2.5, 3.5), (2.5, 10.0, 4.5), (3.5, 4.5, 10.0))
    object_inertia: Any = ((10.0, 0.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 10.0))
    dimensions: Any = (2.0, 2.0, 2.0)
    u_max: Any = 3.0
    v_max: float = 5.0
    omega_max: float = 0.7
    object_radius: float = 12.0
    spacecraft_radius: float = 3.0
    pointing_target: Any = (0.0, 0.0, 0.0)
    pointing_reference: Any = (1.0, 1.0, 1.0)
    thrust_frame: str = "lvlh"
    orbit_radius: float = 6_621_000.0
    mu: float = MU_EARTH
    dynamics: str = "nonlinear"
    dt: float = 0.1
    max_steps: int = 1200
    substeps: int = 1
    position_weight: Any = (10.0, 10.0, 10.0)
    velocity_weight: Any = (0.5, 0.5, 0.5)
    quaternion_weight: Any = (15.0, 15.0, 15.0, 15.0)
    omega_weight: Any = (0.5, 0.5, 0.5)
    input_weight: Any = (2.0,) * 6
    max_distance: float = 100.0
    contact_tolerance: float = 1e-6
    terminate_on_collision: bool = True
    reward_scale: float = 1.0e3
    collision_penalty: float = 10.0
    violation_penalty: float = 1.0
    thrust_mode: str = "box"
    randomize: bool = False
    random_min_gap: float = 1.0
    random_shell: float = 10.0
    random_cone: float = math.pi
    random_velocity_spread: float = 0.5
    random_angular_spread: float = 0.05
    success_tol: float = 0.5
    collision_voids_success: bool = True

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}")
        p0 = array(self.initial_position, "initial_position", ndim=2)
        m = p0.shape[0]
        if p0.shape != (m, 3) or m < 1:
            raise ValueError(f"initial_position must have shape (M, 3), got {p0.shape}")
        s(self, "initial_position", nested(p0))
        s(self, "initial_velocity", nested(array(self.initial_velocity, "initial_velocity", (m, 3))))
        q0 = array(self.initial_quaternion, "initial_quaternion", (m, 4))
        qn = np.linalg.norm(q0, axis=1, keepdims=True)
        if np.any(qn < 1e-6):
            raise ValueError("initial_quaternion rows must be non-zero [eta, ex, ey, ez], got "
                             f"{q0.tolist()}")
        s(self, "initial_quaternion", nested(q0 / qn))
        s(self, "initial_angular_velocity",
          nested(array(self.initial_angular_velocity, "initial_angular_velocity", (m, 3))))
        wp = array(self.waypoints, "waypoints", ndim=3)
        if wp.shape[1:] != (m, 3) or wp.shape[0] < 1:
            raise ValueError(f"waypoints must have shape (P, M, 3) = (P, {m}, 3), got {wp.shape}")
        s(self, "waypoints", nested(wp))
        wt = array(self.waypoint_times, "waypoint_times").ravel()
        if wt.shape != (wp.shape[0] - 1,) or np.any(np.diff(wt) <= 0) or np.any(wt <= 0):
            raise ValueError(f"waypoint_times must be {wp.shape[0] - 1} increasing positive times "
                             f"(one per phase change), got {wt.tolist()}")
        s(self, "waypoint_times", tuple(float(v) for v in wt))
        s(self, "desired_velocity", nested(array(self.desired_velocity, "desired_velocity", (3,))))
        for name in ("inertia", "object_inertia"):
            j = array(getattr(self, name), name, (3, 3))
            if not np.allclose(j, j.T) or np.min(np.linalg.eigvalsh(0.5 * (j + j.T))) <= 0:
                raise ValueError(f"{name} must be symmetric positive definite, got {j.tolist()}")
            s(self, name, nested(j))
        dims = array(self.dimensions, "dimensions", (3,))
        if np.any(dims <= 0):
            raise ValueError(f"dimensions [L_x, L_y, L_z] must be > 0, got {dims.tolist()}")
        s(self, "dimensions", nested(dims))
        u_max = array(self.u_max, "u_max").ravel()
        if u_max.size == 1:
            u_max = np.full(6, u_max[0])
        if u_max.shape != (6,) or np.any(u_max <= 0):
            raise ValueError(f"u_max must be one or six positive per-input limits, got {self.u_max!r}")
        s(self, "u_max", nested(u_max))
        for name in ("v_max", "omega_max", "object_radius", "spacecraft_radius", "success_tol",
                     "orbit_radius", "mu", "dt", "max_distance", "reward_scale", "random_shell"):
            s(self, name, number(getattr(self, name), name))
        for name in ("collision_penalty", "violation_penalty", "random_min_gap", "contact_tolerance",
                     "random_velocity_spread", "random_angular_spread"):
            s(self, name, number(getattr(self, name), name, allow_zero=True))
        s(self, "pointing_target", nested(array(self.pointing_target, "pointing_target", (3,))))
        ref = array(self.pointing_reference, "pointing_reference", (3,))
        if np.linalg.norm(ref) < 1e-9:
            raise ValueError("pointing_reference must be a non-zero direction, got [0, 0, 0]")
        s(self, "pointing_reference", nested(ref / np.linalg.norm(ref)))
        if self.thrust_frame not in ("lvlh", "body"):
            raise ValueError(f"thrust_frame must be 'lvlh' (eq. 35) or 'body', got {self.thrust_frame!r}")
        if self.dynamics not in ("cw", "nonlinear", "j2", "j2_drag"):
            raise ValueError(f"dynamics must be 'cw', 'nonlinear', 'j2' or 'j2_drag', got {self.dynamics!r}")
        if self.thrust_mode != "box":
            raise ValueError(f"thrust_mode must be 'box' (per-input limits, eq. 36), got {self.thrust_mode!r}")
        s(self, "max_steps", steps(self.max_steps, "max_steps"))
        s(self, "substeps", integer(self.substeps, "substeps", maximum=MAX_SUBSTEPS,
                                    why="the cap on integration substeps per env step, MAX_SUBSTEPS"))
        for name, n in (("position_weight", 3), ("velocity_weight", 3), ("quaternion_weight", 4),
                        ("omega_weight", 3), ("input_weight", 6)):
            w = array(getattr(self, name), name).ravel()
            if w.size == 1:
                w = np.full(n, float(w[0]))
            if w.shape != (n,) or np.any(w < 0):
                raise ValueError(f"{name} must be {n} non-negative diagonal entries (or one scalar), "
                                 f"got {getattr(self, name)!r}")
            s(self, name, nested(w))
        if min(self.input_weight) <= 0:
            raise ValueError(f"input_weight must be > 0 (H positive definite), got {self.input_weight}")
        for name in ("terminate_on_collision", "randomize", "collision_voids_success"):
            s(self, name, flag(getattr(self, name), name))
        states_in_region(self.initial_array()[:, :6], "initial_position / initial_velocity",
                         self.max_distance)
        cone = number(self.random_cone, "random_cone")
        if cone > math.pi:
            raise SatenvError(f"random_cone must be a half-angle in (0, pi] rad (pi: the whole sphere), got {cone!r}")
        s(self, "random_cone", cone)
        if cone < math.pi and np.any(np.linalg.norm(wp[0], axis=1) < 1e-9):
            raise SatenvError(f"random_cone = {cone!r} < pi draws starts around the first waypoints' directions, "
                              f"which must be non-zero, got waypoints[0] = {wp[0].tolist()}")
        _fields.spreads_in_region(self.random_shell, self.random_velocity_spread, self.max_distance,
                                  position_name="random_shell")
        _fields.at_most(R_EARTH, "the Earth's radius [m]", self.orbit_radius, "orbit_radius")
        inputs = f"mu = {self.mu!r}, orbit_radius = {self.orbit_radius!r}"
        _fields.orbit_step(derived(lambda: self.mean_motion, "the mean motion sqrt(mu / orbit_radius^3)",
                                   inputs), self.dt, inputs)
        keep = self.keepout_radius
        d0 = np.linalg.norm(p0, axis=1)
        if np.any(d0 < keep):
            raise ValueError(f"initial positions must satisfy |p| >= r_sigma + r_s = object_radius + "
                             f"spacecraft_radius = {keep} m (eq. 40), "
                             f"got distances {d0.tolist()}")

    # ---- derived quantities ---------------------------------------------------------------
    @property
    def n_agents(self) -> int:
        return len(self.initial_position)

    @property
    def keepout_radius(self) -> float:
        """r_sigma + r_s [m] (eq. 40)."""
        return self.object_radius + self.spacecraft_radius

    @property
    def separation_radius(self) -> float:
        """r_i + r_j [m] (eq. 41; every spacecraft has radius r_s)."""
        return 2.0 * self.spacecraft_radius

    @property
    def mean_motion(self) -> float:
        """n = sqrt(mu / ||r_l||^3) [rad/s] (eq. 6)."""
        return math.sqrt(self.mu / self.orbit_radius**3)

    @property
    def switch_steps(self) -> np.ndarray:
        """Steps k at which phase changes: phase(k) = #{s : k > switch_steps[s]}."""
        ratio = np.asarray(self.waypoint_times) / self.dt
        near = np.abs(ratio - np.round(ratio)) < 1e-6
        return np.where(near, np.round(ratio), np.floor(ratio)).astype(np.int64)

    def phase(self, step) -> np.ndarray:
        """Waypoint phase index at integer step(s) ``step`` (eq. 50: ``t <= 40`` is phase 0)."""
        return np.sum(np.asarray(step)[..., None] > self.switch_steps, axis=-1)

    def waypoint_array(self) -> np.ndarray:
        return np.array(self.waypoints, dtype=float)

    def initial_array(self) -> np.ndarray:
        """The preset's initial state (M, 13) ``[p, v, q, omega]``."""
        return np.concatenate([np.array(self.initial_position), np.array(self.initial_velocity),
                               np.array(self.initial_quaternion),
                               np.array(self.initial_angular_velocity)], axis=1)

    def with_overrides(self, **overrides) -> ServicingScenario:
        """A copy with fields replaced (validated); unknown names raise ``ValueError``."""
        known = {f.name for f in fields(self) if f.init}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ValueError(f"unknown scenario parameter(s) {bad}; valid names: {sorted(known)}")
        return replace(self, **overrides)


PRESETS: dict[str, ServicingScenario] = {
    # pereira2022 §5.2. Not in the paper (our choices): the episode length (120 s, three 40 s
    # phases), the thruster frame ("lvlh": eq. 35 as written), the roll reference of the
    # pointing frame (eq. 44 is degenerate for a target at the object's centre), and q(0)
    # normalised (the printed q(0) has norm 0.989). q(0) and omega(0) are shared by both.
    "pereira2022": ServicingScenario(
        name="pereira2022",
        initial_position=((0.0, -15.0, 0.0), (0.0, 0.0, -15.0)),
        initial_velocity=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
        initial_quaternion=((0.37, -0.43, 0.66, 0.47), (0.37, -0.43, 0.66, 0.47)),
        initial_angular_velocity=((0.01, -0.02, 0.01), (0.01, -0.02, 0.01)),
        waypoints=(((0.0, 15.0, 0.0), (0.0, 0.0, 15.0)),
                   ((0.0, 0.0, 15.0), (15.0, 0.0, 0.0)),
                   ((0.0, 15.0, 0.0), (0.0, -15.0, 0.0))),
        waypoint_times=(40.0, 80.0),
    ),
}
# For RL from scratch (not in the paper): the paper's starts sit on the 15 m keep-out sphere, so an
# episode under zero or random thrust ends at a contact within about 4 steps; here each start is
# 5 m farther out (20 m: random thrust then flies 130-380 steps, seeds 0-4). Everything else is
# pereira2022's.
PRESETS["pereira2022-rl"] = replace(PRESETS["pereira2022"], name="pereira2022-rl",
                                    initial_position=((0.0, -20.0, 0.0), (0.0, 0.0, -20.0)))


def resolve_scenario(preset: str = "pereira2022", **overrides) -> ServicingScenario:
    """``PRESETS[preset]`` with ``overrides`` applied (validated)."""
    return from_preset(PRESETS, preset, "servicing", overrides)


def _start_directions(scenario: ServicingScenario, rng: np.random.Generator) -> np.ndarray:
    """(M, 3) unit start directions: uniform on the sphere, or on the cap of half-angle
    ``random_cone`` around each spacecraft's first waypoint direction (module docstring)."""
    m = scenario.n_agents
    if scenario.random_cone >= math.pi:
        d = rng.normal(size=(m, 3))
        return d / np.linalg.norm(d, axis=1, keepdims=True)
    axis = np.array(scenario.waypoints[0], dtype=float)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    cos_t = rng.uniform(math.cos(scenario.random_cone), 1.0, size=m)      # uniform on the cap's area
    phi = rng.uniform(0.0, 2.0 * math.pi, size=m)
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    return (cos_t[:, None] * axis + (sin_t * np.cos(phi))[:, None] * e1 + (sin_t * np.sin(phi))[:, None] * e2)


def sample_initial_state(scenario: ServicingScenario, rng: np.random.Generator) -> np.ndarray:
    """Draw an initial state (M, 13) from the documented distribution (module docstring)."""
    m = scenario.n_agents
    r0 = scenario.keepout_radius + scenario.random_min_gap
    min_sep = scenario.separation_radius + scenario.random_min_gap
    for _ in range(1000):
        d = _start_directions(scenario, rng)
        p = d * rng.uniform(r0, r0 + scenario.random_shell, size=(m, 1))
        if m > 1:
            dist = np.linalg.norm(p[:, None] - p[None], axis=-1)
            if np.any(dist[np.triu_indices(m, 1)] < min_sep):
                continue
        v = rng.uniform(-1, 1, size=(m, 3)) * scenario.random_velocity_spread
        q = rng.normal(size=(m, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        q *= np.where(q[:, :1] < 0, -1.0, 1.0)
        w = rng.uniform(-1, 1, size=(m, 3)) * scenario.random_angular_spread
        return np.concatenate([p, v, q, w], axis=1)
    raise SatenvError("could not draw a collision-free initial state in 1000 tries; "
                       "increase random_shell or reduce random_min_gap")
