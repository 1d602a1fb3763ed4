"""Property-based tests (hypothesis) over satenv's public entry points.

For random inputs of random types and magnitudes, every call of the four env constructors,
``reset``, ``step``, ``Orbit``, ``simulate``, ``satenv.make_vec`` (construction and ``step``),
``satenv.baselines.make`` (every baseline, random options, on envs it does and does not support and on
non-envs) and ``satenv.training.load`` (random and corrupted policy folders) either raises a clear error
(the package's ``ValueError``/``TypeError`` subclass: :class:`satenv.errors.SatenvError`,
:class:`satenv.baselines.BaselineError`/``BaselineTypeError``, :class:`satenv.training.PolicyLoadError`) or
returns finite results; it never hangs (hypothesis ``deadline`` plus a hard SIGALRM timeout), and
a rejected call leaves the object usable: it still steps and returns what a fresh one returns.

The default run draws a few examples per property; ``pytest -m fuzz tests/test_properties.py``
runs the same properties with many more.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from audit_inputs import (  # tests/ on sys.path
    POLICY_FILE_NAMES,
    apply_edit,
    good_policy_folder,
    time_limit,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import satenv
from satenv import baselines, training
from satenv.dynamics import Orbit, simulate
from satenv.errors import SatenvError

ENV_IDS = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")
HARD_TIMEOUT = 20.0  # s per example: a hang fails the test instead of stalling the suite
DEFAULT = {"max_examples": 12}
FUZZ = {"max_examples": 400}


def call(fn, *args, errors: tuple[type[Exception], ...] = (SatenvError,), **kwargs):
    """``(result, None)`` or ``(None, error)`` for a clear error (one of ``errors``); anything
    else fails (a call still running after ``HARD_TIMEOUT`` raises ``audit_inputs.Hang``)."""
    with time_limit(HARD_TIMEOUT):
        try:
            return fn(*args, **kwargs), None
        except errors as exc:
            assert isinstance(exc, ValueError | TypeError)
            assert str(exc), "an error message must say what was expected"
            return None, exc


def finite(*arrays) -> bool:
    out = True
    for a in arrays:
        if isinstance(a, dict):
            out &= finite(*a.values())
        else:
            out &= bool(np.isfinite(np.asarray(a, dtype=float)).all())
    return out


# ------------------------------------------------------------------------------- strategies
reals = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.sampled_from([0, 1, -1, 1e-300, 1e300, 1e41, 5e6, 1e12, 10**7, 0.5, 2.0]),
)
odd = st.one_of(
    st.none(), st.booleans(), st.complex_numbers(), st.text(max_size=3),
    st.just(np.ma.masked_array([1.0, 2.0, 3.0], mask=[True, False, False])),
    st.just(np.array([1 + 1j, 0, 0])), st.just(np.array([True, False, True])),
)
arrays = st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), reals), min_size=0, max_size=7)
values = st.one_of(reals, odd, arrays)


def pow10(e: float) -> np.float64:
    """``10 ** e`` as a float64 (``inf`` above the float range, where Python's ``**`` raises)."""
    with np.errstate(over="ignore"):
        return np.float64(10.0) ** e


def scaled(default):
    """A default value scaled by a random power of ten (keeps the kind, changes the magnitude)."""
    return st.floats(min_value=-320, max_value=320).map(
        lambda e: (np.asarray(default, dtype=float) * pow10(e)).tolist())


def field_defaults(env_id: str) -> dict:
    sc = satenv.make(env_id).scenario
    return {f.name: getattr(sc, f.name) for f in dataclasses.fields(sc)
            if f.init and not f.name.startswith("_") and f.name != "name"}


DEFAULTS = {e: field_defaults(e) for e in ENV_IDS}


@st.composite
def env_kwargs(draw):
    env_id = draw(st.sampled_from(ENV_IDS))
    names = draw(st.lists(st.sampled_from(sorted(DEFAULTS[env_id])), min_size=1, max_size=2, unique=True))
    kwargs = {}
    for n in names:
        default = DEFAULTS[env_id][n]
        numeric = isinstance(default, int | float | tuple) and not isinstance(default, bool | str)
        kwargs[n] = draw(st.one_of(values, scaled(default)) if numeric else values)
    return env_id, kwargs


# ------------------------------------------------------------------------------- reference runs
def reference(env_id: str):
    """What a fresh env returns for ``reset(seed=0)`` then one zero-action step."""
    env = satenv.make(env_id)
    obs0, _ = env.reset(seed=0)
    obs1, rew, *_ = env.step({a: np.zeros(env.action_space(a).shape) for a in env.agents})
    return obs0, obs1, rew


REFERENCE = {e: reference(e) for e in ENV_IDS}
ENVS = {e: satenv.make(e) for e in ENV_IDS}


def assert_like_fresh(env_id: str, env) -> None:
    """The env still resets and steps exactly like a fresh one."""
    obs0, _ = env.reset(seed=0)
    obs1, rew, *_ = env.step({a: np.zeros(env.action_space(a).shape) for a in env.agents})
    ref0, ref1, ref_rew = REFERENCE[env_id]
    for a in ref0:
        np.testing.assert_array_equal(obs0[a], ref0[a])
        np.testing.assert_array_equal(obs1[a], ref1[a])
    assert rew == ref_rew


# ------------------------------------------------------------------------------- properties
def prop_constructor(case):
    env_id, kwargs = case
    env, err = call(satenv.make, env_id, **kwargs)
    if err is None:
        (obs, _), err = call(env.reset, seed=0)
        assert err is None, f"accepted {kwargs} but reset failed: {err}"
        out, err = call(env.step, {a: np.ones(env.action_space(a).shape) for a in env.agents})
        assert err is None, f"accepted {kwargs} but the first step failed: {err}"
        assert finite(obs, out[0], out[1])


def prop_reset(env_id, seed, initial_state):
    env = ENVS[env_id]
    x0 = env.core.sample_initial_state(np.random.default_rng(0), 1)[0]
    options = None if initial_state is None else {"initial_state": initial_state(x0)}
    out, err = call(env.reset, seed=seed, options=options)
    if err is None:
        obs, infos = out
        assert finite(obs, *[i["state"] for i in infos.values()])
    assert_like_fresh(env_id, env)


def prop_step(env_id, which, bad):
    env = ENVS[env_id]
    env.reset(seed=0)
    actions = {a: np.zeros(env.action_space(a).shape) for a in env.agents}
    actions[env.agents[which % len(env.agents)]] = bad
    out, err = call(env.step, actions)
    if err is None:
        assert finite(out[0], out[1])
    else:  # rejected: the episode goes on from where it was, as in a fresh env
        obs, rew, *_ = env.step({a: np.zeros(env.action_space(a).shape) for a in env.agents})
        for a in obs:
            np.testing.assert_array_equal(obs[a], REFERENCE[env_id][1][a])
        assert rew == REFERENCE[env_id][2]
    assert_like_fresh(env_id, env)


def prop_orbit(kwargs):
    orbit, err = call(Orbit, **kwargs)
    if err is None:
        assert finite(orbit.rv, orbit.n, orbit.period)


def prop_simulate(model, x0, dt, steps, substeps):
    out, err = call(simulate, model, x0, orbit=Orbit(a=6878e3, i=0.9), dt=dt, steps=steps,
                    substeps=substeps)
    if err is None:
        assert out.shape == (int(steps) + 1, np.asarray(x0).shape[0], 6)
        assert finite(out)


# ------------------------------------------------------------------------------- strategies per property
state_edits = st.one_of(
    st.none(),
    st.sampled_from([
        lambda x: x, lambda x: x * 1e41, lambda x: x + 1j, lambda x: x[:-1], lambda x: x.astype(bool),
        lambda x: np.ma.masked_array(x, mask=np.ones(x.shape, bool)), lambda x: x.tolist(),
        lambda x: np.where(np.arange(x.size).reshape(x.shape) == 0, np.nan, x), lambda x: x * 1e3,
        lambda x: np.full(x.shape, 10**400, dtype=object), lambda x: "state",
    ]),
)
action_values = st.one_of(values, st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=6),
                          st.floats(min_value=-320, max_value=320).map(lambda e: np.full(3, pow10(e))))
