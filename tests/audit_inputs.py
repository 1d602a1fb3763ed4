"""Throw bad inputs at every public satenv entry point and count what happens (not a pytest module).

    python tests/audit_inputs.py [--n 600] [--seed 0] [--timeout 5] [--out audit.json]

Entry points: the four env constructors (random fields of random kinds and magnitudes), ``reset``
(seeds and ``initial_state`` options) and ``step`` (actions) of each env, ``Orbit`` and
``simulate``. Each call runs under a SIGALRM timeout and is counted as one of:

``clear``     a ``ValueError``/``TypeError`` raised in satenv code whose message names the field;
``vague``     the same, but the message does not name the field that was changed;
``accepted``  the call returned and everything it produced is finite (for a constructor: also
              the following ``reset`` and one ``step``);
``late``      a constructor accepted the value, but the following ``reset``/``step`` raised a
              clear error (the value should have been rejected up front);
``nonfinite`` silent garbage: a result (state, observation, reward, trajectory) is NaN/inf;
``obscure``   any other exception (``OverflowError``, ``ZeroDivisionError``, ``AttributeError``,
              a ``TypeError`` from ``int(None)``, an error from numpy/scipy internals, ...);
``hang``      the call did not finish within the timeout.

It uses only names that exist before and after the reliability change, so the same script
audits any checkout: ``PYTHONPATH=<checkout> python tests/audit_inputs.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import signal
import sys
import time
import traceback
import warnings
from collections import Counter

import numpy as np

import satenv
from satenv.dynamics import Orbit, simulate

ENVS = ("platoon_v0", "cluster_v0", "servicing_v0", "formation_v0")
CATEGORIES = ("clear", "vague", "accepted", "late", "nonfinite", "obscure", "hang")


class Hang(Exception):
    pass


@contextlib.contextmanager
def time_limit(seconds: float):
    def handler(signum, frame):
        raise Hang()
    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def raised_in_satenv(exc: BaseException) -> bool:
    """True when the innermost frame that raised ``exc`` is satenv's own code."""
    tb = traceback.extract_tb(exc.__traceback__)
    return bool(tb) and f"{os.sep}satenv{os.sep}" in tb[-1].filename


LAST_ERROR: list[str] = [""]


def classify_error(exc: BaseException, field: str) -> str:
    LAST_ERROR[0] = f"{type(exc).__name__}: {str(exc)[:120]}"
    if isinstance(exc, Hang):
        return "hang"
    words = [w for w in field.replace("'", " ").replace("[", " ").split() if w]
    names_field = any(w.lower() in str(exc).lower() for w in words)
    if isinstance(exc, ValueError | TypeError) and raised_in_satenv(exc):
        return "clear" if names_field else "vague"
    return "obscure"


def finite(*arrays) -> bool:
    for a in arrays:
        if isinstance(a, dict):
            if not finite(*a.values()):
                return False
        elif not np.isfinite(np.asarray(a, dtype=float)).all():
            return False
    return True


# ------------------------------------------------------------------------------- bad values
def scalar_pool() -> list:
    return [True, False, 1j, 1 + 0j, np.complex128(2.0), "1.0", None, [], {}, object(), 0, -1, -0.5,
            1e-300, 1e300, -1e300, 10**400, -(10**400), 1e41, math.nan, math.inf, -math.inf,
            np.float32(3e38), np.int64(5), 2**63, 5e6, 1e12, 10**7, 1.5, 0.5, 2, 3,
            np.ma.masked_array(1.0, mask=True), np.array(1.0), np.array([1.0, 2.0]), np.bool_(True)]


