"""Planners never see the truth, and the filter is robust to what it cannot see.

* Under every perturbation the filter, the controllers and the experts model the task's nominal
  env (``satenv.perturbations.nominal``), never the perturbed truth.
* The filter's rows are tightened by the declared ``UncertaintyBounds`` (``satenv.safety.margins``):
  checked one decision ahead on the exact CW model against an adversarial estimate within the
  bounds (the estimate looks safer than the truth), and a thrust that delivers less than commanded.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

import satenv
from satenv import baselines, perturbations, tasks
from satenv.errors import SatenvError
from satenv.perturbations import UncertaintyBounds
from satenv.safety import SafetyConfig, SafetyFilter, filter_actions, safety_model


def _task_with(perturbation: str) -> tasks.Task:
    return next(tasks.get(n) for n in tasks.names() if perturbation in tasks.get(n).perturbations)


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if dataclasses.is_dataclass(a):
        return type(a) is type(b) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    return a == b


def _model_fields(m) -> dict:
    return {f.name: getattr(m, f.name) for f in dataclasses.fields(m) if f.name != "bounds"}


@pytest.mark.parametrize("name", perturbations.names())
def test_the_filter_models_the_nominal_env_under_every_perturbation(name):
    task = _task_with(name)
    env = perturbations.make_env(task, name)
    env.reset(seed=task.seeds("test", 1)[0])
    model = SafetyFilter(env).model
    nominal = safety_model(task.make_env())
    assert _same(_model_fields(model), _model_fields(nominal))
    assert model.bounds == perturbations.get(name).bounds
    if perturbations.get(name).truth(task.make_env().scenario):   # the truth differs: the old model would too
        truth = safety_model(env.env, UncertaintyBounds())
        changed = {"thrust-80": "brake", "disturbance-x2": "disturbance"}.get(name)
        if changed:
            assert getattr(truth, changed) != getattr(model, changed)


@pytest.mark.parametrize("name", ["thrust-80", "disturbance-x2", "model-cw"])
@pytest.mark.parametrize("controller", ["tube_rdmpc", "apf"])
def test_a_cluster_controller_plans_with_the_nominal_scenario(name, controller):
    task = tasks.get("cluster-case1-random")
    env = perturbations.make_env(task, name)
    ctrl = baselines.make(controller, env)
    assert ctrl.sc is env.nominal_env.scenario
    assert repr(ctrl.sc) == repr(task.make_env().scenario) != repr(env.env.scenario)


@pytest.mark.parametrize("controller", ["dmpc", "joint_platoon_mpc"])
def test_a_platoon_controller_and_expert_plan_with_the_nominal_thrust(controller):
    from satenv.baselines import experts

    task = tasks.get("platoon-pereira2022-random")
    env = perturbations.make_env(task, "thrust-80")
    ctrl = experts.make(controller, env) if controller in experts.EXPERTS else baselines.make(controller, env)
    sc = ctrl.core.scenario if controller == "dmpc" else ctrl.scenario
    assert sc.u_max == task.make_env().scenario.u_max != env.env.scenario.u_max


def test_navigation_perturbations_declare_the_bound_of_their_gaussian_error():
    chi = pytest.importorskip("scipy.stats").chi
    k = chi.ppf(perturbations.NAV_BOUND_PROBABILITY, 3)        # an independent reference
    for name in ("nav-0.1m", "nav-1m"):
        p = perturbations.get(name)
        assert p.bounds.position == pytest.approx(k * p.sigma_position, rel=1e-9)
        assert p.bounds.velocity == pytest.approx(k * p.sigma_velocity, rel=1e-9)
    rng = np.random.default_rng(0)
    inside = np.mean(np.linalg.norm(rng.standard_normal((200_000, 3)), axis=1) <= k)
    assert abs(inside - perturbations.NAV_BOUND_PROBABILITY) < 5e-4
    for name in ("thrust-80", "disturbance-x2", "model-j2"):
        assert perturbations.get(name).bounds.exact
    assert perturbations.declared_bounds(satenv.make("cluster_v0")).exact


@pytest.mark.parametrize("field,value,error", [("position", -1.0, ValueError), ("thrust", 1.0, ValueError),
                                               ("velocity", math.nan, ValueError), ("disturbance", True, TypeError),
                                               ("position", "1", TypeError)])
def test_bad_bounds_name_the_field(field, value, error):
    with pytest.raises(error, match=f"UncertaintyBounds.{field}"):
        UncertaintyBounds(**{field: value})
    assert isinstance(UncertaintyBounds(), UncertaintyBounds)


def test_the_filter_rejects_bounds_of_the_wrong_type():
    with pytest.raises(TypeError, match="bounds"):
        SafetyFilter(satenv.make("cluster_v0"), bounds={"position": 1.0})


# ----------------------------------------------------------------------------- robust margins
def _pair_trials(told: UncertaintyBounds, error: UncertaintyBounds, kappa: float = 1.0, seed: int = 0,
                 n: int = 300) -> np.ndarray:
    """Two cluster agents near their separation ``D``, closing and thrusting at each other. The
    filter, told ``told``, reads an estimate off by ``error`` that shows them farther apart and
    opening (the worst case within the error); the truth applies ``kappa`` times the filtered
    acceleration. Returns the true gap to ``D`` at the next decision of every trial the filter
    solved (no backup)."""
    m = safety_model(satenv.make("cluster_v0"), told)
    cfg = SafetyConfig()
    rng = np.random.default_rng(seed)
    gaps = []
    for _ in range(n):
        x = np.zeros((1, m.n_agents, 6))
        x[0, :, 0], x[0, :, 1] = -20_000.0, 5_000.0 * np.arange(m.n_agents)   # every other agent far away
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        x[0, 1, :3] = x[0, 0, :3] + (m.pair_distance + rng.uniform(0.0, 30.0)) * u
        x[0, 1, 3:] = -rng.uniform(0.0, 0.6) * u + 0.05 * rng.standard_normal(3)
        est = x.copy()
        for i, sign in ((0, -1.0), (1, 1.0)):
            est[0, i, :3] += sign * error.position * u
            est[0, i, 3:] += sign * error.velocity * u
        proposal = np.zeros((1, m.n_agents, 3))
        proposal[0, 0], proposal[0, 1] = u, -u
        safe, rec = filter_actions(m, cfg, est, np.zeros(1), proposal)
        if rec.infeasible[0, :2].any():
            continue
        nxt = x[0, :2] @ m.A.T + kappa * safe[0, :2] @ m.S.T @ m.B.T
        gaps.append(np.linalg.norm(nxt[1, :3] - nxt[0, :3]) - m.pair_distance)
    return np.array(gaps)


NAV = UncertaintyBounds(position=5.0, velocity=0.05)


def test_the_tightened_filter_keeps_the_true_pair_apart_under_navigation_error():
    gaps = _pair_trials(NAV, NAV)
    assert len(gaps) >= 100 and gaps.min() >= -1e-6


def test_without_the_bounds_the_same_estimate_breaks_the_separation():
    assert _pair_trials(UncertaintyBounds(), UncertaintyBounds()).min() >= -1e-6   # the setup is safe when exact
    assert _pair_trials(UncertaintyBounds(), NAV).min() < 0.0                        # told nothing: it is not


def _closing_pair(told: UncertaintyBounds, kappa: float, seed: int, steps: int = 120) -> float:
    """Two cluster agents 100-150 m outside their separation, closing at 0.4-0.6 m/s (brakeable
    at ``kappa`` of the authority), each proposing full thrust at the other for ``steps``
    decisions; the truth applies ``kappa`` times the filtered acceleration. The smallest true gap
    to the separation distance."""
    m = safety_model(satenv.make("cluster_v0"), told)
    rng = np.random.default_rng(seed)
    x = np.zeros((1, m.n_agents, 6))
    x[0, :, 0], x[0, :, 1] = -20_000.0, 5_000.0 * np.arange(m.n_agents)
    u = rng.standard_normal(3)
    u /= np.linalg.norm(u)
    x[0, 1, :3] = x[0, 0, :3] + (m.pair_distance + rng.uniform(100.0, 150.0)) * u
    x[0, 1, 3:] = -rng.uniform(0.4, 0.6) * u
    low = math.inf
    for _ in range(steps):
        towards = x[0, 1, :3] - x[0, 0, :3]
        proposal = np.zeros((1, m.n_agents, 3))
        proposal[0, 0] = towards / np.linalg.norm(towards)
        proposal[0, 1] = -proposal[0, 0]
        safe, _ = filter_actions(m, SafetyConfig(), x, np.zeros(1), proposal)
        x = x @ m.A.T + kappa * safe @ m.S.T @ m.B.T
        low = min(low, float(np.linalg.norm(x[0, 1, :3] - x[0, 0, :3])) - m.pair_distance)
    return low


@pytest.mark.parametrize("seed", range(3))
def test_the_tightened_filter_holds_when_the_thrust_delivers_less(seed):
    theta = 0.7
    assert _closing_pair(UncertaintyBounds(), 1.0 - theta, seed) < 0.0        # told nothing: they collide
    assert _closing_pair(UncertaintyBounds(thrust=theta), 1.0 - theta, seed) >= 0.0


def test_zero_bounds_leave_the_filter_as_it_was():
    env = satenv.make("servicing_v0", randomize=True)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    a = rng.uniform(-1, 1, (len(env.possible_agents), env.core.action_dim))
    plain = SafetyFilter(env).filter(a)[0]
    told = SafetyFilter(env, bounds=UncertaintyBounds()).filter(a)[0]
    wide = SafetyFilter(env, bounds=UncertaintyBounds(position=3.0)).filter(a)[0]
    assert np.array_equal(plain, told) and isinstance(wide, np.ndarray)


def test_a_perturbed_env_needs_a_known_perturbation():
    with pytest.raises(SatenvError, match="unknown perturbation"):
        perturbations.make_env(tasks.get("cluster-case1-random"), "nav-2m")


def test_the_shield_reads_the_estimate_the_policy_reads():
    task = tasks.get("servicing-pereira2022-random")
    seed = task.seeds("test", 1)[0]
    truth, noisy = task.make_env(), perturbations.make_env(task, "nav-1m")
    truth.reset(seed=seed)
    obs, _ = noisy.reset(seed=seed)
    filt = satenv.safety.shield(baselines.make("zero", noisy), noisy).filter
    assert np.array_equal(filt.core.x, noisy.env.core.x)              # the state the env holds now
    assert not np.allclose(filt.core.x[..., :6], truth.core.x[..., :6])  # the estimate, not the truth


class _Recorder:
    """An inner-loop hook that records the states it is given and corrects nothing."""

    def __init__(self) -> None:
        self.states: list[np.ndarray] = []

    def correction(self, t, x, chief, u_cmd):
        self.states.append(np.array(x))
        return np.zeros(np.shape(u_cmd))


def _hooked_step(task: tasks.Task, perturbation: str | None) -> tuple[Any, np.ndarray, _Recorder]:
    """One zero-thrust step of the task's first test seed with a recording hook: the env, the state
    the policy observed before the step and the hook."""
    env = perturbations.make_env(task, perturbation)
    env.reset(seed=task.seeds("test", 1)[0])
    seen = env.core.x.copy()
    hook = _Recorder()
    env.set_inner_loop(hook)
    env.step({a: np.zeros(3, dtype=np.float32) for a in env.agents})
    return env, seen, hook


def test_the_physics_rate_hook_reads_the_estimate_never_the_truth():
    task = tasks.get("cluster-case1-rung1-near3")
    plain_env, truth, plain = _hooked_step(task, None)          # nav error leaves the physics alone
    env, seen, hook = _hooked_step(task, "nav-1m")
    assert env.inner_loop is hook and plain_env.inner_loop is plain   # restored after the step
    assert len(hook.states) == len(plain.states) == task.make_env().scenario.substeps
    noise = seen[..., :6] - truth[..., :6]                       # the decision's navigation error
    assert np.abs(noise).max() > 0.1
    for nav, true in zip(hook.states, plain.states, strict=True):   # every sub-step: truth + that error
        np.testing.assert_allclose(nav[..., :6] - true[..., :6], noise, rtol=0, atol=1e-9)


def test_a_perturbed_env_refuses_a_filter_inside_the_truth():
    task = tasks.get("platoon-pereira2022-random")
    with pytest.raises(SatenvError, match="satenv.safety.shield"):
        perturbations.make_env(task, "thrust-80", safety_filter=True)
    assert perturbations.make_env(task, None, safety_filter=True).safety is not None   # unperturbed: allowed
