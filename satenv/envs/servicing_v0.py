"""servicing_v0 — 6-DOF on-orbit servicing with attitude (pereira2022 §4, §5.2).

``satenv.envs.servicing_v0.parallel_env(**kwargs)`` returns a PettingZoo ``ParallelEnv``;
``env(**kwargs)`` the AEC version; ``raw_env(**kwargs)`` the raw AEC env (no wrappers), as
PettingZoo names it.

M spacecraft ``sat_1 … sat_M`` move around a passive object at the origin of the LVLH frame
(x radial, y along-track, z orbit normal; circular orbit of radius ``orbit_radius``), reach
re-planned waypoints (eq. 50) and point their body z axis at the object (eq. 43-49), without
entering the keep-out sphere (eq. 40) or each other's (eq. 41).

Dynamics (eq. 35), per spacecraft, state ``x = [p (3), v (3), q (4), omega (3)]``:

* translation — ``satenv.dynamics.RelativeModel(dynamics, ...)`` (default ``"nonlinear"``: the
  two-body relative motion of eq. 2-5, exact ECI propagation), driven by the LVLH acceleration
  ``F_t u`` (``thrust_frame="lvlh"``, eq. 35 as written) or ``R(q) F_t u`` (``"body"``:
  body-fixed thrusters), held over each step;
* attitude — quaternion kinematics (eq. 10) and relative rotational dynamics (eq. 11-17) of
  :mod:`satenv.dynamics.attitude` about the LVLH-fixed object (``omega_lb = [0, 0, n]``), body
  torque ``F_r u``; RK4, the quaternion renormalised after every integration step;
* six inputs ``u`` (eq. 36, ``F_t``, ``F_r`` from ``dimensions``), per-input limits ``u_max``
  (the paper's u_max, "per unit mass": ``F_t u`` is an acceleration [m/s^2] and ``F_r u`` a
  torque [N m], i.e. m_f = 1 kg as in eq. 35-36; one number or six).

Arguments (keywords; all optional)
----------------------------------
``preset``        ``"pereira2022"`` (default, §5.2: 2 spacecraft, J_f, J_l = 10 I, L = [2, 2, 2] m,
                  u_max = 3, v_max = 5 m/s, omega_max = 0.7 rad/s, r_sigma = 12 m, r_s = 3 m,
                  p1(0) = [0, -15, 0], p2(0) = [0, 0, -15], q(0), omega(0), waypoints of eq. 50
                  switching at t = 40 s and 80 s, T_s = 0.1 s, ||r_l|| = 6621 km, 1200 steps).
                  ``"pereira2022-rl"``: the same with both starts at 20 m, 5 m outside the keep-out
                  sphere (the paper's start touches it: unthrusted episodes end at step 4).
``render_mode``   ``None``, ``"rgb_array"`` or ``"human"`` (positions, trails, the object and
                  keep-out spheres, waypoints and each body's pointing axis).
any field of :class:`satenv.scenarios.servicing.ServicingScenario` overrides the preset, e.g.
``waypoints``, ``waypoint_times``, ``max_steps``, ``dt``, ``u_max``, ``thrust_frame="body"``,
``dynamics="cw"``, ``randomize=True``, ``terminate_on_collision=False``, ``reward_scale``,
``success_tol`` (0.5 m), ``collision_voids_success``.
Unknown keywords raise ``SatenvError`` (a ``ValueError``).
``reset(seed=..., options={"initial_state": array (M, 13)})`` starts from a given state (the
quaternions are normalised; a zero quaternion is rejected).

Spaces (per agent; float32)
---------------------------
Action ``Box(-1, 1, (6,))``: the six inputs ``u = a * u_max`` (per-input box).

Observation ``Box(-inf, inf, (16 + 6 (M - 1),))``, with ``L = r_sigma + r_s``:

========  ===========================================================================
entries   meaning
========  ===========================================================================
0–2       position error to the current waypoint ``(p - p_d) / L``
3–5       velocity error ``(v - v_d) / v_max``
6–9       quaternion error ``q_tilde = q (x) q_d_bar`` (eta_tilde >= 0), q_d the pointing frame
10–12     angular-velocity error ``(omega - omega_d) / omega_max`` (eq. 48-49)
13–15     own position ``p / L`` (the object is at the origin)
16 …      per other spacecraft j (ascending index, self skipped):
          ``(p_j - p) / L`` and ``(v_j - v) / v_max``
========  ===========================================================================

``state()`` returns ``[x_1 … x_M (13 M), p_d,1 … p_d,M (3 M), t]`` (see
:func:`unpack_global_state`).

Desired attitude (eq. 43-49): ``k_d`` points from the spacecraft to ``pointing_target`` (the
object's centre by default), ``j_d = k_d x a / |k_d x a|`` with the scenario's
``pointing_reference`` ``a`` (eq. 44's ``a = p`` is degenerate for a target at the centre),
``i_d = j_d x k_d``; ``q_d`` from ``R_d = [i_d j_d k_d]``; ``omega_d`` from eq. 45-49.

Reward (per spacecraft, the stage cost of eq. 39 after the step)
----------------------------------------------------------------
``r = -l / reward_scale - collision_penalty * collision - violation_penalty * violations``,
``l = e_p^T Q_p e_p + e_v^T Q_v e_v + [1 - eta_tilde, eps_tilde]^T Q_q [.] + e_w^T Q_w e_w
+ u^T H u`` with the §5.2 weights (``position_weight`` …, ``input_weight``).

``reward="training"`` (the default of a training task's env, :mod:`satenv.tasks`) replaces this
with the training reward of :mod:`satenv.rewards` (progress toward the target, a bonus inside the
success tolerance, a success bonus, penalties for collision, violation and leaving the region);
``reward="paper"`` (the default) keeps it. Under either, the infos carry ``safety_cost`` (1.0 on
a collision or a hard-bound violation of the agent in the step, else 0.0).

Termination / truncation
------------------------
Terminated (all agents) on a collision — a spacecraft inside the keep-out sphere
``|p| < r_sigma + r_s`` (eq. 40) or two spacecraft closer than ``r_i + r_j`` (eq. 41), both up
to ``contact_tolerance`` (1e-6 m: the §5.2 initial positions and waypoints lie exactly on the
keep-out sphere, so a coasting spacecraft there collides within about a second) — when
``terminate_on_collision`` (default), or when a spacecraft is farther than ``max_distance``.
Truncated at ``max_steps``.

Infos (per agent, SI units)
---------------------------
``state`` (13,), ``accel`` (3,) LVLH acceleration applied [m/s^2] (mean over the step),
``delta_v`` ``|accel| dt`` [m/s], ``tracking_error`` (3,) ``p - p_d``, ``min_separation``
[m] centre distance to the nearest other body (object centre or spacecraft), ``collision``,
``violations`` (int: eq. 40 + eq. 41 per other spacecraft + one per velocity axis with
``|v_i| > v_max`` + one per axis with ``|omega_i| > omega_max``), ``cost`` = ``violations``
(float); and ``thrust`` (6,) ``u``, ``torque`` (3,) [N m], ``waypoint`` (3,), ``phase``,
``dist_object`` [m], ``dist_other`` [m] (inf when alone), ``pointing_error`` [rad] (body z vs
line of sight), ``attitude_error`` [rad] (full rotation to q_d), ``quaternion_error`` (4,),
``omega_error`` (3,) [rad/s].

Version History
---------------
* v0: initial release.
* v0 (unreleased changes, still v0): one env surface across satenv — ``n_steps`` renamed
  ``max_steps``, ``thrust_limit`` renamed ``u_max`` (one or six per-input limits); new
  ``success_tol`` (0.5 m) and ``collision_voids_success``; ``state_space``, ``observation_spaces``
  / ``action_spaces`` dicts, ``metadata["render_fps"]`` from ``dt``; ``raw_env`` is the raw AEC
  env; base class ``SatParallelEnv`` (was ``FormationEnv``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pettingzoo import AECEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from satenv.dynamics import Orbit, RelativeModel, delta_v, saturate_box
from satenv.dynamics.attitude import (
    attitude_constants,
    attitude_kernel,
    attitude_step,
    compiled_attitude_step,
    desired_angular_velocity,
    matrix_to_quat,
    pointing_error,
    pointing_frame,
    pointing_rate,
    quat_error,
    quat_normalize,
    quat_to_matrix,
    thruster_matrices,
)
from satenv.envs.base import BatchedCore, SatenvError, SatParallelEnv, StepResult, resolve_preset
from satenv.scenarios.servicing import (
    PRESETS,
    ServicingScenario,
    resolve_scenario,
    sample_initial_state,
)

__all__ = ["ServicingCore", "ServicingEnv", "env", "parallel_env", "raw_env", "STATE_DIM",
           "unpack_global_state", "attitude_reference", "stage_cost"]

STATE_DIM = 13
"""Per-agent true state ``[p (3), v (3), q (4), omega (3)]``."""


def unpack_global_state(state: np.ndarray, n_agents: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Split ``env.state()`` into ``(x (M, 13), waypoints (M, 3), t [s])``."""
    state = np.asarray(state, dtype=float)
    m = int(n_agents)
    if state.shape != (16 * m + 1,):
        raise ValueError(f"servicing global state must have shape ({16 * m + 1},) for {m} agents, "
                         f"got {state.shape}")
    return (state[: 13 * m].reshape(m, 13), state[13 * m: 16 * m].reshape(m, 3), float(state[-1]))