def perturb_array(rng: np.random.Generator, value) -> object:
    """A bad (or sometimes fine) variant of an array-like default value."""
    arr = np.array(value, dtype=float)
    kind = int(rng.integers(12))
    if kind == 0:
        return arr * 10.0 ** rng.choice([41, 100, 200, 300, 307])
    if kind == 1:
        out = arr.copy()
        if out.size:
            out.flat[int(rng.integers(out.size))] = rng.choice([np.nan, np.inf, -np.inf, 1e300])
        return out
    if kind == 2:
        return arr + 1j
    if kind == 3:
        return np.ma.masked_array(arr, mask=np.ones(arr.shape, bool))
    if kind == 4:
        return arr.astype(bool)
    if kind == 5:
        return arr.reshape(-1)[:-1] if arr.size > 1 else np.zeros((2, 2))
    if kind == 6:
        return arr.tolist() if arr.ndim else [float(arr)]
    if kind == 7:
        return np.zeros((0,) + arr.shape[1:])
    if kind == 8:
        return arr.astype(object) * 10**400 if arr.size else arr
    if kind == 9:
        return arr * rng.uniform(0.5, 1.5)            # probably fine
    if kind == 10:
        return -arr
    return np.repeat(arr[None], 2, axis=0) if arr.ndim else [arr, arr]


def bad_value(rng: np.random.Generator, default) -> object:
    if default is not None and not isinstance(default, str | bool) and np.ndim(default) > 0 and rng.random() < 0.6:
        with contextlib.suppress(Exception):
            return perturb_array(rng, default)
    pool = scalar_pool()
    if isinstance(default, int | float) and not isinstance(default, bool) and rng.random() < 0.3:
        return default * float(10.0 ** rng.uniform(-320, 300)) if rng.random() < 0.7 else default * rng.uniform(0.5, 2)
    return pool[int(rng.integers(len(pool)))]


