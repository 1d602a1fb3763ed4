"""baselines: the registry, env checks, config validation (caps, types) and the solver guard.

Fault injection: each baseline's solver is replaced by one that raises, returns a point of the
wrong shape, a NaN point, or reports success with an infeasible point (outside the variable
bounds, or — for the NLPs — violating the constraint rows). Every fault must be flagged
(``info["fallbacks"]``, ``info["solver_status"]``), the action must stay finite and in
``[-1, 1]``, and the episode must go on.
"""

import math
import subprocess
import sys

import numpy as np
import pytest

import satenv
from satenv import baselines
from satenv.baselines import BaselineError, BaselineTypeError
from satenv.baselines.base import guarded_solve, new_info

FAULTS = ("raise", "shape", "nan", "infeasible")


# ---------------------------------------------------------------------------------- registry
def test_registry_names_and_supporting_envs():
    assert set(baselines.BASELINES) == {"zero", "random", "dmpc", "tube_rdmpc", "apf", "nmpc", "cgmres"}
    expected = {"platoon_v0": ["zero", "random", "dmpc"],
                "cluster_v0": ["zero", "random", "tube_rdmpc", "apf"],
                "servicing_v0": ["zero", "random", "nmpc"],
                "formation_v0": ["zero", "random", "cgmres"]}
    for env_id, names in expected.items():
        env = satenv.make(env_id)
        assert baselines.supporting(env) == names
        assert baselines.supporting(env, cheap=True) == [n for n in names if baselines.get(n).cheap]
        for name in baselines.BASELINES:
            cls = baselines.get(name)
            assert env_id in cls.env_ids or not cls.supports(env)


def test_every_controller_and_expert_the_task_registry_names_resolves():
    """satenv.tasks names controllers and experts; satenv.baselines.registry defines every one."""
    from satenv import tasks
    from satenv.baselines import registry

    names = {t.controller for t in tasks.TASKS.values()} | {s.controller for s in tasks.SYSTEMS.values()}
    assert names and names <= set(registry.BASELINES)
    for name in names:
        assert callable(getattr(registry.get(name), "supports", None)), name
    experts = {s.expert for s in tasks.SYSTEMS.values()}
    assert experts and all(isinstance(registry.get_expert(name), type) for name in experts)
    with pytest.raises(BaselineError, match="unknown expert"):
        registry.get_expert("no_such_expert")


def test_one_resolver_of_module_attribute_strings():
    from satenv.baselines.registry import ResolveError, resolve

    assert resolve("satenv.baselines.base:ZeroPolicy") is baselines.ZeroPolicy
    for bad in ("satenv.baselines.base", "satenv.baselines.base:NoSuchThing", ":x", 3):
        with pytest.raises(ResolveError):
            resolve(bad)
    with pytest.raises(ModuleNotFoundError):
        resolve("no_such_module_anywhere:x")


