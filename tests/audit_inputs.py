"""Throw bad inputs at every public satenv entry point and count what happens (not a pytest module).

    python tests/audit_inputs.py [--n 600] [--seed 0] [--timeout 5] [--out audit.json]

Entry points: the four env constructors (random fields of random kinds and magnitudes), ``reset``
(seeds and ``initial_state`` options) and ``step`` (actions) of each env, ``Orbit``,
``simulate``, ``satenv.make_vec`` (``num_envs``, seeds) and its ``step`` (actions of random
shapes, dtypes and values), ``baselines.make`` (every baseline, random options, on envs it does
and does not support and on non-envs; an accepted one acts once) and ``training.load`` (a good
policy folder with random corruptions: random bytes, random JSON, truncation, deleted files,
edited fields, bad tensors, with and without a re-hashed manifest). Each call runs under a
SIGALRM timeout and is counted as one of:

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

Then two checks of issue 13 beyond bad inputs: **solver faults** (each baseline's solver replaced
by one that raises, returns a wrong shape, a NaN point or an infeasible point reported as a
success, as in ``tests/test_baseline_registry.py``; every injected solve counted as ``flagged``
(a fallback recorded in ``info``, action finite and in bounds), ``crashed`` (an exception escaped
``act``) or ``unflagged``), and a **crafted policy folder** (``weights.pt`` and an SB3
``model.zip`` whose unpickling would create a marker file): the marker must not appear.

Run it from a checkout: ``PYTHONPATH=<checkout> python tests/audit_inputs.py``.
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
import tempfile
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
    """True when the innermost frame that raised ``exc`` is the project's own code (satenv,
    baselines, training)."""
    tb = traceback.extract_tb(exc.__traceback__)
    return bool(tb) and any(f"{os.sep}{pkg}{os.sep}" in tb[-1].filename
                            for pkg in ("satenv", "baselines", "training"))


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


# ------------------------------------------------------------------------------- make_vec
def audit_make_vec(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    env_id = str(rng.choice(ENVS))
    kwargs = {"num_envs": 2, "seed": 0}
    picks = [str(n) for n in rng.choice(["num_envs", "seed"], size=int(rng.integers(1, 3)), replace=False)]
    for n in picks:
        kwargs[n] = bad_value(rng, kwargs[n]) if rng.random() < 0.8 else int(rng.choice([0, -1, 2**20 + 1, 10**9]))
    field = " ".join(picks)
    try:
        with time_limit(timeout):
            vec = satenv.make_vec(env_id, kwargs["num_envs"], seed=kwargs["seed"])
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    try:
        with time_limit(timeout):
            obs, _ = vec.reset()
            out = vec.step(rng.uniform(-1, 1, vec.action_shape))
    except BaseException as exc:  # noqa: BLE001
        cat = classify_error(exc, "step reset non-finite")
        return ("late" if cat in ("clear", "vague") else cat), field
    return ("accepted" if finite(obs, out[0], out[1]) else "nonfinite"), field


def audit_vec_step(vec, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    vec.reset(seed=0)
    actions = bad_value(rng, np.zeros(vec.action_shape)) if rng.random() < 0.8 else bad_value(rng, None)
    try:
        with time_limit(timeout):
            obs, rew, *_ = vec.step(actions)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, "actions"), "actions"
    return ("accepted" if finite(obs, rew) else "nonfinite"), "actions"


# ------------------------------------------------------------------------------- baselines
NON_ENVS = (None, "platoon_v0", object(), 3, {"name": "platoon_v0"}, np.zeros(3))


def audit_baseline(envs: dict, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    import baselines

    name = str(rng.choice(sorted(baselines.BASELINES)))
    cls = baselines.get(name)
    cfg = getattr(baselines, cls.__name__ + "Config", None)
    defaults = {} if cfg is None else {f.name: f.default for f in dataclasses.fields(cfg) if f.init}
    r = rng.random()
    env = NON_ENVS[int(rng.integers(len(NON_ENVS)))] if r < 0.15 else envs[str(rng.choice(ENVS))]
    names = sorted(defaults) + ["no_such_option"]
    size = min(len(names), int(rng.integers(0, 3))) if r >= 0.15 else 0
    picks = [str(n) for n in rng.choice(names, size=size, replace=False)]
    options = {n: bad_value(rng, defaults.get(n)) for n in picks}
    field = " ".join([cls.__name__, *picks, "env" if r < 0.15 else ""])
    try:
        with time_limit(timeout):
            pol = baselines.make(name, env, **options)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    if r < 0.15:
        return "accepted", field
    try:
        with time_limit(timeout):
            obs, _ = env.reset(seed=0)
            pol.reset(seed=0)
            act = pol.act(obs)
    except BaseException as exc:  # noqa: BLE001
        cat = classify_error(exc, "act")
        return ("late" if cat in ("clear", "vague") else cat), field
    ok = finite(act) and all(np.all(np.abs(a) <= 1.0) for a in act.values())
    return ("accepted" if ok else "nonfinite"), field


# ------------------------------------------------------------------------------- training.load
def audit_load(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    from pathlib import Path

    import training
    from training.policy import write_manifest

    with tempfile.TemporaryDirectory(dir=tmp) as folder:
        root = good_policy_folder(Path(folder) / "p")
        names = []
        for _ in range(int(rng.integers(1, 3))):
            name = str(rng.choice(POLICY_FILE_NAMES + ("model.zip",)))
            kind = str(rng.choice(EDIT_KINDS))
            payload = {"bytes": rng.bytes(int(rng.integers(0, 64))),
                       "json": JSON_PAYLOADS[int(rng.integers(len(JSON_PAYLOADS)))],
                       "field": (str(rng.choice(FIELD_EDITS)), bad_value(rng, 6)),
                       "tensors": str(rng.choice(TENSOR_EDITS))}.get(kind)
            if kind == "field" and payload[0] == "norm":
                payload = ("norm", {"identity": False, "mean": bad_value(rng, np.zeros(6)),
                                    "var": bad_value(rng, np.ones(6))})
            with contextlib.suppress(TypeError, ValueError, OverflowError):
                apply_edit(root, name, kind, _jsonable(payload))
            names += [name, payload[0] if kind == "field" else ""]
        if rng.random() < 0.5 and all((root / f).is_file() for f in POLICY_FILE_NAMES[:5]):
            write_manifest(root)
        field = " ".join(n for n in names if n)
        try:
            with time_limit(timeout):
                policy = training.load(root)
        except BaseException as exc:  # noqa: BLE001
            cat = classify_error(exc, field + " policy manifest weights obs_norm")
            return ("clear" if cat == "vague" and type(exc).__name__ == "PolicyLoadError" else cat), field
        try:
            with time_limit(timeout):
                obs = rng.normal(size=(4, 6)) * 10.0 ** rng.uniform(-3, 300)
                act = policy.act({f"a{i}": o for i, o in enumerate(obs)})
        except BaseException as exc:  # noqa: BLE001
            return classify_error(exc, "act observation"), field
        return ("accepted" if finite(act) and all(np.all(np.abs(a) <= 1) for a in act.values()) else "nonfinite"), field


def _jsonable(value):
    """``value`` with numpy arrays/scalars as lists/floats (JSON payloads); others unchanged."""
    if isinstance(value, tuple):
        return tuple(_jsonable(v) for v in value)
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    return value


def good_policy_folder(root):
    """A small valid policy folder (identity-free normaliser) written by ``save_artifacts``."""
    import torch

    from training.actor import MLPActor
    from training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

    torch.manual_seed(0)
    actor = MLPActor(6, 3, [8], "tanh", False)
    policy = LearnedPolicy(actor, ObsNormalizer(np.zeros(6), np.ones(6), 10.0), obs_shape=(6,))
    meta = {"env_id": "platoon_v0", "observation_shape": [6], "action_shape": [3]}
    return save_artifacts(root, policy, env_meta=meta, config={"algo": "ppo"})


POLICY_FILE_NAMES = ("policy.json", "weights.pt", "obs_norm.json", "env.json", "config.json", "manifest.json")
EDIT_KINDS = ("delete", "bytes", "json", "truncate", "field", "tensors")
FIELD_EDITS = ("obs_dim", "act_dim", "hidden", "activation", "squash", "format", "observation_shape",
               "obs_symlog_scale", "action_power", "norm")
TENSOR_EDITS = ("nan", "shape", "dtype", "extra", "missing", "list")
JSON_PAYLOADS = (None, 1, -1e300, "x", [], {}, [1, 2], {"a": None}, {"format": 1}, {"identity": True},
                 {"sha256": {}}, {"format": "satenv-policy/1", "actor": {"type": "mlp"}})


def apply_edit(root, name, kind, payload) -> None:
    import json

    import torch

    path = root / name
    if kind == "delete":
        path.unlink(missing_ok=True)
    elif kind == "bytes":
        path.write_bytes(payload)
    elif kind == "json":
        path.write_text(json.dumps(payload))
    elif kind == "truncate" and path.exists():
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    elif kind == "field":
        key, value = payload
        spec = json.loads((root / "policy.json").read_text())
        if key in ("obs_dim", "act_dim", "hidden", "activation", "squash"):
            spec["actor"][key] = value
            (root / "policy.json").write_text(json.dumps(spec))
        elif key == "format":
            spec["format"] = value
            (root / "policy.json").write_text(json.dumps(spec))
        elif key == "observation_shape":
            (root / "env.json").write_text(json.dumps({"observation_shape": value}))
        elif key == "norm":
            (root / "obs_norm.json").write_text(json.dumps(value))
        else:
            (root / "config.json").write_text(json.dumps({"algo": "ppo", key: value}))
    elif kind == "tensors" and (root / "weights.pt").is_file():
        state = torch.load(root / "weights.pt", weights_only=True)
        first = next(iter(state))
        if payload == "nan":
            state[first] = torch.full_like(state[first], float("nan"))
        elif payload == "shape":
            state[first] = torch.zeros(3, 3)
        elif payload == "dtype":
            state[first] = state[first].to(torch.int64)
        elif payload == "extra":
            state["extra.weight"] = torch.zeros(2)
        elif payload == "missing":
            del state[first]
        else:
            state = [1, 2, 3]
        torch.save(state, root / "weights.pt")


# ------------------------------------------------------------------------------- solver faults
FAULT_KINDS = ("raise", "shape", "nan", "infeasible")


def _fault_cases():
    """``(baseline, env_id, options, install(policy, kind, counter) -> undo)`` for every baseline
    with a solver, patching the hooks ``tests/test_baseline_registry.py`` uses."""
    from test_baseline_registry import _bad_point, _FakeNLP

    def dmpc(pol, kind, hits):
        from baselines.dmpc import QPSolver
        real = QPSolver.solve_raw

        def faulty(self):
            hits[0] += 1
            if kind == "raise":
                raise ValueError("injected")
            x, ok, status = real(self)
            return _bad_point(kind, x), True, status
        QPSolver.solve_raw = faulty
        return lambda: setattr(QPSolver, "solve_raw", real)

    def apf(pol, kind, hits):
        def faulty():
            hits[0] += 1
            if kind == "raise":
                raise FloatingPointError("injected")
            return _bad_point("nan" if kind == "infeasible" else kind, np.zeros((pol.m, 3)))
        pol._law = faulty
        return lambda: pol.__dict__.pop("_law", None)

    def cgmres(pol, kind, hits):
        import baselines.cgmres as mod
        real = mod.gmres

        def faulty(matvec, b, x0, kmax):
            hits[0] += 1
            if kind == "raise":
                raise np.linalg.LinAlgError("injected")
            x, rel = real(matvec, b, x0, kmax)
            return (_bad_point(kind, x), rel) if kind != "infeasible" else (x, 10.0)
        mod.gmres = faulty
        return lambda: setattr(mod, "gmres", real)

    def nlp(attr, bounds):
        def install(pol, kind, hits):
            owner, name = (pol.nlp, "solver_for") if attr == "tube" else (pol, "_nlp")
            real = getattr(owner, name)

            def faulty_for(*bounds_args):
                fake = _FakeNLP(kind, *bounds(pol, *bounds_args))

                def faulty(**args):
                    hits[0] += 1
                    return fake(**args)
                faulty.stats = fake.stats
                return faulty
            if attr == "tube":   # one solver per neighbour-slot count
                setattr(owner, name, lambda k, copy=0, relaxed=False: faulty_for(k))
            else:
                setattr(owner, name, faulty_for())
            return lambda: setattr(owner, name, real)
        return install

    return [("dmpc", "platoon_v0", {"topology": "BDL"}, {"seed": 0}, dmpc),
            ("apf", "cluster_v0", {}, {}, apf),
            ("cgmres", "formation_v0", {}, {}, cgmres),
            ("tube_rdmpc", "cluster_v0", {}, {}, nlp("tube", lambda p, k: p.nlp.row_bounds(k))),
            ("nmpc", "servicing_v0", {}, {"horizon": 5}, nlp("nmpc", lambda p: (p._lbg, p._ubg)))]


def _failures(info: dict) -> int:
    """Solver failures recorded in a policy's ``info`` (each one a fallback or, before a retry,
    ``solver_failures``; see ``baselines.base.guarded_solve``)."""
    return max(info.get("fallbacks", 0), info.get("solver_failures", 0))


def audit_solver_faults(steps: int = 3) -> dict:
    """Inject every fault kind into every baseline's solver for ``steps`` decisions; count each
    injected solve as flagged / crashed / unflagged."""
    import baselines

    out = {}
    for name, env_id, env_kwargs, options, install in _fault_cases():
        row = Counter()
        kinds = FAULT_KINDS + (("rows",) if name in ("tube_rdmpc", "nmpc") else ())
        for kind in kinds:
            env = satenv.make(env_id, max_steps=steps + 2, **env_kwargs)
            pol = baselines.make(name, env, **options)
            obs, _ = env.reset(seed=0)
            pol.reset(seed=0)
            hits = [0]
            undo = install(pol, kind, hits)
            try:
                for _ in range(steps):
                    before, calls = _failures(pol.info), hits[0]
                    try:
                        act = pol.act(obs)
                    except Exception:  # noqa: BLE001 - a crash is what is counted here
                        row["crashed"] += max(1, hits[0] - calls)
                        break
                    flagged = _failures(pol.info) - before
                    sane = finite(act) and all(np.all(np.abs(a) <= 1.0) for a in act.values())
                    n = hits[0] - calls
                    row["flagged"] += min(flagged, n) if sane else 0
                    row["unflagged"] += n - (min(flagged, n) if sane else 0)
                    obs, *_ = env.step(act)
                    if not env.agents:
                        break
            finally:
                undo()
        out[name] = dict(row, injected=sum(row.values()))
        print(f"solver faults {name:11s} injected={out[name]['injected']} flagged={row['flagged']} "
              f"crashed={row['crashed']} unflagged={row['unflagged']}", flush=True)
    return out


def audit_crafted_policy() -> dict:
    """A ``weights.pt`` and an SB3 ``model.zip`` whose unpickling would create a marker file."""
    import base64
    import pickle
    import zipfile
    from pathlib import Path

    import training
    from training.policy import write_manifest

    class Boom:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    tmp = Path(tempfile.mkdtemp(prefix="audit_crafted_"))
    marker = tmp / "CODE_RAN"
    payload = pickle.dumps(Boom())
    errors = []
    weights = good_policy_folder(tmp / "weights")
    (weights / "weights.pt").write_bytes(payload)
    write_manifest(weights)
    legacy = tmp / "legacy_zip"
    legacy.mkdir()
    (legacy / "env.json").write_text(json.dumps({"observation_shape": [6]}))
    (legacy / "config.json").write_text(json.dumps({"algo": "ppo"}))
    np.savez(legacy / "obs_norm.npz", identity=np.array(True))
    with zipfile.ZipFile(legacy / "model.zip", "w") as z:
        z.writestr("data", json.dumps({"policy_class": {":type:": "<class 'abc.ABCMeta'>",
                                                        ":serialized:": base64.b64encode(payload).decode()}}))
        z.writestr("policy.pth", payload)
    for folder in (weights, legacy):
        try:
            training.load(folder)
            errors.append(f"{folder.name}: loaded")
        except Exception as exc:  # noqa: BLE001
            errors.append(f"{folder.name}: {type(exc).__name__}: {str(exc)[:90]}")
    result = {"code_ran": marker.exists(), "outcomes": errors}
    print(f"crafted policy folders: code ran: {result['code_ran']}; " + " | ".join(errors), flush=True)
    return result


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=600, help="inputs per entry point")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=5.0, help="seconds per call before it counts as a hang")
    ap.add_argument("--out", default=None, help="write the counts (and examples) as JSON")
    ap.add_argument("--only", default="", help="comma-separated substrings: audit only the entry points "
                    "whose name contains one of them ('faults', 'crafted' for the two extra checks)")
    args = ap.parse_args(argv)
    only = [w for w in args.only.split(",") if w]
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
                ("simulate", lambda r: audit_simulate(r, args.timeout)),
                ("make_vec()", lambda r: audit_make_vec(r, args.timeout))]
    vecs = {e: satenv.make_vec(e, 2, seed=0) for e in ENVS}
    entries += [(f"{e} vec.step", lambda r, e=e: audit_vec_step(vecs[e], r, args.timeout)) for e in ENVS]
    entries += [("baselines.make", lambda r: audit_baseline(envs, r, args.timeout))]
    tmp = tempfile.mkdtemp(prefix="audit_load_")
    entries += [("training.load", lambda r: audit_load(tmp, r, args.timeout))]
    t0 = time.time()
    entries = [(n, f) for n, f in entries if not only or any(w in n for w in only)]
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
    if not only or "faults" in only:
        result["solver_faults"] = audit_solver_faults()
    if not only or "crafted" in only:
        result["crafted_policy"] = audit_crafted_policy()
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=1, default=str)
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