# ------------------------------------------------------------------------------- entry points
def audit_constructor(env_id: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    base = satenv.make(env_id)
    defaults = {f.name: getattr(base.scenario, f.name) for f in dataclasses.fields(base.scenario)
                if f.init and not f.name.startswith("_") and f.name != "name"}
    names = sorted(defaults) + ["render_mode", "preset", "no_such_kwarg"]
    picks = rng.choice(names, size=int(rng.integers(1, 3)), replace=False)
    kwargs = {str(n): bad_value(rng, defaults.get(str(n))) for n in picks}
    field = " ".join(kwargs)
    try:
        with time_limit(timeout):
            env = satenv.make(env_id, **kwargs)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    try:
        with time_limit(timeout):
            obs, _ = env.reset(seed=0)
            out = env.step({a: rng.uniform(-1, 1, env.action_space(a).shape) for a in env.agents})
    except BaseException as exc:  # noqa: BLE001
        cat = classify_error(exc, "step reset non-finite")
        return ("late" if cat in ("clear", "vague") else cat), field
    return ("accepted" if finite(obs, out[0], out[1]) else "nonfinite"), field


def fresh_env(env_id: str):
    env = satenv.make(env_id)
    env.reset(seed=0)
    return env


def audit_reset(env, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    x0 = env.core.sample_initial_state(np.random.default_rng(0), 1)[0]
    r = rng.random()
    if r < 0.3:
        kwargs, field = {"seed": bad_value(rng, 1)}, "seed"
    elif r < 0.4:
        kwargs, field = {"options": bad_value(rng, None)}, "options"
    else:
        kwargs, field = {"options": {"initial_state": bad_value(rng, x0)}}, "initial_state"
    try:
        with time_limit(timeout):
            obs, infos = env.reset(**kwargs)
            out = env.step({a: np.zeros(env.action_space(a).shape) for a in env.agents})
    except BaseException as exc:  # noqa: BLE001
        env.reset(seed=0)
        return classify_error(exc, field), field
    ok = finite(obs, out[0], out[1], *[i["state"] for i in infos.values()])
    env.reset(seed=0)
    return ("accepted" if ok else "nonfinite"), field


def audit_step(env, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    if not env.agents:
        env.reset(seed=0)
    shape = env.action_space(env.agents[0]).shape
    actions = {a: rng.uniform(-1, 1, shape) for a in env.agents}
    r = rng.random()
    if r < 0.1:
        actions.pop(env.agents[0])
    elif r < 0.15:
        actions = bad_value(rng, None)
    else:
        actions[env.agents[int(rng.integers(len(env.agents)))]] = bad_value(rng, np.ones(shape))
    try:
        with time_limit(timeout):
            obs, rew, *_ = env.step(actions)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, "action actions agent"), "action"
    if finite(obs, rew):
        return "accepted", "action"
    env.reset(seed=0)
    return "nonfinite", "action"


ORBIT_DEFAULTS = {"a": 6878e3, "e": 0.01, "i": 0.9, "raan": 0.1, "argp": 0.2, "nu": 0.3, "mu": 3.986004418e14}


def audit_orbit(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    kwargs = dict(ORBIT_DEFAULTS)
    picks = rng.choice(sorted(kwargs), size=int(rng.integers(1, 3)), replace=False)
    for n in picks:
        kwargs[str(n)] = bad_value(rng, ORBIT_DEFAULTS[str(n)])
    field = " ".join(str(n) for n in picks) + " Orbit"
    try:
        with time_limit(timeout):
            orbit = Orbit(**kwargs)
            ok = finite(orbit.rv, orbit.n, orbit.period)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    return ("accepted" if ok else "nonfinite"), field


def audit_simulate(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    defaults = {"model": "j2", "x0": np.array([[0.0, 100.0, 0.0, 0.0, 0.0, 0.0]]),
                "orbit": Orbit(a=6878e3, i=0.9), "dt": 10.0, "steps": 5, "u": None, "substeps": None}
    kwargs = dict(defaults, model=str(rng.choice(["cw", "nonlinear", "j2", "j2_drag"])))
    picks = rng.choice(sorted(defaults), size=int(rng.integers(1, 3)), replace=False)
    for n in picks:
        n = str(n)
        if n == "model":
            kwargs[n] = bad_value(rng, None)
        elif n == "orbit":
            kwargs[n] = bad_value(rng, None)
        elif n == "u":
            kwargs[n] = bad_value(rng, np.full((kwargs["steps"], 1, 3), 0.01)) if isinstance(kwargs["steps"], int) else bad_value(rng, None)
        elif n == "x0":
            kwargs[n] = (np.array([[-6878e3, 0, 0, 0, 0, 0.0]]) if rng.random() < 0.15
                         else bad_value(rng, defaults["x0"]))
        else:
            kwargs[n] = bad_value(rng, defaults[n])
    field = " ".join(str(n) for n in picks)
    model = kwargs.pop("model")
    x0 = kwargs.pop("x0")
    try:
        with time_limit(timeout):
            out = simulate(model, x0, **kwargs)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    return ("accepted" if finite(out) else "nonfinite"), field


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=600, help="inputs per entry point")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=5.0, help="seconds per call before it counts as a hang")
    ap.add_argument("--out", default=None, help="write the counts (and examples) as JSON")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    np.seterr(all="ignore")
    rng = np.random.default_rng(args.seed)
    counts: dict[str, Counter] = {}
    examples: dict[str, dict[str, list[str]]] = {}
    entries = [(f"{e}()", lambda r, e=e: audit_constructor(e, r, args.timeout)) for e in ENVS]
    envs = {e: fresh_env(e) for e in ENVS}
    entries += [(f"{e}.reset", lambda r, e=e: audit_reset(envs[e], r, args.timeout)) for e in ENVS]
    entries += [(f"{e}.step", lambda r, e=e: audit_step(envs[e], r, args.timeout)) for e in ENVS]
    entries += [("Orbit", lambda r: audit_orbit(r, args.timeout)),
                ("simulate", lambda r: audit_simulate(r, args.timeout))]
    t0 = time.time()
    for name, fn in entries:
        c = counts[name] = Counter()
        ex = examples[name] = {}
        for _ in range(args.n):
            LAST_ERROR[0] = ""
            cat, field = fn(rng)
            c[cat] += 1
            if cat not in ("clear", "accepted") and len(ex.setdefault(cat, [])) < 5:
                ex[cat].append(f"{field} -> {LAST_ERROR[0]}")
        print(f"{name:22s} " + " ".join(f"{k}={c[k]}" for k in CATEGORIES), flush=True)
    total = Counter()
    for c in counts.values():
        total.update(c)
    print(f"{'total':22s} " + " ".join(f"{k}={total[k]}" for k in CATEGORIES)
          + f"   ({time.time() - t0:.0f} s)")
    result = {"counts": {k: dict(v) for k, v in counts.items()}, "total": dict(total),
              "examples": examples, "n": args.n, "seed": args.seed}
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=1, default=str)
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