orbit_kwargs = st.fixed_dictionaries({"a": st.one_of(reals, odd, st.floats(6.5e6, 5e7))},
                                     optional={"e": st.one_of(reals, st.floats(0, 0.99)),
                                               "i": st.one_of(reals, st.floats(0, 3.1)),
                                               "mu": st.one_of(reals, odd), "nu": values})
sim_x0 = st.one_of(
    st.sampled_from([[[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]], [[-6878e3, 0, 0, 0, 0, 0]],
                     [[1e41, 0, 0, 0, 0, 0]], [[0.0, 100.0, 0.0, 0.0, 0.0, 1j]]]),
    values)

# ------------------------------------------------------------------------------- baselines
def baseline_options(name: str) -> dict:
    """The option names of baseline ``name`` with their defaults (its config dataclass)."""
    cls = baselines.get(name)
    cfg = getattr(baselines, cls.__name__ + "Config", None)
    return {} if cfg is None else {f.name: f.default for f in dataclasses.fields(cfg) if f.init}


OPTIONS = {n: baseline_options(n) for n in baselines.BASELINES}
NON_ENVS = (None, "platoon_v0", object(), 3, {"name": "platoon_v0"}, satenv.platoon_v0, np.zeros(3))
BASELINE_ERRORS = (baselines.BaselineError, baselines.BaselineTypeError, SatenvError)


