"""The per-scenario model of the filter: constraints, action-to-acceleration map, braking authority."""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from satenv.dynamics import cw_matrices, thruster_matrices
from satenv.perturbations import UncertaintyBounds, declared_bounds, nominal
from satenv.safety.config import _KIND, SafetyTypeError


# ---------------------------------------------------------------------------------------------
# the per-scenario model
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Body:
    """A sphere of radius ``radius`` around ``center + velocity t`` that one agent must avoid."""

    kind: str
    center: np.ndarray
    velocity: np.ndarray
    radius: float


@dataclass(frozen=True, eq=False)
class SafetyModel:
    """The constraints and the one-decision model of one scenario (:func:`safety_model`).

    ``S`` maps a normalised action to an LVLH acceleration (``(3, d)``; rotated by the body
    attitude when ``body_frame``); ``u_box`` bounds the QP's action; ``brake`` is ``a_i``.
    """

    env_id: str
    n_agents: int
    action_dim: int
    dt: float
    n: float
    A: np.ndarray
    B: np.ndarray
    S: np.ndarray
    u_box: float
    norm_mode: bool
    body_frame: bool
    brake: float
    reach: float                     # |n^T B_p du| <= reach per unit of ||du|| bound (delta)
    accel_max: float                 # max ||S u|| over the action box
    disturbance: float               # bound on a disturbance acceleration [m/s^2]
    pair_distance: float = 0.0       # 0: no agent-agent constraint
    bodies: tuple[Body, ...] = ()
    chain_sphere: tuple[np.ndarray, float] | None = None       # (offset c, radius): p_f - p_{f-1} - c
    chain_halfspaces: tuple[np.ndarray, np.ndarray] | None = None  # (normals (K, 3), bounds (K,))
    lbar: np.ndarray | None = None   # platoon: velocity bound (40) on (Lbar x)_f
    v_max: float = 0.0               # velocity bound (per axis); 0: none
    attitude: tuple | None = None    # servicing: (j_f, j_l, omega_l, omega_max, G (3, d), substeps)
    kinds: tuple[int, ...] = ()
    budget: tuple[np.ndarray, np.ndarray] | None = None   # (own, other) (M, slots): braking fractions
    bounds: UncertaintyBounds = UncertaintyBounds()       # what it cannot see (satenv.safety.margins)

    @functools.cached_property
    def body_state(self) -> np.ndarray:
        """``[centre at t = 0, velocity]`` of every body ``(nb, 6)``."""
        return np.array([np.r_[b.center, b.velocity] for b in self.bodies]).reshape(-1, 6)

    @functools.cached_property
    def body_radius(self) -> np.ndarray:
        return np.array([b.radius for b in self.bodies])

    @property
    def n_chain(self) -> int:
        """Position slots of the platoon target-chaser pairs (keep-out sphere, LOS half-spaces)."""
        return (self.chain_sphere is not None) + (0 if self.chain_halfspaces is None else len(self.chain_halfspaces[1]))

    def state_dim_ok(self, width: int) -> bool:
        return width >= (13 if self.body_frame or self.attitude is not None else 6)


def safety_model(target: Any, bounds: UncertaintyBounds | None = None) -> SafetyModel:
    """The :class:`SafetyModel` of an env, a ``make_vec`` batch or a batched core: built from the
    nominal env (:func:`satenv.perturbations.nominal`, never the perturbed truth), with ``bounds``
    (default: the env's declared bounds, :func:`satenv.perturbations.declared_bounds`)."""
    if bounds is not None and not isinstance(bounds, UncertaintyBounds):
        raise SafetyTypeError(f"bounds must be a satenv.perturbations.UncertaintyBounds or None, got "
                              f"{type(bounds).__name__}")
    core = _core_of(nominal(target))
    name = type(core).__name__
    sc = core.scenario
    builders = {"PlatoonCore": _platoon, "ClusterCore": _cluster, "ServicingCore": _servicing,
                "FormationCore": _formation, "FormationFlyingCore": _formation}
    if name not in builders:
        raise SafetyTypeError(f"the safety filter knows the satenv cores {sorted(builders)}, got {name}")
    fields = builders[name](core, sc)
    n = float(core.model.orbit.n)
    a, b = cw_matrices(n, float(sc.dt))
    s = fields.pop("S")
    norm_mode = getattr(sc, "thrust_mode", "box") == "norm"
    u_box = 1.0 / math.sqrt(3.0) if norm_mode else 1.0
    sv = np.linalg.svd(s, compute_uv=False)
    fields.update(
        n_agents=core.n_agents, action_dim=s.shape[1], dt=float(sc.dt), n=n, A=a, B=b, S=s,
        u_box=u_box, norm_mode=norm_mode, brake=float(sv.min()) * u_box,
        reach=float(np.linalg.norm(b[:3], 2)),
        accel_max=float(sv.max()) * u_box * math.sqrt(s.shape[1]))
    model = SafetyModel(**fields, bounds=declared_bounds(target) if bounds is None else bounds)
    return dataclasses.replace(model, kinds=_row_kinds(model), budget=_budget(model))


def _has_position_rows(m: SafetyModel) -> bool:
    """Whether the model keeps any distance (agents apart, a body, a chain constraint)."""
    return m.pair_distance > 0 or bool(m.bodies) or m.n_chain > 0


def courtesy(n_agents: int) -> np.ndarray:
    """``c_f`` ``(M,)``: the fraction of its braking authority platoon follower ``f`` may use along
    its chaser's direction when the chaser is near its bound, ``(f + 1) / M`` (0-based ``f``).

    A chaser's braking relative to its target must cover the target's ``c_{f-1}``, and the chaser's
    own acceleration along that direction is capped at ``c_f`` by its own chaser: every chain pair
    keeps ``c_f - c_{f-1} = 1 / M`` of an authority (the last chaser ``1 - c_{M-2} = 1 / M``)."""
    return (np.arange(n_agents) + 1.0) / n_agents