def test_cheap_table_matches_the_classes_and_imports_no_solver():
    assert {n for n in baselines.BASELINES if baselines.get(n).cheap} == baselines.registry.CHEAP
    code = ("import sys, satenv\nfrom satenv import baselines\n"
            "for e in satenv.ENV_IDS: satenv.baselines.supporting(satenv.make(e), cheap=True)\n"
            "print(sorted(m for m in ('casadi', 'daqp', 'osqp', 'satenv.baselines.cgmres', 'satenv.baselines.nmpc',"
            " 'satenv.baselines.tube_rdmpc') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_make_builds_and_unknown_names_are_rejected():
    env = satenv.platoon_v0()
    assert isinstance(baselines.make("dmpc", env), baselines.DMPC)
    with pytest.raises(BaselineError, match="unknown baseline 'DMPC'"):
        baselines.get("DMPC")


@pytest.mark.parametrize("name,other", [("dmpc", "cluster_v0"), ("apf", "platoon_v0"),
                                        ("cgmres", "servicing_v0"), ("nmpc", "formation_v0"),
                                        ("tube_rdmpc", "formation_v0")])
def test_unsupported_env_and_non_env_give_clear_errors(name, other):
    cls = baselines.get(name)
    with pytest.raises(BaselineError, match=rf"{cls.__name__} cannot control {other}.*supports"):
        cls(satenv.make(other))
    for bad in (None, "platoon_v0", object()):
        with pytest.raises(BaselineTypeError, match="needs a satenv env"):
            cls(bad)


def test_zero_policy_rejects_non_envs():
    with pytest.raises(TypeError, match="PettingZoo env"):
        baselines.ZeroPolicy(None)


# ---------------------------------------------------------------------------------- configs
@pytest.mark.parametrize("name,field,bad,match", [
    ("dmpc", "horizon", 10**6, r"horizon must be in \[1, 200\]"),
    ("dmpc", "horizon", True, "horizon must be an int"),
    ("dmpc", "sigma", math.nan, "sigma must be finite"),
    ("dmpc", "sigma", 1j, "sigma must be a real number"),
    ("dmpc", "terminal_weight", (1.0,) * 5, "terminal_weight must have 6 entries"),
    ("dmpc", "max_iterations", 1e300, "max_iterations must be an int"),
    ("apf", "k_att", math.inf, "k_att must be finite"),
    ("apf", "cw_compensation", 1, "cw_compensation must be True or False"),
    ("tube_rdmpc", "max_iter", 10**9, r"max_iter must be in \[1, 100000\]"),
    ("tube_rdmpc", "beta", True, "beta must be a real number"),
    ("nmpc", "horizon", 201, r"horizon must be in \[1, 200\]"),
    ("nmpc", "rk4_steps", 10**6, r"rk4_steps must be in \[1, 100\]"),
    ("cgmres", "horizon_steps", 10**5, r"horizon_steps must be in \[1, 200\]"),
    ("cgmres", "fd_step", complex(1e-6, 0), "fd_step must be a real number"),
])
def test_config_validation_rejects_bad_values_with_caps(name, field, bad, match):
    cfg_cls = getattr(baselines, baselines.get(name).__name__ + "Config")
    with pytest.raises(BaselineError, match=match):
        cfg_cls(**{field: bad})


def test_tube_horizon_is_capped_before_any_work():
    env = satenv.cluster_v0()
    with pytest.raises(BaselineError, match="at most 200 decision periods"):
        baselines.TubeRDMPC(env, horizon=1e300)


@pytest.mark.parametrize("name", ["dmpc", "apf", "cgmres"])
def test_unknown_option_error_is_the_same_everywhere(name):
    env_id = baselines.get(name).env_ids[0]
    with pytest.raises(BaselineError, match=r"unknown option\(s\) \['nope'\]; accepted"):
        baselines.make(name, satenv.make(env_id), nope=1)


def test_paper_configs_and_config_objects():
    p22 = satenv.platoon_v0(preset="pereira2022")
    cfg = baselines.DMPCConfig.for_env(p22)
    assert (cfg.variant, cfg.horizon, cfg.iterations, cfg.convex_weights) == ("convex_step", 40, 2, (0.6, 0.4))
    assert baselines.DMPCConfig.for_env(satenv.platoon_v0()) == baselines.DMPCConfig()
    pol = baselines.DMPC(satenv.platoon_v0(), baselines.DMPCConfig(horizon=10), sigma=0.1)
    assert (pol.cfg.horizon, pol.cfg.sigma) == (10, 0.1)
    # three followers: the paper's two convex weights become uniform
    three = satenv.platoon_v0(preset="pereira2022", initial_state=[[30, -50, 40, 0, 0, 0],
                                                                  [45, -96, 10, 0, 0, 0],
                                                                  [45, -120, 10, 0, 0, 0]])
    assert baselines.DMPCConfig.for_env(three).convex_weights is None


def test_controller_fields_left_the_env_kwargs():
    for kw in ("horizon", "sigma", "controller", "terminal_weight", "iterations", "convex_weights"):
        with pytest.raises(ValueError, match="unknown"):
            satenv.platoon_v0(**{kw: 1})
    with pytest.raises(ValueError, match="unknown"):
        satenv.servicing_v0(horizon=30)


# ---------------------------------------------------------------------------------- the guard
def test_guard_checks_every_failure_kind():
    info = new_info()
    ok = guarded_solve(info, lambda: (np.ones(2), True, "solved"), shape=(2,), lower=-1, upper=1)
    assert ok is not None and info["solver_status"] == "solved" and info["fallbacks"] == 0
    cases = [(lambda: 1 / 0, "error: ZeroDivisionError"), (lambda: (np.ones(3), True, "s"), "wrong shape"),
             (lambda: (np.array([np.nan, 0]), True, "s"), "non-finite"),
             (lambda: (np.array([2.0, 0]), True, "s"), "infeasible: bound"),
             (lambda: (np.zeros(2), False, "max iter"), "failed: max iter")]
    for k, (solve, why) in enumerate(cases, 1):
        assert guarded_solve(info, solve, shape=(2,), lower=-1, upper=1) is None
        assert info["fallbacks"] == k and info["solver_status"].startswith(why)
    assert guarded_solve(info, lambda: (np.zeros(2), True, "s"), shape=(2,),
                         violation=lambda x: 0.5, violation_tol=0.1) is None
    assert info["solver_status"].startswith("infeasible: constraint")


def _check_episode_goes_on(env, pol, obs, steps=2):
    for _ in range(steps):
        act = pol.act(obs)
        for a in act.values():
            assert np.all(np.isfinite(a)) and np.all(np.abs(a) <= 1.0)
        obs, *_ = env.step(act)
        if not env.agents:
            break
    return obs


def _bad_point(kind, x):
    return {"shape": np.zeros(np.size(x) + 1), "nan": np.full(np.shape(x), np.nan),
            "infeasible": np.full(np.shape(x), 1e3)}[kind]


@pytest.mark.parametrize("kind", FAULTS)
def test_dmpc_solver_faults(monkeypatch, kind):
    from satenv.baselines.dmpc import QPSolver

    env = satenv.platoon_v0(topology="BDL")
    pol = baselines.DMPC(env, seed=0)
    obs, _ = env.reset(seed=0)
    obs = _check_episode_goes_on(env, pol, obs, 1)
    real = QPSolver.solve_raw

    def faulty(self):
        if kind == "raise":
            raise ValueError("injected")
        x, ok, status = real(self)
        return _bad_point(kind, x), True, status

    monkeypatch.setattr(QPSolver, "solve_raw", faulty)
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] > 0
    want = {"raise": "error: ValueError", "shape": "wrong shape", "nan": "non-finite",
            "infeasible": "infeasible"}[kind]
    assert pol.info["solver_status"].startswith(want)


