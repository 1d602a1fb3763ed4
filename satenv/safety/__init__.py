"""Run-time assurance: a safety filter between any policy and any satenv env.

The filter changes a proposed action only when it would lead to a violation, and records that it
did. One core, three ways to use it::

    from satenv.safety import SafetyFilter, shield
    safe, record = SafetyFilter(env).filter(actions)     # (B, M, d) arrays, any env or make_vec batch
    policy = shield(policy, env)                         # a policy wrapper (same reset / act / info)
    env = satenv.make("cluster_v0", safety_filter=True)  # or make_vec / satenv.torchrl.make_env

The package: :mod:`~satenv.safety.config` (settings, record, errors), :mod:`~satenv.safety.model`
(the per-scenario model), :mod:`~satenv.safety.rows` (the rows below), :mod:`~satenv.safety.margins`
(their tightening by declared bounds), :mod:`~satenv.safety.core` (the batched QP and
:class:`SafetyFilter`), :mod:`~satenv.safety.shield` (the policy wrapper) and
:mod:`~satenv.safety.wrapper` (the env wrapper ``safety_filter=True`` builds).

**Planners never see the truth.** The model is the task's nominal env's
(:func:`satenv.perturbations.nominal`), whatever perturbation the env flies under; the state is the
one the env holds when the policy acts (under navigation error: the estimate). What the filter
cannot see, the env declares (:func:`satenv.perturbations.declared_bounds`), and
:mod:`satenv.safety.margins` tightens every row by it (derived margins, none tuned).

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

Guarantee (for the CW double-integrator model, the scenario's disturbance bound, errors within the
declared bounds and states whose rows are feasible): separation and half-space gaps stay >= 0 at
every decision and the pair stays brakeable; the velocity boxes hold at the next decision. Not
guaranteed: infeasible starts (a start inside the margin with closing speed), model mismatch (J2,
drag, nonlinear terms beyond the drift bound), dips between decisions larger than the margin,
constraints of other agents' QPs that fall back (their share is then missing), an agent squeezed
between several pairs at once (each pair assumes its full authority), the allowed region
(``max_distance``) and the pereira2023 minimum-error constraint (41) (implied by separation for the
PLF topology only).
"""

from __future__ import annotations

from satenv.perturbations import UncertaintyBounds
from satenv.safety.config import (
    CONSTRAINTS,
    MIN_MARGIN,
    SafetyConfig,
    SafetyError,
    SafetyRecord,
    SafetyTypeError,
    SafetyWarning,
)
from satenv.safety.core import SafetyFilter, filter_actions, solve_qp
from satenv.safety.model import SafetyModel, courtesy, safety_model
from satenv.safety.rows import constraint_rows
from satenv.safety.shield import Shield, shield
from satenv.safety.wrapper import filtered_env, safety_config

__all__ = ["CONSTRAINTS", "MIN_MARGIN", "SafetyConfig", "SafetyError", "SafetyFilter", "SafetyModel", "SafetyRecord",
           "SafetyTypeError", "SafetyWarning", "Shield", "constraint_rows", "courtesy", "filter_actions",
           "filtered_env", "safety_config", "safety_model", "shield", "solve_qp", "UncertaintyBounds"]

# read by satenv.training.imitation.barrier (one step of the filter's own rows)
from satenv.dynamics import quat_to_matrix as quat_to_matrix  # noqa: E402
from satenv.safety.core import _effective as _effective  # noqa: E402
from satenv.safety.rows import _omega_rows as _omega_rows  # noqa: E402