def _budget(m: SafetyModel) -> tuple[np.ndarray, np.ndarray]:
    """The fractions ``(own, other)`` of each agent's braking authority that each position slot
    may use, ``(M, slots)``: a pair of agents (1, 1), a body or the passive leader (1, 0). A
    platoon chaser keeps its target-chaser pair alone (the target's action is known: the chain is
    filtered in order) with ``1 / M`` of its authority (:func:`courtesy`)."""
    na = m.n_agents
    own = [np.ones((na, na if m.pair_distance > 0 else 0)), np.ones((na, len(m.bodies)))]
    other = [own[0].copy(), np.zeros((na, len(m.bodies)))]
    own.append(np.full((na, m.n_chain), 1.0 / na))
    other.append(np.zeros((na, m.n_chain)))
    return np.concatenate(own, axis=1), np.concatenate(other, axis=1)


def _u_scale(sc: Any, d: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(sc.u_max, dtype=float), (d,)).copy()


def _platoon(core: Any, sc: Any) -> dict[str, Any]:
    out: dict[str, Any] = {
        "env_id": "platoon_v0", "S": np.diag(_u_scale(sc, 3)), "body_frame": False, "disturbance": 0.0,
        "pair_distance": 2.0 * sc.follower_radius,
        "bodies": (Body("leader", np.zeros(3), np.zeros(3), sc.leader_radius + sc.follower_radius),),
        "lbar": np.asarray(core.lbar, dtype=float), "v_max": float(sc.v_max)}
    if sc.keepout_radius > 0:
        out["chain_sphere"] = (np.asarray(sc.keepout_center, dtype=float), float(sc.keepout_radius))
    if sc.los_slopes is not None:   # eq. 34: p_y <= -y_r, c_x |p_x| + p_y <= c_x x_r, c_z |p_z| + p_y <= c_z z_r
        cx, cz = sc.los_slopes
        xr, yr, zr = sc.port
        m = np.array([[0, 1, 0], [cx, 1, 0], [-cx, 1, 0], [0, 1, cz], [0, 1, -cz]], dtype=float)
        bnd = np.array([-yr, cx * xr, cx * xr, cz * zr, cz * zr], dtype=float)
        norm = np.linalg.norm(m, axis=1)
        out["chain_halfspaces"] = (m / norm[:, None], bnd / norm)
    return out


def _cluster(core: Any, sc: Any) -> dict[str, Any]:
    bodies = [Body("obstacle", np.asarray(sc.obstacle_position, float), np.asarray(sc.obstacle_velocity, float),
                   float(sc.obstacle_distance))]
    if sc.target_distance > 0:
        bodies.append(Body("target", np.asarray(sc.target_spacecraft, float), np.zeros(3), float(sc.target_distance)))
    return {"env_id": "cluster_v0", "S": float(sc.u_max) * np.eye(3), "body_frame": False,
            "disturbance": float(sc.disturbance_amplitude), "pair_distance": float(sc.pair_distance),
            "bodies": tuple(bodies)}


def _servicing(core: Any, sc: Any) -> dict[str, Any]:
    f_t, f_r = thruster_matrices(sc.dimensions)
    u = _u_scale(sc, 6)
    gain = sc.dt * np.linalg.solve(np.asarray(core.j_f, float), f_r * u)   # d omega^+ / d u (first order)
    return {"env_id": "servicing_v0", "S": f_t * u, "body_frame": sc.thrust_frame == "body",
            "attitude": (core.j_f, core.j_l, core.omega_l, float(sc.omega_max), gain, int(sc.substeps)),
            "disturbance": 0.0, "pair_distance": float(sc.separation_radius),
            "bodies": (Body("keep-out", np.zeros(3), np.zeros(3), float(sc.keepout_radius)),),
            "v_max": float(sc.v_max)}


def _formation(core: Any, sc: Any) -> dict[str, Any]:
    return {"env_id": "formation_v0", "S": np.diag(_u_scale(sc, 3)), "body_frame": False,
            "disturbance": 0.0, "pair_distance": float(sc.collision_distance)}


def _row_kinds(m: SafetyModel) -> tuple[int, ...]:
    """The constraint kind of every row slot (the same for every agent and copy), in the order of
    :func:`constraint_rows`: (C1) then (C2) of every position slot, the chain targets' courtesy
    rows, the velocity rows, the angular-velocity rows."""
    slots = [_KIND["separation"]] * (m.n_agents if m.pair_distance > 0 else 0)
    slots += [_KIND[body.kind] for body in m.bodies]
    chain = [_KIND["keep-out"]] * (m.chain_sphere is not None)
    chain += [_KIND["los"]] * (0 if m.chain_halfspaces is None else len(m.chain_halfspaces[1]))
    kinds = 2 * (slots + chain) + chain
    kinds += [_KIND["velocity"]] * (6 if m.v_max > 0 else 0)
    kinds += [_KIND["angular-velocity"]] * (6 if m.attitude is not None else 0)
    return tuple(kinds)


def _core_of(target: Any) -> Any:
    core = getattr(target, "core", target)
    if not (hasattr(core, "scenario") and hasattr(core, "x") and hasattr(core, "model")):
        raise SafetyTypeError("the safety filter needs a satenv env (satenv.make), a make_vec batch or "
                              f"a batched core, got {type(target).__name__}")
    return core