def test_dmpc_row_violation_is_caught(monkeypatch):
    """A point inside the input box that breaks the velocity rows (40) is a failure too."""
    from satenv.baselines.dmpc import QPSolver

    env = satenv.platoon_v0(topology="BDL", v_max=0.5)
    pol = baselines.DMPC(env, seed=0)
    obs, _ = env.reset(seed=0)
    monkeypatch.setattr(QPSolver, "solve_raw", lambda self: (self.ub.copy(), True, "forced"))
    _check_episode_goes_on(env, pol, obs, 1)
    assert pol.info["fallbacks"] > 0 and pol.info["solver_status"].startswith("infeasible: constraint")


@pytest.mark.parametrize("kind", ("raise", "shape", "nan"))
def test_apf_faults(monkeypatch, kind):
    env = satenv.cluster_v0(max_steps=3)
    pol = baselines.APF(env)
    obs, _ = env.reset(seed=0)
    pol.reset()

    def faulty():
        if kind == "raise":
            raise FloatingPointError("injected")
        return _bad_point(kind, np.zeros((pol.m, 3)))

    monkeypatch.setattr(pol, "_law", faulty)
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 and pol.info["solver_status"] != "not run"


@pytest.mark.parametrize("kind", FAULTS)
def test_cgmres_faults(monkeypatch, kind):
    import satenv.baselines.cgmres as mod

    env = satenv.formation_v0(max_steps=6)
    pol = baselines.CGMRES(env)
    obs, _ = env.reset(seed=0)
    pol.reset()
    obs = _check_episode_goes_on(env, pol, obs, 1)
    real = mod.gmres

    def faulty(matvec, b, x0, kmax):
        if kind == "raise":
            raise np.linalg.LinAlgError("injected")
        x, rel = real(matvec, b, x0, kmax)
        return (_bad_point(kind, x), rel) if kind != "infeasible" else (x, 10.0)

    monkeypatch.setattr(mod, "gmres", faulty)
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 and pol.info["fallback"]
    monkeypatch.setattr(mod, "gmres", real)
    _check_episode_goes_on(env, pol, obs, 1)
    assert not pol.info["fallback"]