@st.composite
def baseline_case(draw):
    name = draw(st.sampled_from(sorted(OPTIONS)))
    target = draw(st.one_of(st.sampled_from(ENV_IDS), st.sampled_from(range(len(NON_ENVS)))))
    names = sorted(OPTIONS[name]) + ["no_such_option"]
    picks = draw(st.lists(st.sampled_from(names), max_size=2, unique=True))
    options = {}
    for n in picks:
        default = OPTIONS[name].get(n)
        numeric = isinstance(default, int | float | tuple) and not isinstance(default, bool)
        options[n] = draw(st.one_of(values, scaled(default)) if numeric else values)
    return name, target, options


def prop_baseline(case):
    name, target, options = case
    env = ENVS[target] if isinstance(target, str) else NON_ENVS[target]
    pol, err = call(baselines.make, name, env, errors=BASELINE_ERRORS, **options)
    if err is None and isinstance(target, str) and baselines.get(name).cheap:
        obs, _ = env.reset(seed=0)
        pol.reset(seed=0)
        act, err = call(pol.act, obs, errors=BASELINE_ERRORS)
        assert err is None, f"{name}({options}) was built but cannot act: {err}"
        assert all(np.isfinite(a).all() and np.all(np.abs(a) <= 1.0) for a in act.values())
    if isinstance(target, str):
        assert_like_fresh(target, env)


