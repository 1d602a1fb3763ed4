"""Property-based tests (hypothesis) over satenv's public entry points.

For random inputs of random types and magnitudes, every call of the four env constructors,
``reset``, ``step``, ``Orbit`` and ``simulate`` either raises a clear error (a
:class:`satenv.errors.SatenvError`, i.e. a ``ValueError``, or its ``TypeError`` subclass) or
returns finite results; it never hangs (hypothesis ``deadline`` plus a hard SIGALRM timeout), and
a rejected call leaves the env usable: it still steps and returns what a fresh env returns.

The default run draws a few examples per property; ``pytest -m fuzz tests/test_properties.py``
runs the same properties with many more.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from audit_inputs import time_limit  # tests/ is on sys.path under pytest (as for truth.py)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import satenv
from satenv.dynamics import Orbit, simulate
from satenv.errors import SatenvError

ENV_IDS = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")
HARD_TIMEOUT = 20.0  # s per example: a hang fails the test instead of stalling the suite
DEFAULT = {"max_examples": 12}
FUZZ = {"max_examples": 400}


def call(fn, *args, **kwargs):
    """``(result, None)`` or ``(None, error)`` for a clear satenv error; anything else fails
    (a call still running after ``HARD_TIMEOUT`` raises ``audit_inputs.Hang``)."""
    with time_limit(HARD_TIMEOUT):
        try:
            return fn(*args, **kwargs), None
        except SatenvError as exc:
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


def scaled(default):
    """A default value scaled by a random power of ten (keeps the kind, changes the magnitude)."""
    return st.floats(min_value=-320, max_value=320).map(
        lambda e: (np.asarray(default, dtype=float) * 10.0 ** e).tolist())


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
                          st.floats(min_value=-320, max_value=320).map(lambda e: np.full(3, 10.0 ** e)))
orbit_kwargs = st.fixed_dictionaries({"a": st.one_of(reals, odd, st.floats(6.5e6, 5e7))},
                                     optional={"e": st.one_of(reals, st.floats(0, 0.99)),
                                               "i": st.one_of(reals, st.floats(0, 3.1)),
                                               "mu": st.one_of(reals, odd), "nu": values})
sim_x0 = st.one_of(
    st.sampled_from([[[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]], [[-6878e3, 0, 0, 0, 0, 0]],
                     [[1e41, 0, 0, 0, 0, 0]], [[0.0, 100.0, 0.0, 0.0, 0.0, 1j]]]),
    values)

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