class _FakeNLP:
    """A CasADi-nlpsol stand-in that injects one fault kind (``rows``: bounds-feasible x, rows
    violated; ``infeasible``: x outside the variable bounds) and reports success."""

    def __init__(self, kind, lbg, ubg):
        self.kind, self.lbg, self.ubg = kind, np.asarray(lbg), np.asarray(ubg)

    def __call__(self, **args):
        if self.kind == "raise":
            raise RuntimeError("injected")
        x0 = np.asarray(args["x0"], dtype=float).ravel()
        x = (np.clip(x0, args["lbx"], args["ubx"]) if self.kind == "rows" else _bad_point(self.kind, x0))
        g = np.where(np.isfinite(self.lbg), self.lbg - 1.0, self.ubg + 1.0)
        if self.kind != "rows":
            g = np.clip(0.0, self.lbg, self.ubg)
        return {"x": x, "g": g, "lam_x": np.zeros_like(x0), "lam_g": np.zeros_like(self.lbg)}

    def stats(self):
        return {"success": True, "return_status": "Solve_Succeeded", "iter_count": 1}


@pytest.fixture(scope="module")
def tube():
    pytest.importorskip("casadi")
    env = satenv.cluster_v0(max_steps=4)
    return env, baselines.TubeRDMPC(env)


@pytest.mark.parametrize("kind", (*FAULTS, "rows"))
def test_tube_rdmpc_faults(monkeypatch, tube, kind):
    env, pol = tube
    obs, _ = env.reset(seed=0)
    pol.reset()
    monkeypatch.setattr(pol.nlp, "solver_for",
                        lambda k, copy=0, relaxed=False: _FakeNLP(kind, *pol.nlp.row_bounds(k)))
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 * pol.m and pol.info["relaxed"] == 2 * pol.m
    assert pol.info["solver_status"] != "Solve_Succeeded"


@pytest.fixture(scope="module")
def nmpc():
    pytest.importorskip("casadi")
    env = satenv.servicing_v0(max_steps=4)
    return env, baselines.NMPC(env, horizon=5)


@pytest.mark.parametrize("kind", (*FAULTS, "rows"))
def test_nmpc_faults(monkeypatch, nmpc, kind):
    env, pol = nmpc
    obs, _ = env.reset(seed=0)
    pol.reset()
    monkeypatch.setattr(pol, "_nlp", _FakeNLP(kind, pol._lbg, pol._ubg))
    _check_episode_goes_on(env, pol, obs)
    assert pol.info["fallbacks"] == 2 * pol.m
    want = {"raise": "error: RuntimeError", "shape": "wrong shape", "nan": "non-finite",
            "infeasible": "infeasible: bound", "rows": "infeasible: constraint"}[kind]
    assert pol.info["solver_status"].startswith(want)
