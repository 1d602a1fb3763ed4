"""Run-time assurance: a safety filter between any policy and any satenv env.

The filter changes a proposed action only when it would lead to a violation, and records that it
did. One core, three ways to use it::

    from satenv.safety import SafetyFilter, shield
    safe, record = SafetyFilter(env).filter(actions)     # (B, M, d) arrays, any env or make_vec batch
    policy = shield(policy, env)                         # a policy wrapper (same reset / act / info)
    env = satenv.make("cluster_v0", safety_filter=True)  # or make_vec / satenv.torchrl.make_env

**Constraints** (from the scenario's own fields; each agent's state ``x_i = [p_i, v_i]`` in LVLH):

* spheres ``||p_i - p_j|| >= D`` between agents (each takes half), and between an agent and a
  body it alone must avoid (platoon leader, cluster obstacle and target spacecraft, servicing
  keep-out sphere); the pereira2022 §5.1 keep-out sphere of each target–chaser pair;
* half-spaces ``m^T (p_f - p_{f-1}) <= b`` (the pereira2022 §5.1 LOS cone, eq. 34);
* velocity boxes (relative degree one): pereira2023 bound (40) on the velocity part of the
  neighbourhood error ``E_f = (Lbar x)_f``, the servicing ``|v_i| <= v_max`` and
  ``|omega_i| <= omega_max`` (first-order torque effect on the env's own coasting attitude step);
* the thrust box: the filtered action stays in ``[-1, 1]^d`` (the inscribed cube
  ``[-1/sqrt 3, 1/sqrt 3]^3`` of the thrust ball in ``thrust_mode="norm"``).

**Prediction.** One decision ``dt`` of the exact discrete CW model (:func:`satenv.dynamics.cw_matrices`)
``x^+ = A x + B u``; relative states of two agents obey it exactly, a body's motion is the env's
own (fixed, or the obstacle's straight line). The truth models (nonlinear, J2, drag) differ from
it; the repository has no J2 linearisation, so CW is the model for every ``dynamics``.

**Barrier** (Wang, Ames, Egerstedt 2017, for double integrators with braking ``a``): for gap
``s = ||r_p|| - D`` (or ``b - m^T r_p``) and rate ``rho = n^T r_v`` along the direction ``n`` in
which the gap grows, ``h = rho + sqrt(2 a s)``: ``h >= 0`` iff braking at ``a`` along ``n`` stops
before the gap closes. ``a`` is the braking authority of the pair (``a_i + a_j``, or ``a_i``
against a body; ``a_i = sigma_min(S_i)`` of the action-to-acceleration map) minus a bound on the
CW drift (``3 n^2 ||r_p|| + 2 n ||r_v||``) and on the scenario's disturbance.

**Backup condition** (one decision, relative degree two): with ``n`` the direction of the coasting
prediction ``rbar^+ = A r`` and ``Delta u`` the relative acceleration,

    (C1)  sbar + n^T B_p Delta u >= 0                       the gap at the next decision (n^T r_p <= ||r_p||)
    (C2)  n^T (rbar_v^+ + B_v Delta u) + phi(s^+) >= (1 - gamma) h(now)   still brakeable next decision

with ``phi`` the chord of ``sqrt(2 a s)`` over the reachable gaps ``[sbar - delta, sbar + delta]``
(a lower bound of the concave root there, so (C2) is linear and conservative). Both rows are
linear in ``Delta u = S_i u_i - S_j u_j``; each agent keeps its share (half for a pair, all
against a body): ``w^T S_i u_i >= -share * g``. Summed, the two shares give the pair's row.
The pereira2022 target-chaser pairs (LOS cone, keep-out sphere of ``p_f - p_{f-1}``) are the
chaser's alone, filtered down the chain so that its rows hold its target's filtered
acceleration; a target ``f`` whose chaser is near its bound (``h < 3 max||S u|| dt``) keeps its
acceleration along the chaser's direction ``n`` within ``c_f a`` (a courtesy row, ``c_f = (f+1)/M``),
and every chain pair brakes with ``a / M`` (:func:`courtesy`: otherwise the two pairs of a follower
can ask it to accelerate both ways along one direction at once).
The margin (``margin * D``, ``los_margin``) inflates ``D`` but never beyond the current gap (a
start on the boundary stays feasible).

**QP** per agent: ``min ||u - u_ref||^2  s.t.  W u >= l,  |u| <= u_box`` (daqp), only for the
agents whose proposal breaks a row; every other action passes unchanged (bit for bit). A QP that is
infeasible or fails (any exception, a bad status, a non-finite point, a violated row) gives the
backup action — maximum braking: the action in the box that maximises the smallest row slack
(or, if that solve fails too, full thrust along the row the proposal breaks most) — and the
``infeasible`` flag; never an exception, never a NaN.

Guarantee (for the CW double-integrator model, the scenario's disturbance bound and states whose
rows are feasible): separation and half-space gaps stay >= 0 at every decision and the pair stays
brakeable; the velocity boxes hold at the next decision. Not guaranteed: infeasible starts (a
start inside the margin with closing speed), model mismatch (J2, drag, nonlinear terms beyond the
drift bound), dips between decisions larger than the margin, constraints of other agents' QPs
that fall back (their share is then missing), an agent squeezed between several pairs at once
(each pair assumes its full authority), the allowed region (``max_distance``) and the
pereira2023 minimum-error constraint (41) (implied by separation for the PLF topology only).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from satenv.dynamics import attitude_step, cw_matrices, quat_to_matrix, thruster_matrices
from satenv.dynamics._checks import all_finite
from satenv.errors import SatenvError, SatenvTypeError

__all__ = ["CONSTRAINTS", "MIN_MARGIN", "SafetyConfig", "SafetyError", "SafetyFilter",
           "SafetyModel", "SafetyRecord", "SafetyTypeError", "SafetyWarning", "Shield", "constraint_rows", "courtesy", "filter_actions",
           "filtered_env", "safety_config", "safety_model", "shield", "solve_qp"]

CONSTRAINTS: tuple[str, ...] = ("separation", "leader", "obstacle", "target", "keep-out", "los", "velocity",
                                 "angular-velocity")
"""Names of the constraint kinds (:attr:`SafetyRecord.active` indexes this tuple; -1: none)."""
_KIND = {name: k for k, name in enumerate(CONSTRAINTS)}
_BIG = 1e30
_ROW_TOL = 1e-12      # a proposal within this of a row (its own units: m, m/s, rad/s) passes unchanged
_QP_TOL = 1e-7        # a QP point may violate a row / the box by this much
_FLOOR = 0.05         # braking authority never below this fraction of the nominal (drift-heavy pairs)
MIN_MARGIN = 1e-9
"""The smallest ``margin``, ``los_margin`` and ``velocity_margin`` a :class:`SafetyConfig` takes: a
margin below it is lost in the float rounding of the gaps it inflates (km-scale distances carry
relative errors near 1e-13) and would only look like a margin."""


class SafetyError(SatenvError):
    """Bad input to the safety filter (a ``ValueError``): the message names the field."""


class SafetyTypeError(SafetyError, SatenvTypeError):
    """Input of the wrong type to the safety filter (a ``TypeError``)."""


class SafetyWarning(UserWarning):
    """The filter was asked for where it enforces less than one may expect (e.g. no separation)."""


# ---------------------------------------------------------------------------------------------
# config and record
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SafetyConfig:
    """The filter's settings (validated; unknown options are rejected by :meth:`from_options`).

    Attributes:
        margin: each separation distance ``D`` is inflated to ``(1 + margin) D`` (> 0).
        los_margin: half-space (LOS cone) margin [m] (> 0).
        velocity_margin: velocity bounds tightened to ``(1 - velocity_margin) V`` (in (0, 1)).
        gamma: discrete barrier rate in (0, 1]: ``h^+ >= (1 - gamma) h`` (1: only keep brakeable).
        penalty: reward penalty per unit ``|du|`` in the filtered envs (>= 0; 0: none).
    """

    margin: float = 0.02
    los_margin: float = 0.05
    velocity_margin: float = 0.02
    gamma: float = 1.0
    penalty: float = 0.0

    def __post_init__(self) -> None:
        limits = {"margin": (0.0, math.inf, False), "los_margin": (0.0, math.inf, False),
                  "velocity_margin": (0.0, 1.0, False), "gamma": (0.0, 1.0, True),
                  "penalty": (0.0, math.inf, None)}
        for name, (low, high, high_ok) in limits.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise SafetyTypeError(f"SafetyConfig.{name} must be a real number, got {value!r:.40}")
            try:
                v = float(value)
            except OverflowError:   # an int beyond the float range, e.g. 10**400
                v = math.inf
            ok = (math.isfinite(v) and (v >= low if high_ok is None else v > low)
                  and (v <= high if high_ok else v < high))
            if not ok:
                rng = (f">= {low:g}" if high_ok is None else f"> {low:g}") + (
                    "" if high == math.inf else f" and {'<=' if high_ok else '<'} {high:g}")
                raise SafetyError(f"SafetyConfig.{name} must be finite and {rng}, got {value!r:.40}")
            if name.endswith("margin") and v < MIN_MARGIN:
                raise SafetyError(f"SafetyConfig.{name} must be >= MIN_MARGIN = {MIN_MARGIN:g} (a smaller margin "
                                  f"is lost in float rounding), got {value!r:.40}")
            object.__setattr__(self, name, v)

    @classmethod
    def from_options(cls, config: SafetyConfig | None = None, **options: Any) -> SafetyConfig:
        """``config`` (default ``SafetyConfig()``) with ``options`` replaced; unknown keys rejected."""
        if config is not None and not isinstance(config, SafetyConfig):
            raise SafetyTypeError(f"config must be a SafetyConfig or None, got {type(config).__name__}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise SafetyError(f"safety filter: unknown option(s) {unknown}; accepted: {known}")
        return dataclasses.replace(config or cls(), **options)


@dataclass(frozen=True)
class SafetyRecord:
    """What the filter did, per copy and agent ``(B, M)``.

    ``intervened`` (the action changed), ``delta`` ``|du|`` (Euclidean norm of the change of the
    normalised action the env applies: the proposal clipped to the action box first, so it is
    finite and at most the box's diameter for any finite proposal), ``infeasible`` (QP infeasible or failed: the backup action was applied),
    ``active`` (index into :data:`CONSTRAINTS` of the binding constraint, -1 when none).
    """

    intervened: np.ndarray
    delta: np.ndarray
    infeasible: np.ndarray
    active: np.ndarray

    @property
    def active_names(self) -> np.ndarray:
        """:attr:`active` as names (``""`` when none), ``(B, M)`` object array."""
        names = np.array(("",) + CONSTRAINTS, dtype=object)
        return names[self.active + 1]

    def infos(self) -> dict[str, np.ndarray]:
        """The record as info arrays ``safety_intervened``, ``safety_delta``,
        ``safety_infeasible``, ``safety_active`` (names)."""
        return {"safety_intervened": self.intervened, "safety_delta": self.delta,
                "safety_infeasible": self.infeasible, "safety_active": self.active_names}


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


def safety_model(target: Any) -> SafetyModel:
    """The :class:`SafetyModel` of an env, a ``make_vec`` batch or a batched core."""
    core = _core_of(target)
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
    model = SafetyModel(**fields)
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


# ---------------------------------------------------------------------------------------------
# constraint rows
# ---------------------------------------------------------------------------------------------
def _barrier(m: SafetyModel, cfg: SafetyConfig, gap0, rate0, gap_bar, dirn, vel_bar, brake, span):
    """Rows (C1), (C2) of the module docstring in acceleration space: ``w^T du >= -g``.

    ``gap0, rate0``: the gap and its rate now; ``gap_bar, dirn, vel_bar``: the coasting gap, the
    direction ``n`` and relative velocity at the next decision; ``brake`` the pair's ``a``;
    ``span`` the bound ``delta`` on ``|n^T B_p du|``. Returns ``(w1, g1, w2, g2, h)``, ``h`` the
    barrier now.
    """
    bp, bv = m.B[:3], m.B[3:]
    w1 = dirn @ bp
    s_lo = np.maximum(gap_bar - span, 0.0)
    s_hi = np.maximum(gap_bar + span, s_lo + 1e-12)
    slope = (np.sqrt(s_hi) - np.sqrt(s_lo)) / (s_hi - s_lo)
    c = np.sqrt(2.0 * brake)
    w2 = dirn @ bv + (c * slope)[..., None] * w1
    h0 = rate0 + c * np.sqrt(np.maximum(gap0, 0.0))
    g2 = (np.sum(dirn * vel_bar, axis=-1) + c * (np.sqrt(s_lo) + slope * (gap_bar - s_lo))
          - (1.0 - cfg.gamma) * h0)
    return w1, gap_bar, w2, g2, h0


def _sphere(cfg, r, r_bar, radius):
    """Geometry of ``||r_p|| >= radius`` for relative states ``r`` (now) and ``r_bar`` (coasting,
    next decision), ``(..., 6)``: ``(gap0, rate0, gap_bar, dirn, vel_bar)``, ``dirn`` the unit
    coasting direction (the margin: :class:`SafetyConfig`, never beyond the current gap)."""
    d0 = np.sqrt(np.einsum("...i,...i->...", r[..., :3], r[..., :3]))
    d_m = radius + np.minimum(cfg.margin * radius, np.maximum(d0 - radius, 0.0))
    d_bar = np.sqrt(np.einsum("...i,...i->...", r_bar[..., :3], r_bar[..., :3]))
    dirn = r_bar[..., :3] / np.maximum(d_bar, 1e-12)[..., None]
    rate0 = np.einsum("...i,...i->...", r[..., :3], r[..., 3:]) / np.maximum(d0, 1e-12)
    return d0 - d_m, rate0, d_bar - d_m, dirn, r_bar[..., 3:]


def _halfspaces(cfg, r, r_bar, normals, bounds):
    """Geometry of ``normals_k^T r_p <= bounds_k`` (``(K, 3)``, ``(K,)``) for ``r``, ``r_bar``
    ``(..., 6)``: arrays ``(..., K)``; the gap grows along ``-normal``."""
    gap0 = bounds - r[..., :3] @ normals.T
    b_m = bounds - np.minimum(cfg.los_margin, np.maximum(gap0, 0.0))
    dirn = np.broadcast_to(-normals, (*r.shape[:-1], *normals.shape))
    vel = np.repeat(r_bar[..., None, 3:], len(bounds), axis=-2)
    return b_m - r[..., :3] @ normals.T, -(r[..., 3:] @ normals.T), b_m - r_bar[..., :3] @ normals.T, dirn, vel


def _drift(m: SafetyModel, state: np.ndarray) -> np.ndarray:
    """Bound on the CW drift acceleration of a relative state: ``3 n^2 ||r_p|| + 2 n ||r_v||``."""
    sq = state[..., :6] * state[..., :6]
    return 3.0 * m.n**2 * np.sqrt(sq[..., :3].sum(-1)) + 2.0 * m.n * np.sqrt(sq[..., 3:].sum(-1))


def constraint_rows(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every agent's rows ``w^T (S_i u_i) >= l`` in acceleration space: ``w (B, M, K, 3)``,
    ``l (B, M, K)`` (``l = -1e30``: an unused slot); ``K = len(m.kinds)`` minus the
    angular-velocity rows (:func:`_omega_rows`, in action space).

    Every position constraint is one slot ``(gap0, rate0, gap_bar, dirn, vel_bar)`` with a budget
    ``(own, other)`` (the fractions of each agent's braking authority the pair may use; ``other
    = 0``: a body or the passive leader) and a drift bound; one :func:`_barrier` call serves all.
    """
    x6 = x[..., :6]
    xb = x6 @ m.A.T                                       # coasting prediction of every agent
    bsz, na = x6.shape[:2]
    geos: list[tuple] = []                                # (gap0, rate0, gap_bar, dirn, vel_bar), (B, M, k)
    drifts: list[np.ndarray] = []
    if m.pair_distance > 0:
        r = x6[:, :, None] - x6[:, None]                  # (B, M, M, 6): agent i minus agent j
        geos.append(_sphere(cfg, r, xb[:, :, None] - xb[:, None], m.pair_distance))
        drifts.append(_drift(m, r))
    if m.bodies:   # (B, nb, 6) body states now and at the next decision (their own motion)
        centre = m.body_state[None, :, :3] + t[:, None, None] * m.body_state[None, :, 3:]
        now = np.concatenate([centre, np.broadcast_to(m.body_state[None, :, 3:], centre.shape)], -1)
        nxt = now + m.dt * np.concatenate([m.body_state[:, 3:], np.zeros((len(m.bodies), 3))], -1)
        geos.append(_sphere(cfg, x6[:, :, None] - now[:, None], xb[:, :, None] - nxt[:, None], m.body_radius))
        drifts.append(np.repeat(_drift(m, x6)[..., None], len(m.bodies), axis=-1))
    n_chain = m.n_chain
    if n_chain:
        zero = np.zeros_like(x6[:, :1])
        r = x6 - np.concatenate([zero, x6[:, :-1]], axis=1)
        rb = xb - np.concatenate([zero, xb[:, :-1]], axis=1)
        if m.chain_sphere is not None:
            off = np.r_[m.chain_sphere[0], np.zeros(3)]
            geos.append(tuple(v[:, :, None] for v in _sphere(cfg, r - off, rb - off, m.chain_sphere[1])))
        if m.chain_halfspaces is not None:
            geos.append(_halfspaces(cfg, r, rb, *m.chain_halfspaces))
        drifts.append(np.repeat(_drift(m, r)[..., None], n_chain, axis=-1))
    ws: list[np.ndarray] = []
    ls: list[np.ndarray] = []
    if geos:
        geo = [np.concatenate([g[f] for g in geos], axis=2) if len(geos) > 1 else geos[0][f] for f in range(5)]
        drift = np.concatenate(drifts, axis=2) if len(drifts) > 1 else drifts[0]
        w1, l1, w2, l2, h0 = _shared(m, cfg, m.budget[0], m.budget[1], drift, *geo)
        if m.pair_distance > 0:                            # an agent and itself: no row
            eye = np.eye(na, dtype=bool)
            l1[..., :na] = np.where(eye, -_BIG, l1[..., :na])
            l2[..., :na] = np.where(eye, -_BIG, l2[..., :na])
        ws += [w1, w2]
        ls += [l1, l2]
        if n_chain:   # courtesy: the target f - 1 of a chaser near its bound, along n <= c_{f-1} a
            near = h0[:, :, -n_chain:] < 3.0 * m.accel_max * m.dt
            bound = -(courtesy(na) * m.brake)[None, :, None]      # shifted: agent f - 1 gets c_{f-1}
            ws.append(_up(-geo[3][:, :, -n_chain:], 0.0))
            ls.append(np.where(_up(near, False), np.broadcast_to(bound, near.shape), -_BIG))
    if m.v_max > 0:
        _velocity_rows(m, cfg, x6, xb, ws, ls)
    if not ws:                                            # e.g. formation_v0 at collision_distance = 0
        return np.zeros((bsz, na, 0, 3)), np.zeros((bsz, na, 0))
    w = np.concatenate([v.reshape(bsz, na, -1, 3) for v in ws], axis=2)
    lo = np.concatenate([v.reshape(bsz, na, -1) for v in ls], axis=2)
    return w, lo


def _shared(m, cfg, own, other, drift, gap0, rate0, gap_bar, dirn, vel_bar):
    """:func:`_barrier` with the pair's authority, and this agent's share of the rows.

    ``a = (own + other) a_i`` minus the drift bound and the disturbance of each moving agent
    (floored at ``_FLOOR`` of the nominal: there the barrier is no longer a guarantee);
    ``delta = ||B_p|| max ||S u||`` per moving agent; this agent's share ``own / (own + other)``.
    """
    units, movers = own + other, 1.0 + (other > 0)
    brake = np.maximum(units * m.brake - movers * m.disturbance - drift, _FLOOR * units * m.brake)
    w1, g1, w2, g2, h0 = _barrier(m, cfg, gap0, rate0, gap_bar, dirn, vel_bar, brake, movers * m.reach * m.accel_max)
    share = own / units
    return w1, -share * g1, w2, -share * g2, h0


def _up(v: np.ndarray, fill: float) -> np.ndarray:
    """``v`` of agent ``f`` moved to agent ``f - 1`` (the last agent gets ``fill``)."""
    out = np.full_like(v, fill)
    out[:, :-1] = v[:, 1:]
    return out


def _velocity_rows(m, cfg, x6, xb, ws, ls) -> None:
    """Velocity boxes (relative degree one): ``|e_k^+| <= V`` per axis, two rows each, for
    ``e = (Lbar x)_f`` (platoon: bound (40), ``V = (g_f + d_f) v_max``; the neighbours' inputs
    taken at their worst, ``beta = d_f ||(B_v S)_k||_1 u_box``) or ``e = v_i`` (servicing)."""
    bv = m.B[3:]
    if m.lbar is not None:
        gd = np.diag(m.lbar)
        e_bar = np.einsum("ij,bjk->bik", m.lbar, xb[..., 3:])
        heard = -(m.lbar - np.diag(gd)).sum(axis=1)
        beta = heard[:, None] * (np.abs(bv @ m.S).sum(axis=1) * m.u_box)[None, :]
        v_lim = gd[:, None] * m.v_max
        gain = gd[:, None, None] * bv[None]
    else:
        e_bar = xb[..., 3:]
        beta = 0.0
        v_lim = m.v_max
        gain = bv[None]
    lim = v_lim * (1.0 - cfg.velocity_margin)     # one decision can always come back inside
    g = np.broadcast_to(gain, (*x6.shape[:2], 3, 3))
    ws.extend([g, -g])
    ls.extend([-lim - e_bar + beta, -lim + e_bar + beta])


def _omega_rows(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Servicing ``|omega_k^+| <= omega_max`` (relative degree one) in action space: the coasting
    ``omega^+`` of the env's attitude step, plus ``dt J_f^-1 F_r diag(u_max) u`` (first order)."""
    j_f, j_l, omega_l, w_max, gain, sub = m.attitude
    w_now = x[..., 10:13]
    _, w_bar = attitude_step(x[..., 6:10], w_now, np.zeros_like(w_now), m.dt, j_f, j_l, omega_l, sub)  # coasting
    lim = w_max * (1.0 - cfg.velocity_margin)
    g = np.broadcast_to(gain, (*x.shape[:2], *gain.shape))
    return np.concatenate([g, -g], axis=2), np.concatenate([-lim - w_bar, -lim + w_bar], axis=2)


# ---------------------------------------------------------------------------------------------
# the filter
# ---------------------------------------------------------------------------------------------
def solve_qp(u_ref: np.ndarray, rows: np.ndarray, lower: np.ndarray, box: float) -> tuple[np.ndarray, int]:
    """``min ||u - u_ref||^2  s.t.  rows u >= lower,  |u| <= box`` with daqp: ``(u, exitflag)``."""
    import daqp

    d = u_ref.shape[0]
    bu = np.concatenate([np.full(d, box), np.full(len(lower), _BIG)])
    bl = np.concatenate([np.full(d, -box), lower])
    x, _, flag, _ = daqp.solve(np.eye(d), -u_ref, np.ascontiguousarray(rows), bu, bl,
                               np.zeros(d + len(lower), dtype=np.int32))
    return np.asarray(x, dtype=float), int(flag)


def filter_actions(m: SafetyModel, cfg: SafetyConfig, x: np.ndarray, t: np.ndarray,
                   actions: np.ndarray) -> tuple[np.ndarray, SafetyRecord]:
    """Safe actions ``(B, M, d)`` and the :class:`SafetyRecord` for states ``x (B, M, >= 6)``
    at times ``t (B,)`` [s] and proposed normalised actions ``(B, M, d)`` (module docstring).

    Pure: reads only its arguments. Inputs are validated (:class:`SafetyError` names the field).
    """
    x, t, a = _check_inputs(m, x, t, actions)
    s = m.S if not m.body_frame else np.einsum("bmij,jk->bmik", quat_to_matrix(x[..., 6:10]), m.S)
    w, lo = constraint_rows(m, cfg, x, t)
    rows = np.einsum("bmki,ij->bmkj", w, s) if s.ndim == 2 else np.einsum("bmki,bmij->bmkj", w, s)
    if m.attitude is not None:
        w_om, lo_om = _omega_rows(m, cfg, x)
        rows, lo = np.concatenate([rows, w_om], axis=2), np.concatenate([lo, lo_om], axis=2)
    kinds = np.asarray(m.kinds, dtype=np.int64)
    bsz, na, d = a.shape
    if not m.n_chain:
        res = _solve_rows(m, rows.reshape(bsz * na, -1, d), lo.reshape(bsz * na, -1), a.reshape(bsz * na, d), kinds)
        out, safe, infeasible, active = (v.reshape(bsz, na, *v.shape[1:]) for v in res)
    else:   # down the chain: a chaser's rows hold its target's filtered acceleration
        slots = m.budget[0].shape[1]
        idx = np.r_[slots - m.n_chain:slots, 2 * slots - m.n_chain:2 * slots]
        out, safe = np.empty_like(a), np.empty((bsz, na), dtype=bool)
        infeasible, active = np.empty((bsz, na), dtype=bool), np.empty((bsz, na), dtype=np.int64)
        acc_prev = np.zeros((bsz, 3))                      # the passive leader's
        for f in range(na):
            lo_f = lo[:, f].copy()
            lo_f[:, idx] += np.einsum("bki,bi->bk", w[:, f, idx], acc_prev)
            out[:, f], safe[:, f], infeasible[:, f], active[:, f] = _solve_rows(m, rows[:, f], lo_f, a[:, f], kinds)
            eff = _effective(m, out[:, f])
            acc_prev = eff @ s.T if s.ndim == 2 else np.einsum("bij,bj->bi", s[:, f], eff)
    delta = np.linalg.norm(_effective(m, out) - _effective(m, a), axis=-1)   # of the applied actions
    return out, SafetyRecord(~safe, delta, infeasible, active)


def _solve_rows(m: SafetyModel, rows: np.ndarray, lo: np.ndarray, a: np.ndarray,
                kinds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Filter ``n`` agents' proposals ``a (n, d)`` against their rows ``rows u >= lo``
    ``(n, K, d)``, ``(n, K)``: ``(out, safe, infeasible, active)``; a safe proposal is returned
    as it is (clipped to the action box, as the env would: a filtered action never leaves it), an
    unsafe one is replaced by the QP's point or the backup action."""
    ref = _effective(m, a)
    safe = (np.einsum("nkj,nj->nk", rows, ref) - lo).min(axis=-1, initial=np.inf) >= -_ROW_TOL
    out = np.clip(a, -1.0, 1.0)
    infeasible = np.zeros(len(a), dtype=bool)
    active = np.full(len(a), -1, dtype=np.int64)
    reach = -m.u_box * math.sqrt(m.action_dim) - 1e-9      # (normalised) rows below this never bind
    for i in np.flatnonzero(~safe):
        scale = np.linalg.norm(rows[i], axis=-1)
        tiny = scale < 1e-12
        lo_i = np.where(tiny, np.where(lo[i] <= 0.0, -_BIG, _BIG), lo[i] / np.where(tiny, 1.0, scale))
        rows_i = np.where(tiny[:, None], 0.0, rows[i] / np.where(tiny, 1.0, scale)[:, None])
        keep = lo_i > reach
        u = _guarded_qp(ref[i], rows_i[keep], lo_i[keep], m.u_box)
        if u is None:
            u, k = _backup(m, rows_i[keep], lo_i[keep], rows_i[keep] @ ref[i] - lo_i[keep])
            infeasible[i] = True
            active[i] = kinds[keep][k]
        else:
            active[i] = kinds[int(np.argmin(rows_i @ u - lo_i))]
        out[i] = u
    return out, safe, infeasible, active


def _effective(m: SafetyModel, a: np.ndarray) -> np.ndarray:
    """The action the env applies: clipped to the box (``"norm"``: then into the unit ball)."""
    ref = np.clip(a, -1.0, 1.0)
    if m.norm_mode:
        ref = ref / np.maximum(1.0, np.linalg.norm(ref, axis=-1, keepdims=True))
    return ref


def _guarded_qp(ref: np.ndarray, rows: np.ndarray, lower: np.ndarray, box: float) -> np.ndarray | None:
    """The QP's point, or ``None`` when it must not be used (any failure of :func:`solve_qp`)."""
    try:
        u, flag = solve_qp(ref, rows, lower, box)
    except Exception:  # noqa: BLE001 - any solver fault gives the backup, never a crash
        return None
    if (flag not in (1, 2) or u.shape != ref.shape or not np.all(np.isfinite(u))
            or np.any(np.abs(u) > box + _QP_TOL) or (len(lower) and np.min(rows @ u - lower) < -_QP_TOL)):
        return None
    return np.clip(u, -box, box)


def _backup(m: SafetyModel, rows: np.ndarray, lower: np.ndarray, slack: np.ndarray) -> tuple[np.ndarray, int]:
    """Maximum braking when the QP fails: the action that maximises the smallest row slack,
    ``argmax_u min_k (rows_k u - lower_k)`` over the action box (a daqp QP in ``(u, t)``), or, if
    that fails too, full thrust along the row the proposal breaks most. Returns the action and
    the index of the row it brakes for (the least satisfied one)."""
    d = rows.shape[1]
    k = int(np.argmin(slack))
    try:
        import daqp

        a = np.hstack([rows, -np.ones((len(rows), 1))])
        bu = np.r_[np.full(d, m.u_box), _BIG, np.full(len(rows), _BIG)]
        bl = np.r_[np.full(d, -m.u_box), -_BIG, lower]
        h = np.eye(d + 1) * 1e-6
        z, _, flag, _ = daqp.solve(h, np.r_[np.zeros(d), -1.0], a, bu, bl, np.zeros(len(bu), dtype=np.int32))
        u = np.asarray(z, dtype=float)[:d]
        if flag in (1, 2) and np.all(np.isfinite(u)):
            u = np.clip(u, -m.u_box, m.u_box)
            if m.norm_mode:
                u = u / max(1.0, float(np.linalg.norm(u)))
            return u, int(np.argmin(rows @ u - lower))
    except Exception:  # noqa: BLE001 - the backup never raises
        pass
    row = rows[k]
    if m.norm_mode:
        nrm = float(np.linalg.norm(row))
        return (row / nrm if nrm > 0 else np.zeros_like(row)), k
    return np.sign(row) * m.u_box, k


def _real_array(name: str, value: Any) -> np.ndarray:
    """``value`` as a float array; text, masked, complex, bool and object input is a
    :class:`SafetyTypeError` naming ``name`` (never a silent cast that drops a mask or an imaginary
    part)."""
    if isinstance(value, (str, bytes)) or np.ma.isMaskedArray(value) or np.iscomplexobj(value):
        raise SafetyTypeError(f"safety filter: {name} must be a real array, got "
                              f"{type(value).__name__}{' (complex)' if np.iscomplexobj(value) else ''}")
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "fiu":
            raise TypeError
        return arr.astype(float, copy=False)
    except (TypeError, ValueError, OverflowError):
        kind = getattr(getattr(value, "dtype", None), "name", type(value).__name__)
        raise SafetyTypeError(f"safety filter: {name} must be a real array, got {kind}") from None


def _check_inputs(m: SafetyModel, x: Any, t: Any, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    arrays = []
    for name, value, ndim in (("state", x, 3), ("t", t, 1), ("actions", actions, 3)):
        arr = _real_array(name, value)
        if arr.ndim != ndim:
            raise SafetyError(f"safety filter: {name} must have {ndim} dimensions, got shape {arr.shape}")
        if not all_finite(arr):
            raise SafetyError(f"safety filter: {name} has non-finite entries (NaN or inf)")
        arrays.append(arr)
    x, t, a = arrays
    b, na = a.shape[:2]
    if a.shape != (b, m.n_agents, m.action_dim):
        raise SafetyError(f"safety filter: actions must have shape (copies, {m.n_agents}, {m.action_dim}), "
                          f"got {a.shape}")
    if x.shape[:2] != (b, m.n_agents) or not m.state_dim_ok(x.shape[2]):
        raise SafetyError(f"safety filter: state must have shape ({b}, {m.n_agents}, >= 6), got {x.shape}")
    if t.shape != (b,):
        raise SafetyError(f"safety filter: t must have shape ({b},), got {t.shape}")
    return x, t, a


class SafetyFilter:
    """The filter bound to an env, a ``make_vec`` batch or a batched core: :meth:`filter` reads
    its current state.

    Args:
        target: ``satenv.make(...)`` env, ``satenv.make_vec(...)`` batch or a ``BatchedCore``.
        config: a :class:`SafetyConfig`; ``options`` replace its fields (unknown ones raise).
    """

    def __init__(self, target: Any, config: SafetyConfig | None = None, **options: Any) -> None:
        self.config = SafetyConfig.from_options(config, **options)
        self.core = _core_of(target)
        self.model = safety_model(self.core)
        if not _has_position_rows(self.model):
            warnings.warn(f"safety filter on {self.model.env_id} ({getattr(self.core.scenario, 'name', '')}): the "
                          "scenario has no keep-out distance (collision_distance = 0), so the filter enforces "
                          "no separation, only the thrust box; give the env a collision_distance [m] "
                          "(e.g. satenv.make('formation_v0', collision_distance=5.0, ...))", SafetyWarning,
                          stacklevel=2)

    def filter(self, actions: Any) -> tuple[np.ndarray, SafetyRecord]:
        """Safe actions ``(B, M, d)`` (or ``(M, d)`` for ``(M, d)`` input) and the record."""
        a = _real_array("actions", actions)
        single = a.ndim == 2
        x = self.core.x
        copies = len(x)
        if a.ndim == 3 and len(a) != copies:
            raise SafetyError(f"safety filter: actions has {len(a)} copies (shape {a.shape}) but the env it "
                              f"filters for has {copies}; expected shape ({copies}, {self.model.n_agents}, "
                              f"{self.model.action_dim})" + (f" or ({self.model.n_agents}, {self.model.action_dim})"
                                                              if copies == 1 else ""))
        t = self.core.t * float(self.core.scenario.dt)
        out, rec = filter_actions(self.model, self.config, x, t, a[None] if single else a)
        return (out[0], rec) if single else (out, rec)


class Shield:
    """A policy filtered by :class:`SafetyFilter` for the env it acts on (same ``reset`` /
    ``act`` / ``info`` as any policy). It reads the env's true state (privileged, like the
    scripted baselines). An action that is safe is returned as the policy gave it (the same
    object); ``info`` adds ``safety_interventions``, ``safety_delta`` (sum of ``|du|``),
    ``safety_infeasible`` (agent-steps) and ``safety_steps`` since :meth:`reset`, and
    ``safety_record`` (the last :class:`SafetyRecord`).
    """

    name = "shield"

    def __init__(self, env: Any, policy: Any, config: SafetyConfig | None = None, **options: Any) -> None:
        if not (callable(getattr(policy, "act", None)) and callable(getattr(policy, "reset", None))):
            raise SafetyTypeError(f"shield: policy must have reset() and act(observations), got {type(policy).__name__}")
        self.filter = SafetyFilter(env, config, **options)
        self.env = env
        self.policy = policy
        self.agents = list(env.possible_agents)
        self._counts = _zero_counts()

    @property
    def info(self) -> dict[str, Any]:
        return {**getattr(self.policy, "info", {}), **self._counts}

    def __getattr__(self, name: str) -> Any:
        """Anything else is the wrapped policy's (e.g. a learned policy's ``obs_shape``)."""
        if name in ("policy", "filter", "_counts"):
            raise AttributeError(name)
        return getattr(self.policy, name)

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)
        self._counts = _zero_counts()

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        proposed = self.policy.act(observations)
        live = [a for a in self.agents if a in proposed]
        if len(live) != len(self.agents):   # an ended episode: nothing to filter
            return proposed
        safe, rec = self.filter.filter(np.stack([_real_array(f"action of {a}", proposed[a]) for a in live]))
        c = self._counts
        c["safety_interventions"] += int(rec.intervened.sum())
        c["safety_delta"] += float(rec.delta.sum())
        c["safety_infeasible"] += int(rec.infeasible.sum())
        c["safety_steps"] += 1
        c["safety_record"] = rec
        return {a: (safe[i].astype(np.float32) if rec.intervened[0, i] else proposed[a])
                for i, a in enumerate(live)}


def _zero_counts() -> dict[str, Any]:
    return {"safety_interventions": 0, "safety_delta": 0.0, "safety_infeasible": 0, "safety_steps": 0,
            "safety_record": None}


def shield(policy: Any, env: Any, config: SafetyConfig | None = None, **options: Any) -> Shield:
    """``policy`` filtered for ``env``: a :class:`Shield`."""
    return Shield(env, policy, config, **options)


# ---------------------------------------------------------------------------------------------
# filtered envs (safety_filter=True on satenv.make / make_vec / satenv.torchrl.make_env)
# ---------------------------------------------------------------------------------------------
def _filtered_class(cls: type) -> type:
    """The subclass of a satenv env class whose ``step`` filters the actions first: per-agent
    infos get the record (``safety_*``), rewards ``- penalty * |du|``."""

    def step(self, actions):
        if not self.agents:
            return cls.step(self, actions)
        safe, rec = self.safety.filter(self._action_array(actions))
        obs, rewards, terms, truncs, infos = cls.step(self, dict(zip(self.possible_agents, safe, strict=True)))
        pen = self.safety.config.penalty
        extra = {k: v[0].tolist() for k, v in rec.infos().items()}
        for i, agent in enumerate(self.possible_agents):
            infos[agent].update({k: v[i] for k, v in extra.items()})
            if pen:
                rewards[agent] -= pen * extra["safety_delta"][i]
        return obs, rewards, terms, truncs, infos

    if cls not in _FILTERED:
        _FILTERED[cls] = type(f"Filtered{cls.__name__}", (cls,), {"step": step, "__doc__": cls.__doc__,
                                                                  "__module__": __name__})
    return _FILTERED[cls]


_FILTERED: dict[type, type] = {}


def __getattr__(name: str) -> type:
    """``satenv.safety.Filtered<EnvClass>`` (the class :func:`filtered_env` gives an env), so that a
    filtered env pickles by reference (e.g. into a Gymnasium ``AsyncVectorEnv`` worker)."""
    if name.startswith("Filtered"):
        import importlib

        import satenv

        for env_id in satenv.ENV_IDS:
            cls = getattr(importlib.import_module(f"satenv.envs.{env_id}"), name[len("Filtered"):], None)
            if isinstance(cls, type):
                return _filtered_class(cls)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def filtered_env(env: Any, config: SafetyConfig | None = None, **options: Any) -> Any:
    """``env`` (a ``satenv.make`` env) with its actions filtered at every ``step`` (the same
    object, its class a filtered subclass: every attribute and check of the env still holds)."""
    filt = SafetyFilter(env, config, **options)
    env.__class__ = _filtered_class(type(env))
    env.safety = filt
    return env


def safety_config(value: Any) -> SafetyConfig:
    """The config of a ``safety_filter=`` argument: ``True`` (defaults) or a :class:`SafetyConfig`."""
    if value is True:
        return SafetyConfig()
    if isinstance(value, SafetyConfig):
        return value
    raise SafetyTypeError(f"safety_filter must be True, False or a satenv.safety.SafetyConfig, got {value!r}")
