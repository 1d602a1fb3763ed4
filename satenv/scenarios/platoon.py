"""Leader–follower platoon scenarios (pereira2023 Table I; pereira2022 §5.1), SI units.

All states are LVLH states of the followers relative to the passive leader at the origin:
``[x, y, z, vx, vy, vz]`` with x radial, y along-track, z orbit normal.

Formation targets (``formation``):

* ``"neighbourhood"`` (pereira2023 eq. 15): follower f drives its neighbourhood error
  ``E_f = sum_{i in N_f}(x_f - x_i) + g_f x_f`` to ``(g_f + d_f) E_d``; the resulting
  formation depends on the topology (``Topology.desired_states``).
* ``"chain"`` (pereira2022 §3): follower f holds ``x_f - x_{f-1} = E_d`` (leader = follower 0),
  i.e. ``x_f* = f E_d``.
* ``"ring"`` (swarms): the followers equally spaced on a circle around the leader in the
  along-track / cross-track plane, ``|E_d|`` (position part) apart: radius
  ``R = |E_d| / (2 sin(pi / N))``, follower f at angle ``2 pi (f - 1) / N`` from the -y axis, at rest.
  Its graph is usually ``topology="RING"``.

Swarms of any size up to ``satenv.scenarios._fields.MAX_AGENTS`` come from :func:`swarm`.

Random initial states (``randomize=True`` in the env, :func:`sample_initial_state`): each
follower's position is the preset's nominal position plus ``U(-s, s)`` per axis with
``s = random_position_spread`` [m]; its velocity is ``U(-v, v)`` per axis with
``v = random_velocity_spread`` [m/s]. Draws are rejected (up to 1000 times) until every pair of
bodies (leader included) is at least ``2 r_f + random_min_gap`` apart and, for scenarios with a
line-of-sight cone / keep-out sphere, every chaser starts strictly inside the cone and outside
the sphere (so the pereira2022 controller starts feasible).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from satenv.dynamics.constants import R_EARTH
from satenv.graph import make_topology
from satenv.neighbours import nearest
from satenv.scenarios._fields import (
    SatenvError,
    at_most,
    derived,
    flag,
    from_preset,
    number,
    orbit_step,
    spreads_in_region,
    states_in_region,
    steps,
    vector,
)

__all__ = ["PlatoonScenario", "PRESETS", "resolve_scenario", "ring_states", "sample_initial_state", "swarm"]

MU_TABLE1 = 3.98600441e14  # pereira2023 Table I value of mu [m^3/s^2]


@dataclass(frozen=True)
class PlatoonScenario:
    """Parameters of a platoon scenario (frozen, validated; SI units).

    Args:
        name: preset name (informational).
        initial_state: (N, 6) follower states relative to the leader, LVLH [m, m/s].
        desired_error: E_d (6,) — pereira2023 desired neighbourhood error, or (``chain``)
            the desired state of each follower relative to its predecessor.
        formation: ``"neighbourhood"`` or ``"chain"`` (module docstring).
        topology: ``"PLF"``, ``"BDL"``, ``"TPLF"`` or an (N, N) 0/1 adjacency (i hears j).
        mu: gravitational parameter [m^3/s^2]; orbit_radius: ||r_l|| [m] (circular leader).
        dt: sampling time T_s [s]; max_steps: episode length n_k (truncation).
        state_weight: diagonal of Q (6,); input_weight: diagonal of W (3,); alpha: per-follower
            cost weights (N,) — the stage cost of eq. 14 (the env's reward; the DMPC minimises
            it too). The controller's own settings (horizon N, terminal weight P, Jacobi
            tolerance sigma, variant, convex weights, iterations) are
            ``satenv.baselines.dmpc.DMPCConfig``.
        u_max: per-axis acceleration limit [m/s^2]; v_max: velocity limit [m/s].
        follower_radius: r_f [m]; leader_radius [m] (collision when distance < r_i + r_j).
        min_error_constraint: the minimum-tracking-error constraint (41) is part of the task
            (counted in ``violations``; the DMPC adds its linearisation (42)).
        keepout_radius: r_delta [m] of the keep-out sphere centred at keepout_center in each
            target-chaser frame (pereira2022 eq. 31); 0 disables.
        los_slopes: (c_x, c_z) of the LOS cone (eq. 34), port: (x_rho, y_rho, z_rho) [m];
            ``los_slopes=None`` disables the cone.
        dynamics: truth model for the env: ``"cw"``, ``"nonlinear"``, ``"j2"``, ``"j2_drag"``.
        inclination: leader orbit inclination [rad] (matters for ``"j2"`` only; the papers do
            not give one, 0 by default).
        thrust_mode: ``"box"`` (per-axis limit u_max, eq. 39) or ``"norm"``.
        max_distance: the allowed region: an episode terminates if a follower is farther than
            this from the leader [m].
        terminate_on_collision: end the episode at a collision (distance < r_i + r_j).
        reward_scale, collision_penalty, violation_penalty: reward shaping of the env (see
            ``satenv.envs.platoon_v0``).
        neighbour_slots: observe one slot per follower heard (padded to the largest in-degree)
            instead of one per other follower: observations of size ``15 + 7 max_f d_f``
            instead of ``15 + 7 (N - 1)``, the layout for swarms (``satenv.envs.platoon_v0``).
        randomize: draw initial states from the distribution below instead of the preset's.
        random_position_spread, random_velocity_spread, random_min_gap: see module docstring.
        success_tol: an episode succeeds when every follower ends within this distance of its
            target [m] (:func:`satenv.metrics.success`).
        collision_voids_success: a collision flag makes the episode a failure. ``None``
            (default): derived from the geometry — ``True`` unless the target formation itself
            puts two bodies closer than their contact distance (as pereira2023 Table I does:
            there success means reaching the formation, collisions are still counted).
    """

    name: str
    initial_state: tuple[tuple[float, ...], ...]
    desired_error: tuple[float, ...] = (0.0, -8.0, 0.0, 0.0, 0.0, 0.0)
    formation: str = "neighbourhood"
    topology: Any = "PLF"
    mu: float = MU_TABLE1
    orbit_radius: float = 6_621_000.0
    dt: float = 0.1
    max_steps: int = 180
    state_weight: tuple[float, ...] = (13.0,) * 6
    input_weight: tuple[float, ...] = (0.1,) * 3
    alpha: tuple[float, ...] = (2.0, 1.5, 1.0, 1.0)
    u_max: float = 6.0
    v_max: float = 20.0
    follower_radius: float = 3.0
    leader_radius: float = 3.0
    min_error_constraint: bool = False
    keepout_center: tuple[float, ...] = (0.0, 0.0, 0.0)
    keepout_radius: float = 0.0
    los_slopes: tuple[float, ...] | None = None
    port: tuple[float, ...] = (0.0, 0.0, 0.0)
    dynamics: str = "cw"
    inclination: float = 0.0
    thrust_mode: str = "box"
    max_distance: float = 500.0
    terminate_on_collision: bool = True
    reward_scale: float = 1.0e4
    collision_penalty: float = 100.0
    violation_penalty: float = 1.0
    neighbour_slots: bool = False
    randomize: bool = False
    random_position_spread: float = 20.0
    random_velocity_spread: float = 0.5
    random_min_gap: float = 2.0
    success_tol: float = 1.0
    collision_voids_success: bool | None = None
    _topology: Any = field(init=False, repr=False, compare=False)
    _voids_derived: bool = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        s = object.__setattr__
        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}.")
        s(self, "max_distance", number(self.max_distance, "max_distance"))
        x0 = states_in_region(self.initial_state, "initial_state (N, 6) follower states relative "
                              "to the leader", self.max_distance)
        n = x0.shape[0]
        s(self, "initial_state", tuple(tuple(float(v) for v in row) for row in x0))
        s(self, "desired_error", vector(self.desired_error, "desired_error", 6))
        if self.formation not in ("neighbourhood", "chain", "ring"):
            raise ValueError(
                f"formation must be 'neighbourhood', 'chain' or 'ring', got {self.formation!r}."
            )
        try:
            topo = make_topology(self.topology, n)
        except (TypeError, ValueError) as exc:
            raise SatenvError(f"topology: {exc}") from None
        s(self, "_topology", topo)
        if not isinstance(self.topology, str):
            s(self, "topology", tuple(tuple(int(v) for v in row) for row in topo.adjacency))
        else:
            s(self, "topology", topo.name)
        for name in ("mu", "orbit_radius", "dt", "u_max", "v_max", "follower_radius",
                     "leader_radius", "max_distance", "success_tol"):
            s(self, name, number(getattr(self, name), name))
        for name in ("reward_scale",):
            s(self, name, number(getattr(self, name), name))
        for name in ("collision_penalty", "violation_penalty"):
            s(self, name, number(getattr(self, name), name, allow_zero=True))
        for name in ("terminate_on_collision", "randomize", "min_error_constraint", "neighbour_slots"):
            s(self, name, flag(getattr(self, name), name))
        if self.thrust_mode not in ("box", "norm"):
            raise ValueError(f"thrust_mode must be 'box' or 'norm', got {self.thrust_mode!r}.")
        inc = vector([self.inclination], "inclination", 1)[0]
        if not 0.0 <= inc <= math.pi:
            raise ValueError(f"inclination must be in [0, pi] rad, got {self.inclination!r}.")
        s(self, "inclination", inc)
        for name in ("keepout_radius", "random_position_spread", "random_velocity_spread",
                     "random_min_gap"):
            s(self, name, number(getattr(self, name), name, allow_zero=True))
        s(self, "max_steps", steps(self.max_steps, "max_steps"))
        for name, length in (("state_weight", 6), ("input_weight", 3)):
            w = vector(getattr(self, name), name, length)
            if min(w) < 0:
                raise ValueError(f"{name} must be >= 0 (diagonal of a PSD weight), got {w}.")
            s(self, name, w)
        if min(self.input_weight) <= 0:
            raise ValueError(f"input_weight must be > 0 (W positive definite), got {self.input_weight}.")
        alpha = vector(self.alpha, "alpha")
        if len(alpha) != n or min(alpha) <= 0:
            raise ValueError(f"alpha must have {n} positive entries (one per follower), got {alpha}.")
        s(self, "alpha", alpha)
        s(self, "keepout_center", vector(self.keepout_center, "keepout_center", 3))
        s(self, "port", vector(self.port, "port", 3))
        if self.los_slopes is not None:
            c = vector(self.los_slopes, "los_slopes", 2)
            if min(c) <= 0:
                raise ValueError(f"los_slopes (c_x, c_z) must be > 0, got {c}.")
            s(self, "los_slopes", c)
        if self.dynamics not in ("cw", "nonlinear", "j2", "j2_drag"):
            raise ValueError(
                f"dynamics must be 'cw', 'nonlinear', 'j2' or 'j2_drag', got {self.dynamics!r}."
            )
        s(self, "_voids_derived", self.collision_voids_success is None)
        if self._voids_derived:
            s(self, "collision_voids_success", self.target_formation_collision_free())
        elif not isinstance(self.collision_voids_success, bool | np.bool_):
            raise ValueError(f"collision_voids_success must be True, False or None (derived), got "
                             f"{self.collision_voids_success!r}.")
        s(self, "collision_voids_success", bool(self.collision_voids_success))
        spreads_in_region(self.random_position_spread, self.random_velocity_spread, self.max_distance)
        at_most(R_EARTH, "the Earth's radius [m]", self.orbit_radius, "orbit_radius")
        inputs = f"mu = {self.mu!r}, orbit_radius = {self.orbit_radius!r}"
        orbit_step(derived(lambda: self.mean_motion, "the mean motion sqrt(mu / orbit_radius^3)",
                           inputs), self.dt, inputs)

    # ---- derived quantities ---------------------------------------------------------------
    @property
    def n_followers(self) -> int:
        return len(self.initial_state)

    @property
    def n_agents(self) -> int:
        """Number of controlled agents (the followers)."""
        return len(self.initial_state)

    @property
    def mean_motion(self) -> float:
        """Leader orbital rate n = sqrt(mu / ||r_l||^3) [rad/s]."""
        return math.sqrt(self.mu / self.orbit_radius**3)

    @property
    def graph(self):
        """The validated :class:`satenv.graph.Topology`."""
        return self._topology

    def initial_array(self) -> np.ndarray:
        return np.array(self.initial_state, dtype=float)

    def desired_states(self) -> np.ndarray:
        """Formation target states x* (N, 6) relative to the leader."""
        e_d = np.asarray(self.desired_error)
        if self.formation == "chain":
            return np.arange(1, self.n_followers + 1)[:, None] * e_d[None, :]
        if self.formation == "ring":
            return ring_states(self.n_followers, float(np.linalg.norm(e_d[:3])))
        return self._topology.desired_states(e_d)

    def target_formation_collision_free(self) -> bool:
        """True when the target formation keeps every pair of bodies (leader included) at least
        their contact distance ``r_i + r_j`` apart."""
        p = np.vstack([np.zeros(3), self.desired_states()[:, :3]])
        radius = np.r_[self.leader_radius, np.full(self.n_followers, self.follower_radius)]
        i, j = np.triu_indices(len(p), 1)
        return bool(np.all(np.linalg.norm(p[i] - p[j], axis=-1) >= radius[i] + radius[j]))

    def desired_neighbourhood_error(self) -> np.ndarray:
        """Target of the neighbourhood error, ``L_bar x*`` (N, 6); ``(g+d) E_d`` for pereira2023."""
        return self._topology.augmented_laplacian @ self.desired_states()

    def with_overrides(self, **overrides) -> PlatoonScenario:
        """A copy with fields replaced; unknown names raise ValueError.

        If ``initial_state`` changes the number of followers and ``alpha`` is not given, it
        becomes all ones.
        """
        known = {f.name for f in fields(self) if f.init}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ValueError(
                f"unknown scenario parameter(s) {bad}; valid names: {sorted(known)}."
            )
        if self._voids_derived:  # derive it again for the new geometry
            overrides.setdefault("collision_voids_success", None)
        n_new = overrides.get("initial_state")
        if n_new is not None and "alpha" not in overrides:
            n = np.asarray(n_new).shape[0] if np.ndim(n_new) == 2 else None
            if n is not None and n != self.n_followers:
                overrides["alpha"] = (1.0,) * n
        return replace(self, **overrides)


PRESETS: dict[str, PlatoonScenario] = {
    # pereira2023 Table I (the CasADi/MATLAB simulation of §IV). The paper's own target
    # formation puts followers closer than 2 r_f (PLF: 1 m between followers 3 and 4; BDL:
    # coincident pairs), and its simulation does not stop at contact: so neither does this
    # preset — collisions are reported in infos and metrics. Training and collision-aware
    # benchmarks use ``formation="chain"`` (8 m spacing) with ``terminate_on_collision=True``.
    "pereira2023": PlatoonScenario(
        name="pereira2023",
        terminate_on_collision=False,
        initial_state=(
            (30.0, -35.0, 40.0, 0.0, 0.0, 0.0),
            (15.0, -46.0, -30.0, 0.0, 0.0, 0.0),
            (-49.0, -43.0, -20.0, 0.0, 0.0, 0.0),
            (-29.0, -23.0, 37.0, 0.0, 0.0, 0.0),
        ),
    ),
    # pereira2022 §5.1: leader + 2 followers; p12(0) = [30,-50,40], p23(0) = [15,-46,-30] are
    # pair states, so follower 2 starts at p12 + p23 relative to the leader. y_d = [0,-10,0]
    # per pair (chain formation); Q weights the position output only. n_k is not given in
    # the paper: 300 steps (30 s) is our choice. The env's observations use the PLF graph.
    # Its controller (convex step, N = 40, P, gamma = 2, w = (0.6, 0.4)) is
    # ``satenv.baselines.dmpc.PAPER_CONFIGS["pereira2022"]``.
    "pereira2022": PlatoonScenario(
        name="pereira2022",
        initial_state=(
            (30.0, -50.0, 40.0, 0.0, 0.0, 0.0),
            (45.0, -96.0, 10.0, 0.0, 0.0, 0.0),
        ),
        desired_error=(0.0, -10.0, 0.0, 0.0, 0.0, 0.0),
        formation="chain",
        topology="PLF",
        mu=MU_TABLE1,
        orbit_radius=6_621_000.0,
        dt=0.1,
        max_steps=300,
        state_weight=(8.0, 8.0, 8.0, 0.0, 0.0, 0.0),
        input_weight=(0.1, 0.1, 0.1),
        alpha=(2.0, 1.5),
        keepout_center=(0.0, 0.0, 0.0),
        keepout_radius=6.0,
        los_slopes=(1.0, 1.0),
        port=(2.0, 2.0, 4.0),
        u_max=6.0,
        v_max=20.0,
    ),
}


def ring_states(n: int, spacing: float) -> np.ndarray:
    """States ``(n, 6)`` of the ``"ring"`` formation: ``n`` bodies at rest, ``spacing`` apart on a
    circle around the origin in the y-z plane (module docstring)."""
    radius = spacing / (2.0 * math.sin(math.pi / n)) if n > 1 else spacing
    angle = 2.0 * np.pi * np.arange(n) / n
    x = np.zeros((n, 6))
    x[:, 1], x[:, 2] = -radius * np.cos(angle), radius * np.sin(angle)
    return x


def swarm(n: int, formation: str = "chain", topology: str = "PLF", *, spacing: float = 20.0,
          spread: float = 4.0, **overrides: Any) -> dict[str, Any]:
    """Keyword arguments of ``platoon_v0`` for a swarm of ``n`` followers (``1 <= n <= 1024``).

    The ``"pereira2023"`` preset's physics and weights with: the ``formation`` (``"chain"`` along
    -y or ``"ring"``) ``spacing`` metres apart over ``topology`` (``"PLF"``, ``"BDL"``, ``"TPLF"``
    or ``"RING"``), ``alpha`` all ones, observations of the neighbours only
    (``neighbour_slots=True``), ``max_distance`` twice the formation's extent (at least 500 m), a
    collision ending the episode, and randomised starts (``randomize=True``): each follower
    within ``U(-spread, spread)`` per axis of its target, velocities ``U(-0.1, 0.1)`` m/s; with
    ``spacing > 4 spread + 2 r_f`` every draw is collision-free. ``overrides`` replace any of
    these (any scenario field, e.g. ``randomize=False`` to start on the targets).

    >>> env = satenv.make("platoon_v0", **swarm(256, "ring", "RING"))
    """
    if formation not in ("chain", "ring"):
        raise SatenvError(f"swarm formation must be 'chain' or 'ring', got {formation!r}")
    n = int(n)
    e_d = (0.0, -float(spacing), 0.0, 0.0, 0.0, 0.0)
    target = (np.arange(1, n + 1)[:, None] * np.asarray(e_d) if formation == "chain"
              else ring_states(n, float(spacing)))
    extent = float(np.abs(target[:, :3]).max()) + 2.0 * spread
    start = tuple(tuple(row) for row in target.tolist())
    kwargs = {"preset": "pereira2023", "initial_state": start, "formation": formation,
              "topology": topology, "desired_error": e_d, "alpha": (1.0,) * n, "neighbour_slots": True,
              "max_distance": max(500.0, 2.0 * extent), "randomize": True,
              "random_position_spread": float(spread), "random_velocity_spread": 0.1,
              "random_min_gap": 0.5, "terminate_on_collision": True}
    return {**kwargs, **overrides}


def resolve_scenario(preset: str = "pereira2023", **overrides) -> PlatoonScenario:
    """``PRESETS[preset]`` with ``overrides`` applied (validated)."""
    return from_preset(PRESETS, preset, "platoon", overrides)


def pair_states(scenario: PlatoonScenario, x: np.ndarray) -> np.ndarray:
    """Target–chaser pair states ``x_f - x_{f-1}`` (leader = 0), ``(..., N, 6)``."""
    x = np.asarray(x, dtype=float)
    prev = np.concatenate([np.zeros_like(x[..., :1, :]), x[..., :-1, :]], axis=-2)
    return x - prev


def los_keepout_ok(scenario: PlatoonScenario, x: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Per follower (..., N) bool: pair position inside the LOS cone and outside the keep-out.

    ``margin`` [m] tightens both sets. Always True when neither constraint is configured.
    """
    p = pair_states(scenario, x)[..., :3]
    ok = np.ones(p.shape[:-1], dtype=bool)
    if scenario.keepout_radius > 0:
        d = np.linalg.norm(p - np.asarray(scenario.keepout_center), axis=-1)
        ok &= d >= scenario.keepout_radius + margin
    if scenario.los_slopes is not None:
        cx, cz = scenario.los_slopes
        xr, yr, zr = scenario.port
        px, py, pz = p[..., 0], p[..., 1], p[..., 2]
        ok &= py <= -yr - margin
        ok &= cx * np.abs(px) + py <= cx * xr - margin
        ok &= cz * np.abs(pz) + py <= cz * zr - margin
    return ok


def sample_initial_state(scenario: PlatoonScenario, rng: np.random.Generator) -> np.ndarray:
    """Draw an initial state (N, 6) from the documented distribution (module docstring)."""
    nominal = scenario.initial_array()
    n = scenario.n_followers
    s, v = scenario.random_position_spread, scenario.random_velocity_spread
    min_sep = 2.0 * scenario.follower_radius + scenario.random_min_gap
    min_leader = scenario.follower_radius + scenario.leader_radius + scenario.random_min_gap
    for _ in range(1000):
        x = nominal.copy()
        x[:, :3] += rng.uniform(-s, s, size=(n, 3))
        x[:, 3:] = rng.uniform(-v, v, size=(n, 3))
        pos = x[:, :3]
        if np.any(np.linalg.norm(pos, axis=1) < min_leader):
            continue
        if n > 1 and nearest(pos[None])[0].min() < min_sep:
            continue
        if not np.all(los_keepout_ok(scenario, x, margin=0.5)):
            continue
        return x
    raise SatenvError(
        "could not draw a collision-free initial state in 1000 tries; reduce "
        "random_position_spread or random_min_gap."
    )