def attitude_reference(scenario: ServicingScenario, p: np.ndarray, v: np.ndarray,
                       q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Desired frame, quaternion and relative angular velocity (eq. 43-49) at ``(p, v, q)``.

    Returns ``(R_d (..., 3, 3), q_d (..., 4), omega_d (..., 3))``; ``q_d`` is sign-aligned with
    ``q`` (``q . q_d >= 0``).
    """
    r_d = pointing_frame(p, scenario.pointing_target, scenario.pointing_reference)
    q_d = matrix_to_quat(r_d)
    q_d = q_d * np.where(np.sum(q_d * q, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    w_frame = pointing_rate(p, v, r_d, scenario.pointing_target)
    w_d = desired_angular_velocity(q, r_d, w_frame, scenario.mean_motion)
    return r_d, q_d, w_d


def stage_cost(scenario: ServicingScenario, e_p, e_v, q_err, e_w, u) -> np.ndarray:
    """Eq. 39's stage cost with the scenario's weights (batched over leading axes)."""
    qe = np.concatenate([1.0 - q_err[..., :1], q_err[..., 1:]], axis=-1)
    return (np.sum(np.asarray(scenario.position_weight) * e_p**2, -1)
            + np.sum(np.asarray(scenario.velocity_weight) * e_v**2, -1)
            + np.sum(np.asarray(scenario.quaternion_weight) * qe**2, -1)
            + np.sum(np.asarray(scenario.omega_weight) * e_w**2, -1)
            + np.sum(np.asarray(scenario.input_weight) * u**2, -1))


POINTING_MIN_SINE = 0.1
"""``min_sine`` of :func:`satenv.dynamics.attitude.pointing_frame` as the servicing core uses it
(its default)."""


def _kernel_module(scenario: ServicingScenario):
    """:mod:`satenv.envs._servicing_kernel`, or ``None`` (no numba, or eq. 44's ``a = p`` roll
    reference, which the kernel does not implement)."""
    if scenario.pointing_reference is None:
        return None
    try:
        from satenv.envs import _servicing_kernel
    except ImportError:
        return None
    return _servicing_kernel


def _reference_kernel(scenario: ServicingScenario):
    """:func:`satenv.envs._servicing_kernel.attitude_features`, or ``None`` (see :func:`_kernel_module`)."""
    module = _kernel_module(scenario)
    return None if module is None else module.attitude_features


class ServicingCore(BatchedCore):
    """Batched servicing physics and task logic (``B`` copies, ``M`` spacecraft)."""

    state_dim = STATE_DIM
    action_dim = 6

    def __init__(self, scenario: ServicingScenario, batch: int = 1) -> None:
        super().__init__(scenario, batch)
        m = self.n_agents
        sc = scenario
        self.obs_dim = 16 + 6 * (m - 1)
        self.orbit = Orbit.circular(sc.orbit_radius, mu=sc.mu)
        self.h = sc.dt / sc.substeps
        self.model = RelativeModel(sc.dynamics, self.orbit, self.h)
        self.f_t, self.f_r = thruster_matrices(sc.dimensions)
        self.j_f = np.array(sc.inertia)
        self.j_l = np.array(sc.object_inertia)
        self.omega_l = np.array([0.0, 0.0, sc.mean_motion])
        self._att_kernel = attitude_kernel("auto", self.omega_l)   # compiled step (None: numpy)
        self._att_constants = attitude_constants(self.j_f, self.j_l, self.omega_l)
        self._ref_kernel = _reference_kernel(sc)          # compiled attitude reference (None: numpy)
        self._pointing = (np.asarray(sc.pointing_target, dtype=float),
                          np.asarray(sc.pointing_reference if sc.pointing_reference is not None else (0, 0, 0),
                                     dtype=float))
        self.waypoints = sc.waypoint_array()
        self._switch_steps = sc.switch_steps
        self.u_max = np.asarray(sc.u_max)
        self.scale_p = sc.keepout_radius
        others = [[j for j in range(m) if j != i] for i in range(m)]
        self.others = np.array(others, dtype=np.int64).reshape(m, max(m - 1, 0))
        self.x = np.tile(sc.initial_array(), (self.batch, 1, 1))
        self.chief = np.tile(self.model.initial_chief(), (self.batch, 1))
        self._feat: dict[str, np.ndarray] = self._features(self.x, self.t)
        self._fused = self._fused_constants()

    def _fused_constants(self) -> tuple | None:
        """The compiled step's kernel and constants (:func:`satenv.envs._servicing_kernel.step`),
        or ``None`` when it does not apply: no numba, no compiled truth or attitude kernel (e.g.
        ``dynamics="cw"``), or body-fixed thrusters (their force turns with the attitude inside
        the step)."""
        sc = self.scenario
        module = _kernel_module(sc)
        truth = self.model._cache.get("kernel")
        if (module is None or truth is None or self.model.integrator != "rk4" or self._att_kernel is None
                or self._ref_kernel is None or sc.thrust_frame != "lvlh"):
            return None
        run, params = truth
        if run is not module.truth_propagate:
            return None
        att = np.array([sc.substeps, self.h, self.model.substeps, self.model.dt / self.model.substeps,
                        sc.mean_motion, POINTING_MIN_SINE])
        task = np.array([*np.asarray(sc.desired_velocity, dtype=float), sc.keepout_radius - sc.contact_tolerance,
                         sc.separation_radius - sc.contact_tolerance, sc.v_max, sc.omega_max, sc.max_distance,
                         float(sc.terminate_on_collision), sc.reward_scale, sc.collision_penalty,
                         sc.violation_penalty, sc.dt, self.scale_p])
        weights = np.concatenate([np.broadcast_to(np.asarray(w, dtype=float), (k,)) for w, k in (
            (sc.position_weight, 3), (sc.velocity_weight, 3), (sc.quaternion_weight, 4), (sc.omega_weight, 3),
            (sc.input_weight, 6))])
        phases = (np.ascontiguousarray(self.waypoints), np.asarray(self._switch_steps, dtype=np.int64))
        return module.step, self.model, (params, att, *self._att_constants, *self._pointing, task, weights, *phases)

    # ------------------------------------------------------------------ episode
    def sample_initial_state(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.scenario.randomize:
            return np.stack([sample_initial_state(self.scenario, rng) for _ in range(n)])
        return np.tile(self.scenario.initial_array(), (n, 1, 1))

    def reset(self, x0, idx=None, rng=None):
        x0 = np.array(x0, dtype=float)
        x0[..., 6:10] = quat_normalize(x0[..., 6:10])
        sel = slice(None) if idx is None else idx
        self.x[sel] = x0
        self.t[sel] = 0
        self.chief[sel] = self.model.initial_chief()
        self._feat = self._features(self.x, self.t)
        zeros6 = np.zeros((len(x0), self.n_agents, 6))
        return self._info(self._subset(self._feat, sel), self.x[sel], zeros6, np.zeros(zeros6.shape[:-1] + (3,)))

    @staticmethod
    def _subset(feat: dict[str, np.ndarray], sel) -> dict[str, np.ndarray]:
        return {k: v[sel] for k, v in feat.items()}

    def step(self, accel, rng=None) -> StepResult:
        """Advance one T_s under the six inputs ``(B, M, 6)`` (clipped to the per-input box)."""
        sc = self.scenario
        u = saturate_box(np.asarray(accel, dtype=float), self.u_max)
        force = u @ self.f_t.T
        torque = u @ self.f_r.T
        if self._fused_applies():
            return self._step_fused(u, force, torque, observe=False)[0]
        x6, q, w = self.x[..., :6], self.x[..., 6:10], self.x[..., 10:]
        acc_sum = np.zeros_like(force)
        for _ in range(sc.substeps):
            a = force if sc.thrust_frame == "lvlh" else np.einsum("...ij,...j->...i", quat_to_matrix(q), force)
            acc_sum += a
            x6, self.chief = self.model.step(x6, a, self.chief)
            if self._att_kernel is not None:
                q, w = compiled_attitude_step(self._att_kernel, q, w, torque, self.h, 1, self._att_constants)
            else:
                q, w = attitude_step(q, w, torque, self.h, self.j_f, self.j_l, self.omega_l)
        self.x = np.concatenate([x6, q, w], axis=-1)
        self.t += 1
        self._feat = self._features(self.x, self.t)
        accel_lvlh = acc_sum / sc.substeps
        info = self._info(self._feat, self.x, u, accel_lvlh)
        stage = stage_cost(sc, self._feat["e_p"], self._feat["e_v"], self._feat["q_err"],
                           self._feat["e_w"], u)
        rewards = (-stage / sc.reward_scale - sc.collision_penalty * info["collision"]
                   - sc.violation_penalty * info["violations"])
        terminated = (self._feat["d_obj"] > sc.max_distance).any(axis=-1)
        if sc.terminate_on_collision:
            terminated |= info["collision"].any(axis=-1)
        return StepResult(rewards, terminated, info)

    def step_observe(self, accel, rng=None) -> tuple[StepResult, np.ndarray]:
        """:meth:`step` and :meth:`observe` (one compiled pass when :meth:`_step_fused` applies)."""
        if not self._fused_applies():
            return super().step_observe(accel, rng)
        u = saturate_box(np.asarray(accel, dtype=float), self.u_max)
        return self._step_fused(u, u @ self.f_t.T, u @ self.f_r.T, observe=True)

    def _fused_applies(self) -> bool:
        fused = self._fused
        return (fused is not None and fused[1] is self.model and self._att_kernel is not None
                and self._ref_kernel is not None)

    def _step_fused(self, u: np.ndarray, force: np.ndarray, torque: np.ndarray,
                    observe: bool) -> tuple[StepResult, np.ndarray]:
        """:meth:`step` (LVLH thrust) by one call of :func:`satenv.envs._servicing_kernel.step`:
        the substeps, the features, infos, rewards, terminations, the finiteness check and (when
        ``observe``) the observations; the same numbers as the numpy glue around the compiled
        truth, attitude and reference kernels (``tests/test_servicing_kernel.py``)."""
        b, m = self.batch, self.n_agents
        bm = (b, m)
        x, chief = np.empty_like(self.x), np.empty_like(self.chief)
        f = {"waypoint": np.empty((b, m, 3)), "phase": np.empty(bm, np.int64), "e_p": np.empty((b, m, 3)),
             "e_v": np.empty((b, m, 3)), "q_d": np.empty((b, m, 4)), "q_err": np.empty((b, m, 4)),
             "w_d": np.empty((b, m, 3)), "e_w": np.empty((b, m, 3)), "d_obj": np.empty(bm),
             "dist": np.empty((b, m, m)), "pointing": np.empty(bm)}
        state, accel, dv, min_sep = np.empty_like(self.x), np.empty((b, m, 3)), np.empty(bm), np.empty(bm)
        collision, viol, cost = np.empty(bm, bool), np.empty(bm, np.int64), np.empty(bm)
        d_other, eta, rewards = np.empty(bm), np.empty(bm), np.empty(bm)
        terminated, finite = np.empty(b, bool), np.empty(b, bool)
        obs = np.empty((b, m, self.obs_dim) if observe else (0, m, self.obs_dim), np.float32)
        kernel, _, constants = self._fused
        code = kernel(self.x, self.chief, force, torque, u, self.t + 1, *constants, x, chief, state, accel, dv,
                      f["e_p"], min_sep, collision, viol, cost, f["waypoint"], f["phase"], f["d_obj"], d_other,
                      f["pointing"], eta, f["q_err"], f["e_w"], f["e_v"], f["q_d"], f["w_d"], f["dist"], rewards,
                      terminated, finite, obs)
        if code == 1:
            raise ValueError("cannot normalise a zero quaternion; a unit quaternion [eta, ex, ey, ez] "
                             "is needed (the attitude step reached a zero-norm quaternion)")
        self.x, self.chief = x, chief
        self.t += 1
        self._feat = f
        if code == 2:
            raise ValueError("pointing_frame: the spacecraft position coincides with the target point; "
                             "the pointing direction is undefined")
        att = np.arccos(eta)
        att *= 2.0
        # the infos share the feature arrays (the core never writes into either)
        info = {"state": state, "accel": accel, "delta_v": dv, "tracking_error": f["e_p"], "min_separation": min_sep,
                "collision": collision, "violations": viol, "cost": cost, "thrust": u, "torque": torque,
                "waypoint": f["waypoint"], "phase": f["phase"], "dist_object": f["d_obj"], "dist_other": d_other,
                "pointing_error": f["pointing"], "attitude_error": att, "quaternion_error": f["q_err"],
                "omega_error": f["e_w"]}
        return StepResult(rewards, terminated, info, finite), obs

    # ------------------------------------------------------------------ quantities
    def _features(self, x: np.ndarray, t: np.ndarray) -> dict[str, np.ndarray]:
        sc = self.scenario
        p, v, q, w = x[..., :3], x[..., 3:6], x[..., 6:10], x[..., 10:]
        phase = (t[..., None] > self._switch_steps).sum(axis=-1)           # sc.phase(t)
        wp = self.waypoints[phase]                                        # (B, M, 3)
        if self._ref_kernel is not None:
            q_d, w_d, q_err, pointing = self._attitude_features(x)
        else:
            _, q_d, w_d = attitude_reference(sc, p, v, q)
            q_err = quat_error(q, q_d)
            pointing = pointing_error(q, p, sc.pointing_target)
        d_obj = np.linalg.norm(p, axis=-1)
        m = self.n_agents
        dist = np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
        dist[:, np.arange(m), np.arange(m)] = np.inf
        return {"waypoint": wp, "phase": np.broadcast_to(phase[:, None], d_obj.shape),
                "e_p": p - wp, "e_v": v - np.asarray(sc.desired_velocity), "q_d": q_d,
                "q_err": q_err, "w_d": w_d, "e_w": w - w_d, "d_obj": d_obj, "dist": dist,
                "pointing": pointing}

    def _attitude_features(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(q_d, w_d, q_err, pointing error)`` by the compiled kernel (the numpy functions of
        :func:`_features` are the reference, ``tests/test_servicing_kernel.py``)."""
        sc = self.scenario
        lead = x.shape[:-1]
        q_d, q_err = np.empty((*lead, 4)), np.empty((*lead, 4))
        w_d, pointing = np.empty((*lead, 3)), np.empty(lead)
        xs = np.ascontiguousarray(x, dtype=float)
        bad = self._ref_kernel(xs, self._pointing[0], self._pointing[1], sc.mean_motion, POINTING_MIN_SINE,
                               q_d, w_d, q_err, pointing)
        if bad:
            raise ValueError("pointing_frame: the spacecraft position coincides with the target point; "
                             "the pointing direction is undefined")
        return q_d, w_d, q_err, pointing

    def _info(self, f: dict[str, np.ndarray], x: np.ndarray, u: np.ndarray,
              accel: np.ndarray) -> dict[str, np.ndarray]:
        sc = self.scenario
        d_other = f["dist"].min(axis=-1) if self.n_agents > 1 else np.full(f["d_obj"].shape, np.inf)
        keepout = f["d_obj"] < sc.keepout_radius - sc.contact_tolerance
        pair = (f["dist"] < sc.separation_radius - sc.contact_tolerance).sum(axis=-1)
        viol = (keepout.astype(np.int64) + pair
                + (np.abs(x[..., 3:6]) > sc.v_max).sum(axis=-1)
                + (np.abs(x[..., 10:]) > sc.omega_max).sum(axis=-1))
        eta = np.clip(f["q_err"][..., 0], -1.0, 1.0)
        return {
            "state": x.copy(),
            "accel": accel.copy(),
            "delta_v": delta_v(accel, sc.dt),
            "tracking_error": f["e_p"].copy(),
            "min_separation": np.minimum(f["d_obj"], d_other),
            "collision": keepout | (pair > 0),
            "violations": viol.astype(np.int64),
            "cost": viol.astype(float),
            "thrust": u.copy(),
            "torque": u @ self.f_r.T,
            "waypoint": f["waypoint"].copy(),
            "phase": np.array(f["phase"], dtype=np.int64),
            "dist_object": f["d_obj"].copy(),
            "dist_other": d_other,
            "pointing_error": f["pointing"].copy(),
            "attitude_error": 2.0 * np.arccos(eta),
            "quaternion_error": f["q_err"].copy(),
            "omega_error": f["e_w"].copy(),
        }

    def observe(self) -> np.ndarray:
        sc = self.scenario
        f = self._feat
        m, b = self.n_agents, self.batch
        obs = np.zeros((b, m, self.obs_dim))
        obs[..., 0:3] = f["e_p"] / self.scale_p
        obs[..., 3:6] = f["e_v"] / sc.v_max
        obs[..., 6:10] = f["q_err"]
        obs[..., 10:13] = f["e_w"] / sc.omega_max
        obs[..., 13:16] = self.x[..., :3] / self.scale_p
        if m > 1:
            rel = self.x[:, self.others, :6] - self.x[:, :, None, :6]      # (B, M, M-1, 6)
            rel = rel / np.array([self.scale_p] * 3 + [sc.v_max] * 3)
            obs[..., 16:] = rel.reshape(b, m, -1)
        return obs.astype(np.float32)

    def global_state(self) -> np.ndarray:
        b = self.batch
        return np.concatenate([self.x.reshape(b, -1), self._feat["waypoint"].reshape(b, -1),
                               (self.t * self.scenario.dt)[:, None]], axis=1)

    def render_scene(self, b: int = 0) -> dict[str, Any]:
        sc = self.scenario
        x = self.x[b]
        return {
            "positions": x[:, :3].copy(),
            "labels": [f"s{i + 1}" for i in range(self.n_agents)],
            "targets": self._feat["waypoint"][b].copy(),
            "spheres": [(np.zeros(3), sc.object_radius, "object"),
                        (np.zeros(3), sc.keepout_radius, "keep-out")],
            "axes": quat_to_matrix(x[:, 6:10])[:, :, 2],
            "axis_length": 5.0,
            "title": f"servicing_v0 ({sc.name})  t = {self.t[b] * sc.dt:.1f} s",
        }


class ServicingEnv(SatParallelEnv):
    """The servicing ``ParallelEnv`` (see the module docstring)."""

    metadata = {**SatParallelEnv.metadata, "name": "servicing_v0"}
    core_class = ServicingCore
    agent_prefix = "sat"

    def __init__(self, preset: str = "pereira2022", render_mode: str | None = None, reward: str = "paper",
                 **kwargs) -> None:
        scenario = resolve_preset("servicing_v0", preset, PRESETS, resolve_scenario, kwargs)
        super().__init__(scenario, render_mode=render_mode, reward=reward)

    def _check_initial_state(self, value: Any) -> np.ndarray:
        x0 = super()._check_initial_state(value)
        with np.errstate(over="ignore"):
            norms = np.linalg.norm(x0[:, 6:10], axis=1)
        if not np.all((norms >= 1e-6) & np.isfinite(norms)):
            raise SatenvError("options['initial_state'][:, 6:10] are the attitude quaternions "
                              f"[eta, ex, ey, ez] and must be non-zero, got norms {norms.tolist()}")
        return x0


def parallel_env(**kwargs) -> ServicingEnv:
    """The PettingZoo ``ParallelEnv`` (keyword arguments: module docstring)."""
    return ServicingEnv(**kwargs)


def raw_env(**kwargs) -> AECEnv:
    """The raw AEC env (``parallel_to_aec_wrapper``, no further wrappers)."""
    return parallel_to_aec_wrapper(ServicingEnv(**kwargs))


def env(**kwargs) -> AECEnv:
    """The AEC env: :func:`raw_env` with PettingZoo's order-enforcing wrapper."""
    return OrderEnforcingWrapper(raw_env(**kwargs))