# ------------------------------------------------------------------------------- satenv.training.load
json_values = st.recursive(st.one_of(st.none(), st.booleans(), st.floats(), st.integers(-10**30, 10**30),
                                     st.text(max_size=5)),
                           lambda inner: (st.lists(inner, max_size=4)
                                          | st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                           max_leaves=8)


norm_edits = st.fixed_dictionaries({"identity": st.just(False),
                               "mean": st.lists(st.one_of(st.floats(), reals), min_size=0, max_size=8),
                               "var": st.lists(st.one_of(st.floats(), reals), min_size=0, max_size=8)},
                               optional={"clip_obs": st.one_of(reals, odd), "epsilon": st.one_of(reals, odd)})


@st.composite
def folder_edits(draw):
    """A list of ``(file, kind, payload)`` corruptions of a good folder and whether to re-hash."""
    edits = []
    for _ in range(draw(st.integers(1, 2))):
        name = draw(st.sampled_from(POLICY_FILE_NAMES + ("model.zip",)))
        kind = draw(st.sampled_from(["delete", "bytes", "json", "truncate", "field", "tensors"]))
        if kind == "bytes":
            payload = draw(st.binary(max_size=64))
        elif kind == "json":
            payload = draw(json_values)
        elif kind == "field":
            payload = (draw(st.sampled_from(["obs_dim", "act_dim", "hidden", "activation", "squash", "format",
                                              "observation_shape", "obs_symlog_scale", "action_power", "norm"])),
                       draw(st.one_of(json_values, st.sampled_from([10**9, [10**5, 10**5], -1, 0, [0], "relu"]))))
        elif kind == "tensors":
            payload = draw(st.sampled_from(["nan", "shape", "dtype", "extra", "missing", "list"]))
        else:
            payload = None
        edits.append((name, kind, payload))
    return edits, draw(st.booleans()), draw(st.one_of(st.none(), norm_edits))


try:  # warm the import, so the first satenv.training.load example does not pay for it
    import torch  # noqa: F401
except ModuleNotFoundError:  # learned policies need torch; without it the load properties skip
    torch = None


def prop_load(case):
    import json
    import tempfile
    from pathlib import Path

    from satenv.training.policy import PolicyLoadError, write_manifest

    if torch is None:
        pytest.skip("torch is not installed")
    edits, rehash, norm = case
    with tempfile.TemporaryDirectory() as tmp:
        root = good_policy_folder(Path(tmp) / "p")
        for edit in edits:
            apply_edit(root, *edit)
        if norm is not None:
            (root / "obs_norm.json").write_text(json.dumps(norm, default=str))
        if rehash and all((root / f).is_file() for f in POLICY_FILE_NAMES[:5]):
            write_manifest(root)
        policy, err = call(training.load, root, errors=(PolicyLoadError,))
        if err is None:
            obs = np.random.default_rng(0).normal(size=(4, 6)) * 10.0 ** np.arange(-2, 2)[:, None]
            act = policy.act({f"follower_{i}": o for i, o in enumerate(obs)})
            assert all(np.isfinite(a).all() and np.all(np.abs(a) <= 1.0) for a in act.values())
        fresh = training.load(good_policy_folder(Path(tmp) / "again"))     # the loader still works
        assert fresh.predict(np.zeros((1, 6))).shape == (1, 3)


def prop_load_path(path, trusted, env):
    from satenv.training.policy import PolicyLoadError

    call(training.load, path, env, trusted=trusted, errors=(PolicyLoadError,))


# ------------------------------------------------------------------------------- make_vec
VEC_REFERENCE = {}


def vec_reference(env_id: str):
    """``make_vec(env_id, 2, seed=0)``: reset then one zero-action step (obs, rewards)."""
    if env_id not in VEC_REFERENCE:
        vec = satenv.make_vec(env_id, 2, seed=0)
        vec.reset()
        obs, rew, *_ = vec.step(np.zeros(vec.action_shape))
        VEC_REFERENCE[env_id] = (vec, obs.copy(), rew.copy())
    return VEC_REFERENCE[env_id]


def prop_make_vec(env_id, num_envs, seed):
    vec, err = call(satenv.make_vec, env_id, num_envs, seed=seed)
    if err is None:
        obs, _ = vec.reset()
        out, err = call(vec.step, np.ones(vec.action_shape))
        assert err is None, f"make_vec({num_envs}, seed={seed}) was built but cannot step: {err}"
        assert finite(obs, out[0], out[1])


def prop_vec_step(env_id, actions):
    vec, ref_obs, ref_rew = vec_reference(env_id)
    vec.reset(seed=0)
    bad = actions(vec.action_shape) if callable(actions) else actions
    out, err = call(vec.step, bad)
    if err is None:
        assert finite(out[0], out[1])
    vec.reset(seed=0)                                   # still steps like a fresh one
    obs, rew, *_ = vec.step(np.zeros(vec.action_shape))
    np.testing.assert_array_equal(obs, ref_obs)
    np.testing.assert_array_equal(rew, ref_rew)


vec_actions = st.one_of(
    values,
    st.sampled_from([
        lambda s: np.zeros(s, np.float32), lambda s: np.zeros(s) + 1j, lambda s: np.zeros(s, bool),
        lambda s: np.ma.masked_array(np.zeros(s), mask=True), lambda s: np.zeros(s, np.int8),
        lambda s: np.full(s, 10**400, dtype=object), lambda s: np.zeros(s[1:]), lambda s: np.zeros((*s, 1)),
        lambda s: np.zeros(s).tolist(), lambda s: np.full(s, np.nan), lambda s: np.full(s, 1e300),
        lambda s: np.full(s, -np.inf, np.float16), lambda s: np.zeros(s, np.float16).view(np.uint16),
    ]),
    st.floats(min_value=-320, max_value=320).map(lambda e: (lambda s: np.full(s, pow10(e)))),
)


BASE = {"deadline": None, "database": None, "derandomize": True,
        "suppress_health_check": [HealthCheck.too_slow, HealthCheck.filter_too_much]}
CASES = {
    "constructor": (prop_constructor, (env_kwargs(),)),
    "reset": (prop_reset, (st.sampled_from(ENV_IDS), st.one_of(st.none(), st.integers(0, 2**70), values), state_edits)),
    "step": (prop_step, (st.sampled_from(ENV_IDS), st.integers(0, 9), action_values)),
    "orbit": (prop_orbit, (orbit_kwargs,)),
    "simulate": (prop_simulate, (st.sampled_from(["cw", "nonlinear", "j2", "j2_drag", "kepler"]), sim_x0,
                                 st.one_of(reals, odd), st.one_of(st.integers(0, 5), reals, odd),
                                 st.one_of(st.none(), st.integers(1, 3), reals, odd))),
    "baseline": (prop_baseline, (baseline_case(),)),
    "load": (prop_load, (folder_edits(),)),
    "load_path": (prop_load_path, (st.one_of(values, st.sampled_from(["/nonexistent", "", ".", b"/tmp"])),
                                   st.one_of(st.booleans(), values),
                                   st.one_of(st.none(), st.sampled_from([object(), 3, "platoon_v0"])))),
    "make_vec": (prop_make_vec, (st.sampled_from(ENV_IDS),
                                 st.one_of(st.integers(-2, 4), values, st.sampled_from([2**20 + 1, 10**9, 2.0])),
                                 st.one_of(st.none(), st.integers(0, 2**70), values))),
    "vec_step": (prop_vec_step, (st.sampled_from(ENV_IDS), vec_actions)),
}


def build(name: str, profile: dict, deadline_ms: float | None):
    fn, strategies = CASES[name]
    return settings(**BASE, **profile)(given(*strategies)(fn)) if deadline_ms is None else \
        settings(**{**BASE, "deadline": deadline_ms}, **profile)(given(*strategies)(fn))


@pytest.mark.parametrize("name", sorted(CASES))
def test_property(name):
    build(name, DEFAULT, deadline_ms=5000)()


@pytest.mark.fuzz
@pytest.mark.parametrize("name", sorted(CASES))
def test_property_fuzz(name):
    build(name, FUZZ, deadline_ms=10000)()


def test_rejected_calls_leave_env_usable():
    """A concrete case of each rejection, then the env steps like a fresh one."""
    for env_id in ENV_IDS:
        env = ENVS[env_id]
        env.reset(seed=0)
        agent = env.agents[0]
        with pytest.raises(SatenvError):
            env.step({**{a: np.zeros(3) for a in env.agents}, agent: np.array([1j, 0, 0])})
        rng_state = env.np_random.bit_generator.state
        with pytest.raises(SatenvError):
            env.reset(seed=5, options={"initial_state": np.full(env.core.sample_initial_state(
                np.random.default_rng(0), 1)[0].shape, 1e41)})
        assert env.np_random.bit_generator.state == rng_state   # not re-seeded either
        assert env.agents                                        # the episode goes on
        assert_like_fresh(env_id, env)


def test_masked_complex_bool_and_overflow_are_rejected():
    with pytest.raises(TypeError, match="dt"):
        satenv.platoon_v0(dt=True)
    for kwargs in ({"u_max": 1e300}, {"dt": 10**400}):
        with pytest.raises(SatenvError):
            satenv.platoon_v0(**kwargs)
    with pytest.raises(SatenvError, match="mean_motion"):
        satenv.formation_v0(mean_motion=1e-300)
    with pytest.raises(SatenvError, match="Orbit"):
        Orbit(a=1e300)
    with pytest.raises(TypeError, match="masked"):
        simulate("cw", np.ma.masked_array([[0.0, 1, 0, 0, 0, 0]]), orbit=Orbit(a=7e6), dt=1.0, steps=1)
    with pytest.raises(TypeError, match="steps"):
        simulate("cw", [[0.0, 1, 0, 0, 0, 0]], orbit=Orbit(a=7e6), dt=1.0, steps=None)
    with pytest.raises(SatenvError, match="inside the Earth"):
        simulate("j2", [[-7e6, 0, 0, 0, 0, 0]], orbit=Orbit(a=7e6), dt=1.0, steps=1)


def test_work_is_capped():
    with pytest.raises(SatenvError, match="MAX_SUBSTEPS"):
        satenv.cluster_v0(dt=5e6)
    with pytest.raises(SatenvError, match="substeps must be <= 1000"):
        satenv.servicing_v0(substeps=10**7)
    with pytest.raises(SatenvError, match="MAX_SUBSTEPS"):
        simulate("j2", [[0.0, 1, 0, 0, 0, 0]], orbit=Orbit(a=7e6), dt=1e12, steps=1)
    with pytest.raises(SatenvError, match="MAX_WORK"):
        simulate("j2", [[0.0, 1, 0, 0, 0, 0]], orbit=Orbit(a=7e6), dt=5000.0, steps=10**5)


def test_finiteness_guard_names_agent_step_and_quantity():
    env = satenv.platoon_v0()
    env.reset(seed=0)
    env.core.x[0, 1, 0] = math.nan      # corrupt the state from outside (as a bug would)
    with pytest.raises(SatenvError, match=r"non-finite observation of .*state of follower_2;.* at step 1"):
        env.step({a: np.zeros(3) for a in env.agents})
    assert env.agents == []             # the episode is over; reset starts a fresh one
    assert_like_fresh("platoon_v0", env)


def test_step_guard_false_alarm_does_not_raise():
    """Huge finite rewards whose sum overflows trip the fast check, but not the error."""
    env = satenv.platoon_v0()
    env.reset(seed=0)
    obs, res = env.core.observe(), env.core.step(np.zeros((1, 4, 3)))
    huge = np.full_like(res.rewards, np.finfo(float).max)
    assert not env._finite_step(obs, res.info["state"], sum(huge[0].tolist()))
    env._nonfinite(obs, huge, res.info["state"])     # exact check: all finite, no error


def test_all_finite_is_exact():
    from satenv.dynamics._checks import all_finite
    for dtype in (np.float32, np.float64):
        x = np.full(37, np.finfo(dtype).max, dtype=dtype)
        assert all_finite(x)                       # huge finite entries: no false alarm
        for bad in (np.nan, np.inf, -np.inf):
            for i in (0, 17, 36):
                y = x.copy()
                y[i] = bad
                assert not all_finite(y)
