"""Throw bad inputs at every public satenv entry point and count what happens (not a pytest module).

    python tests/audit_inputs.py [--n 600] [--seed 0] [--timeout 5] [--out audit.json]

Entry points: the four env constructors (random fields of random kinds and magnitudes), ``reset``
(seeds and ``initial_state`` options) and ``step`` (actions) of each env, ``Orbit``,
``simulate``, ``satenv.make_vec`` (``num_envs``, seeds) and its ``step`` (actions of random
shapes, dtypes and values), ``satenv.baselines.make`` (every baseline, random options, on envs it does
and does not support and on non-envs; an accepted one acts once) and ``satenv.training.load`` (a good
policy folder with random corruptions: random bytes, random JSON, truncation, deleted files,
edited fields, bad tensors, with and without a re-hashed manifest); and the newest parts: the
filtered envs (``satenv.make(env_id, safety_filter=True)`` and a filtered ``make_vec`` stepped
with actions far outside the box -- 1e300, the most negative float -- and bad actions), the
safety API (``SafetyConfig.from_options``, ``SafetyFilter`` on non-envs and ``filter`` with
actions of other shapes, dtypes and values, ``shield`` with non-policies), every NLP/QP
baseline deciding after its env's true state went non-finite, ``satenv.training.load`` of unusable
paths and of a folder shipped behind its filter without ``env``, ``gymnasium.make`` with bad
``render_mode``/``max_steps``, and ``--resume`` (``satenv.training.train.load_checkpoint``) of corrupted
checkpoints (zip bombs, oversized or torn files). With the default ``--n 600`` that is 40 entry
points, 24,000 cases. Each call runs under a SIGALRM timeout and is counted as one of:

``clear``     a ``ValueError``/``TypeError`` raised in satenv code whose message names the field;
``vague``     the same, but the message does not name the field that was changed;
``accepted``  the call returned and everything it produced is finite (for a constructor: also
              the following ``reset`` and one ``step``);
``late``      a constructor accepted the value, but the following ``reset``/``step`` raised a
              clear error (the value should have been rejected up front);
``nonfinite`` silent garbage: a result (state, observation, reward, trajectory) is NaN/inf;
``obscure``   any other exception (``OverflowError``, ``ZeroDivisionError``, ``AttributeError``,
              a ``TypeError`` from ``int(None)``, an error from numpy/scipy internals, ...);
``hang``      the call did not finish within the timeout;
``out_of_box`` a safety filter returned a finite action outside ``[-1, 1]`` (its box constraint).

A baseline's finite action on a non-finite state that is not flagged (``info["fallbacks"]`` 0)
counts ``vague``; a shipped filtered folder loaded without ``env`` as the bare network counts
``nonfinite`` (silently unsafe); a ``--resume`` whose peak memory grows past ``OVER_CAP_MB``
counts ``over_cap``.

Then two checks beyond bad inputs: **solver faults** (each baseline's solver replaced
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
CATEGORIES = ("clear", "vague", "accepted", "late", "nonfinite", "obscure", "hang", "outside_read",
              "over_cap", "code_ran", "out_of_box")


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
    baselines, training), or ``exc`` is one of the project's own error classes re-raised by a
    library (``gymnasium.make`` re-raises an env's ``TypeError`` as ``type(e)(message + ...)``)."""
    if type(exc).__module__.split(".")[0] in ("satenv", "baselines", "training"):
        return True
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
            fits = isinstance(kwargs["steps"], int) and 0 < kwargs["steps"] <= 10**4
            kwargs[n] = bad_value(rng, np.full((kwargs["steps"], 1, 3), 0.01)) if fits else bad_value(rng, None)
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
    from satenv import baselines
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


# ------------------------------------------------------------------------------- satenv.training.load
def audit_load(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.training.load`` of a good folder with 1-2 random corruptions (random bytes or JSON,
    truncation, deleted files, edited fields, bad tensors, huge safetensors headers, links to a
    file outside, FIFOs, directories, 8 GB sparse files), re-hashed into the manifest half the
    time; also counts files opened outside the folder, memory growth past ``OVER_CAP_MB`` and
    the outside file's content echoed in an error."""
    from pathlib import Path

    from satenv import training
    with tempfile.TemporaryDirectory(dir=tmp) as folder:
        root = good_policy_folder(Path(folder) / "p")
        names = []
        for _ in range(int(rng.integers(1, 3))):
            name = str(rng.choice(POLICY_FILE_NAMES + ("model.zip", "weights.pt")))
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
        if rng.random() < 0.5:
            rehash(root)
        field = " ".join(n for n in names if n)
        trusted = bool(rng.random() < 0.1)
        with watched(str(root)) as seen:
            try:
                with time_limit(timeout):
                    policy = training.load(root, trusted=trusted)
                err = None
            except BaseException as exc:  # noqa: BLE001
                err = exc
        if seen["outside"]:
            LAST_ERROR[0] = f"opened {seen['outside'][:2]}"
            return "outside_read", field
        if seen["grew_mb"] > OVER_CAP_MB:
            LAST_ERROR[0] = f"peak memory grew {seen['grew_mb']:.0f} MB"
            return "over_cap", field
        if err is not None:
            if SECRET in str(err):
                LAST_ERROR[0] = "the error echoes the linked file's content"
                return "outside_read", field
            cat = classify_error(err, field + " policy manifest weights obs_norm")
            names_file = any(n in str(err) for n in (*POLICY_FILE_NAMES, "model.zip", "weights.pt", str(root)))
            if type(err).__name__ == "PolicyLoadError" and cat in ("clear", "vague"):
                cat = "clear" if names_file else "vague"  # a load error must name the file (or folder)
            return cat, field
        if SECRET in json.dumps(policy.meta, default=str):
            return "outside_read", field
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

    from satenv.training.actor import MLPActor
    from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts

    torch.manual_seed(0)
    actor = MLPActor(6, 3, [8], "tanh", False)
    policy = LearnedPolicy(actor, ObsNormalizer(np.zeros(6), np.ones(6), 10.0), obs_shape=(6,))
    meta = {"env_id": "platoon_v0", "observation_shape": [6], "action_shape": [3]}
    return save_artifacts(root, policy, env_meta=meta, config={"algo": "ppo"})


POLICY_FILE_NAMES = ("policy.json", "weights.safetensors", "obs_norm.json", "env.json", "config.json",
                     "manifest.json")
EDIT_KINDS = ("delete", "bytes", "json", "truncate", "field", "tensors", "link", "fifo", "sparse", "dir")
FIELD_EDITS = ("obs_dim", "act_dim", "hidden", "activation", "squash", "format", "observation_shape",
               "obs_symlog_scale", "action_power", "norm")
TENSOR_EDITS = ("nan", "shape", "dtype", "extra", "missing", "list", "bomb", "offsets")
JSON_PAYLOADS = (None, 1, -1e300, "x", [], {}, [1, 2], {"a": None}, {"format": 1}, {"identity": True},
                 {"sha256": {}}, {"format": "satenv-policy/1", "actor": {"type": "mlp"}})
SECRET = "AUDIT-SECRET-5b1e"
"""Content of the file outside every crafted folder that links point to (never to be read)."""


def secret_file() -> str:
    """A file outside the crafted folders (the target of their links)."""
    path = os.path.join(tempfile.gettempdir(), f"audit_secret_{os.getpid()}.json")
    if not os.path.exists(path):
        with open(path, "w") as f:
            f.write(json.dumps({"format": SECRET, "sha256": {SECRET: SECRET}, "identity": SECRET}) + SECRET)
    return path


def apply_edit(root, name, kind, payload) -> None:
    import json

    path = root / name
    special = os.path.islink(path) or (path.exists() and not path.is_file())
    if kind in ("delete", "link", "fifo", "sparse", "dir") or kind in ("bytes", "json") and special:
        if path.is_dir() and not path.is_symlink():
            path.rmdir()
        elif os.path.lexists(path):
            path.unlink()
    if kind == "link":
        path.symlink_to(secret_file())
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "sparse":
        with open(path, "wb") as f:
            f.truncate(8 * 2**30)
    elif kind == "dir":
        path.mkdir()
    elif kind == "bytes":
        path.write_bytes(payload)
    elif kind == "json":
        path.write_text(json.dumps(payload))
    elif special:
        return
    elif kind == "truncate" and path.exists():
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    elif kind == "field":
        key, value = payload
        targets = [root / n for n in ("policy.json", "env.json", "obs_norm.json", "config.json")]
        if any(os.path.lexists(t) and not _regular(t) for t in targets):
            return  # never read or write through a link, FIFO or directory
        try:
            spec = json.loads((root / "policy.json").read_text())
        except (OSError, ValueError):
            return
        if not isinstance(spec, dict) or not isinstance(spec.get("actor"), dict):
            return
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
    elif kind == "tensors" and (root / "weights.safetensors").is_file():
        _edit_tensors(root / "weights.safetensors", payload)


def _regular(path) -> bool:
    return os.path.isfile(path) and not os.path.islink(path)


def _edit_tensors(path, payload) -> None:
    import struct

    import torch
    from safetensors.torch import load_file, save_file

    if payload in ("bomb", "offsets", "list"):
        header = {"body.0.weight": {"dtype": "F32", "shape": [2**15, 2**15] if payload == "bomb" else [8, 6],
                                    "data_offsets": [0, 4 * 2**30] if payload == "bomb" else [0, 10**12]}}
        raw = json.dumps(header).encode() if payload != "list" else b"[1, 2, 3]"
        path.write_bytes(struct.pack("<Q", len(raw)) + raw + b"\0" * 4096)
        return
    try:
        state = load_file(str(path))
    except Exception:  # noqa: BLE001 - an earlier edit broke it: leave it broken
        return
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
    save_file(state, str(path))


def rehash(root) -> None:
    """A manifest matching the folder's regular files (a crafted folder's author can write one;
    links, FIFOs, directories and giant files get a made-up digest)."""
    import hashlib

    digests = {}
    for name in POLICY_FILE_NAMES[:5]:
        path = root / name
        ok = os.path.isfile(path) and not os.path.islink(path) and os.path.getsize(path) < 2**26
        digests[name] = hashlib.sha256(path.read_bytes()).hexdigest() if ok else "0" * 64
    manifest = root / "manifest.json"
    if os.path.isfile(manifest) and not os.path.islink(manifest) or not os.path.lexists(manifest):
        manifest.write_text(json.dumps({"sha256": digests}))


# ------------------------------------------------------------------------------- what a call did
WATCH: dict = {"root": None, "outside": []}
"""The folder whose load is being watched, and the files outside it that were opened."""


def _audit_hook(event: str, args: tuple) -> None:
    root = WATCH["root"]
    if root is None or event != "open" or not args or not isinstance(args[0], str | bytes | os.PathLike):
        return
    path = os.path.abspath(os.fsdecode(args[0]))
    real = os.path.realpath(path)
    if real == WATCH["secret"] or (path.startswith(root + os.sep) and not real.startswith(root + os.sep)):
        WATCH["outside"].append(path)


_HOOKED: list[bool] = []


@contextlib.contextmanager
def watched(root: str | None):
    """Record the files outside ``root`` opened inside the block (``WATCH["outside"]``), and
    the growth of the process's peak memory [MB] (``WATCH["grew_mb"]``)."""
    import resource

    if not _HOOKED:
        sys.addaudithook(_audit_hook)
        _HOOKED.append(True)
    secret = os.path.realpath(secret_file())  # (created before the hook watches)
    WATCH.update(root=None if root is None else os.path.realpath(root), outside=[], secret=secret)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        yield WATCH
    finally:
        WATCH["root"] = None
        WATCH["grew_mb"] = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024


OVER_CAP_MB = 512
"""A call whose peak memory grows by more than this is counted ``over_cap`` (the loads' caps:
2 MiB per JSON member, the weights of the actor ``policy.json`` describes; the crafted actors
are tiny)."""


# ------------------------------------------------------------------------------- solver faults
FAULT_KINDS = ("raise", "shape", "nan", "infeasible", "stall")
STALL_S, STALL_LIMIT_S = 0.05, 0.02
"""A ``stall`` fault sleeps ``STALL_S`` in the solve of a policy built with ``solve_time_limit =
STALL_LIMIT_S``: each such solve must be flagged like any failure."""


def _fault_cases():
    """``(baseline, env_id, options, install(policy, kind, counter) -> undo)`` for every baseline
    with a solver, patching the hooks ``tests/test_baseline_registry.py`` uses."""
    from test_baseline_registry import _bad_point, _FakeNLP

    def dmpc(pol, kind, hits):
        from satenv.baselines.dmpc import QPSolver
        real = QPSolver.solve_raw

        def faulty(self):
            hits[0] += 1
            if kind == "raise":
                raise ValueError("injected")
            x, ok, status = real(self)
            if kind == "stall":
                time.sleep(STALL_S)
                return x, ok, status
            return _bad_point(kind, x), True, status
        QPSolver.solve_raw = faulty
        return lambda: setattr(QPSolver, "solve_raw", real)

    def apf(pol, kind, hits):
        real = pol._law

        def faulty():
            hits[0] += 1
            if kind == "stall":
                time.sleep(STALL_S)
                return real()
            if kind == "raise":
                raise FloatingPointError("injected")
            return _bad_point("nan" if kind == "infeasible" else kind, np.zeros((pol.m, 3)))
        pol._law = faulty
        return lambda: pol.__dict__.pop("_law", None)

    def cgmres(pol, kind, hits):
        import satenv.baselines.cgmres as mod
        real = mod.gmres

        def faulty(matvec, b, x0, kmax):
            hits[0] += 1
            if kind == "raise":
                raise np.linalg.LinAlgError("injected")
            x, rel = real(matvec, b, x0, kmax)
            if kind == "stall":
                time.sleep(STALL_S)
                return x, rel
            return (_bad_point(kind, x), rel) if kind != "infeasible" else (x, 10.0)
        mod.gmres = faulty
        return lambda: setattr(mod, "gmres", real)

    def nlp(attr, bounds):
        def install(pol, kind, hits):
            owner, name = (pol.nlp, "solver_for") if attr == "tube" else (pol, "_nlp")
            real = getattr(owner, name)

            def faulty_for(*bounds_args, solver=None):
                fake = _FakeNLP(kind, *bounds(pol, *bounds_args)) if kind != "stall" else _Stalled(solver)

                def faulty(**args):
                    hits[0] += 1
                    return fake(**args)
                faulty.stats = fake.stats
                return faulty
            if attr == "tube":   # one solver per neighbour-slot count
                setattr(owner, name, lambda k, copy=0, relaxed=False: faulty_for(k, solver=real(k, copy, relaxed)))
            else:
                setattr(owner, name, faulty_for(solver=real))
            return lambda: setattr(owner, name, real)
        return install

    return [("dmpc", "platoon_v0", {"topology": "BDL"}, {"seed": 0}, dmpc),
            ("apf", "cluster_v0", {}, {}, apf),
            ("cgmres", "formation_v0", {}, {}, cgmres),
            ("tube_rdmpc", "cluster_v0", {}, {}, nlp("tube", lambda p, k: p.nlp.row_bounds(k))),
            ("nmpc", "servicing_v0", {}, {"horizon": 5}, nlp("nmpc", lambda p: (p._lbg, p._ubg)))]


class _Stalled:
    """A real CasADi solver that sleeps ``STALL_S`` before each solve."""

    def __init__(self, solver):
        self.solver = solver

    def __call__(self, **args):
        time.sleep(STALL_S)
        return self.solver(**args)

    def stats(self):
        return self.solver.stats()


def _failures(info: dict) -> int:
    """Solver failures recorded in a policy's ``info`` (each one a fallback or, before a retry,
    ``solver_failures``; see ``satenv.baselines.base.guarded_solve``)."""
    return max(info.get("fallbacks", 0), info.get("solver_failures", 0))


def audit_solver_faults(steps: int = 3) -> dict:
    """Inject every fault kind into every baseline's solver for ``steps`` decisions; count each
    injected solve as flagged / crashed / unflagged."""
    from satenv import baselines
    out = {}
    for name, env_id, env_kwargs, options, install in _fault_cases():
        row = Counter()
        kinds = FAULT_KINDS + (("rows",) if name in ("tube_rdmpc", "nmpc") else ())
        for kind in kinds:
            env = satenv.make(env_id, max_steps=steps + 2, **env_kwargs)
            pol = baselines.make(name, env, **options, **({"solve_time_limit": STALL_LIMIT_S}
                                                           if kind == "stall" else {}))
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
    """Folders whose loading would run code if anything were unpickled: a pickle in place of
    ``weights.safetensors``, a pickle ``weights.pt`` (legacy, also loaded with ``trusted=True``,
    which reads it weights-only) and an SB3 ``model.zip``; each would create a marker file."""
    import base64
    import pickle
    import warnings as _warnings
    import zipfile
    from pathlib import Path

    from satenv import training
    from satenv.training.policy import write_manifest

    class Boom:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    tmp = Path(tempfile.mkdtemp(prefix="audit_crafted_"))
    marker = tmp / "CODE_RAN"
    payload = pickle.dumps(Boom())
    errors = []
    weights = good_policy_folder(tmp / "weights")
    (weights / "weights.safetensors").write_bytes(payload)
    write_manifest(weights)
    legacy_pt = good_policy_folder(tmp / "legacy_pt")
    (legacy_pt / "weights.safetensors").unlink()
    (legacy_pt / "weights.pt").write_bytes(payload)
    write_manifest(legacy_pt)
    legacy = tmp / "legacy_zip"
    legacy.mkdir()
    (legacy / "env.json").write_text(json.dumps({"observation_shape": [6]}))
    (legacy / "config.json").write_text(json.dumps({"algo": "ppo"}))
    np.savez(legacy / "obs_norm.npz", identity=np.array(True))
    with zipfile.ZipFile(legacy / "model.zip", "w") as z:
        z.writestr("data", json.dumps({"policy_class": {":type:": "<class 'abc.ABCMeta'>",
                                                        ":serialized:": base64.b64encode(payload).decode()}}))
        z.writestr("policy.pth", payload)
    for folder, trusted in ((weights, False), (weights, True), (legacy_pt, False), (legacy_pt, True),
                            (legacy, False)):
        try:
            with _warnings.catch_warnings():
                _warnings.simplefilter("ignore")
                training.load(folder, trusted=trusted)
            errors.append(f"{folder.name} (trusted={trusted}): loaded")
        except Exception as exc:  # noqa: BLE001
            errors.append(f"{folder.name} (trusted={trusted}): {type(exc).__name__}: {str(exc)[:90]}")
    result = {"code_ran": marker.exists(), "outcomes": errors}
    print(f"crafted policy folders: code ran: {result['code_ran']}; " + " | ".join(errors), flush=True)
    return result


# ------------------------------------------------------------------------------- replayed configs
EVIL_MODULE = "audit_evil_module"
"""A module (written to a temporary folder on ``sys.path``) whose import creates a marker file:
a replayed config naming ``audit_evil_module:make`` must not import it."""


def _evil_module(tmp: str) -> str:
    marker = os.path.join(tmp, "EVIL_IMPORTED")
    with open(os.path.join(tmp, EVIL_MODULE + ".py"), "w") as f:
        f.write(f"open({marker!r}, 'w').close()\n\ndef make(**kw):\n    open({marker!r}, 'w').close()\n")
    if tmp not in sys.path:
        sys.path.insert(0, tmp)
    return marker


class _Reached(Exception):
    """Raised by the stand-in for ``satenv.training.train.train``: the config was accepted."""


def audit_config(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``python -m satenv.training.train --config FILE`` (its ``main``, training replaced by a stub)
    with a shipped config whose env id, baselines or other fields are replaced by random,
    unregistered or code-naming values (``subprocess:run`` with a shell command that would
    create a marker, a module whose import would); ``--allow-code-env-id`` a tenth of the time.
    ``code_ran``: a marker appeared, or a config naming unregistered code reached training
    without the flag."""
    import io
    from pathlib import Path

    import satenv.training.train as tt
    from satenv import baselines

    marker = _evil_module(tmp)
    shell_marker = os.path.join(tmp, "SHELL_RAN")
    base = json.loads((Path(__file__).parents[1] / "satenv/training/policies/platoon_tplf_ppo/config.json").read_text())
    cfg = dict(base, out_dir=os.path.join(tmp, "run"))
    ids = [*satenv.ENV_IDS, "subprocess:run", "os:system", "builtins:exec", f"{EVIL_MODULE}:make", "x:y",
           "platoon_v1", "", "PLATOON_V0", 3, None, ["platoon_v0"], {"a": 1}, "satenv:make", "../../etc:passwd"]
    names = [*baselines.BASELINES, "auto", "os:system", "DMPC", "", None, 7, "subprocess:run", "zero "]
    picks = [str(n) for n in rng.choice(["env_id", "eval_baselines", "env_kwargs", "other"],
                                         size=int(rng.integers(1, 3)), replace=False)]
    for n in picks:
        if n == "env_id":
            cfg["env_id"] = ids[int(rng.integers(len(ids)))]
        elif n == "eval_baselines":
            cfg["eval_baselines"] = [names[int(rng.integers(len(names)))] for _ in range(int(rng.integers(0, 3)))]
        elif n == "env_kwargs":
            cfg["env_kwargs"] = {"args": f"touch {shell_marker}", "shell": True}
        else:
            key = str(rng.choice(sorted(base)))
            cfg[key] = bad_value(rng, base[key] if not isinstance(base[key], list) else None)
    allow = bool(rng.random() < 0.1)
    field = " ".join(picks)
    path = os.path.join(tmp, "config.json")
    with open(path, "w") as f:
        json.dump(_jsonable(cfg), f, default=str)
    argv = ["--config", path, *(["--allow-code-env-id"] if allow else [])]
    real_train = tt.train

    def stub(c, resume=False):
        raise _Reached(c)
    tt.train = stub
    try:
        with time_limit(timeout), contextlib.redirect_stderr(io.StringIO()), \
                contextlib.redirect_stdout(io.StringIO()):
            tt.main(argv)
        outcome = None
    except _Reached as reached:
        outcome = reached.args[0]
    except SystemExit as exc:
        outcome = exc
    except BaseException as exc:  # noqa: BLE001
        outcome = exc
    finally:
        tt.train = real_train
    if any(os.path.exists(m) for m in (marker, shell_marker)):
        for m in (marker, shell_marker):
            with contextlib.suppress(FileNotFoundError):
                os.remove(m)
        LAST_ERROR[0] = "a marker appeared"
        return "code_ran", field
    if isinstance(outcome, SystemExit):
        LAST_ERROR[0] = str(outcome)[:120]
        words = ["env_id", "baseline", "eval_baselines", *picks, *(str(k) for k in cfg)]
        named = any(w and w in str(outcome) for w in words)
        return ("clear" if named else "vague") if outcome.code not in (0, None) else "obscure", field
    if isinstance(outcome, BaseException):
        return classify_error(outcome, field), field
    if outcome.env_id not in satenv.ENV_IDS and not allow:  # training would import and call it
        LAST_ERROR[0] = f"accepted env_id={outcome.env_id!r} without {'--allow-code-env-id'}"
        return "code_ran", field
    if not all(n in baselines.BASELINES or n == "auto" for n in outcome.eval_baselines):
        LAST_ERROR[0] = f"accepted baselines={outcome.eval_baselines} (rejected only later)"
        return "late", field
    return "accepted", field


# ------------------------------------------------------------------------------- metrics
METRIC_NAMES = ("rmse", "rmsee", "foe", "final_position_error", "delta_v_total", "min_separation",
                "collisions", "violations", "safety_cost", "time_to_converge", "success", "summary")
_TRAJ: list = []


def audit_metrics(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """A metric of ``satenv.metrics`` on a recorded trajectory with one random corruption
    (arrays emptied, truncated, reshaped, NaN/inf/huge entries, other dtypes; bad ``dt``, ``t``,
    ``success_tol``, ``collision_voids_success``, ``agents``, ``compute_time``, fallbacks);
    ``nonfinite`` counts a NaN/inf result other than the documented not-converged ``nan``."""
    from satenv import baselines, metrics
    from satenv.rollout import rollout

    if not _TRAJ:
        for env_id in ENVS:
            env = satenv.make(env_id, max_steps=4)
            _TRAJ.append(rollout(env, baselines.make("zero", env), seed=0))
    traj = _TRAJ[int(rng.integers(len(_TRAJ)))]
    keys = ("tracking_error", "accel", "delta_v", "min_separation", "collision", "violations", "cost")
    kind = str(rng.choice(["array", "array", "array", "dt", "t", "tol", "voids", "missing", "agents",
                           "compute", "fallbacks", "none"]))
    rep = dataclasses.replace
    if kind == "array":
        key = str(rng.choice(keys))
        a = np.asarray(traj.info[key])
        how = str(rng.choice(["nan", "inf", "huge", "negative", "empty", "one", "ndim", "complex", "object",
                              "str", "bool", "rows", "cols", "list", "masked"]))
        if how in ("nan", "inf", "huge", "negative"):
            a = a.astype(float).copy()
            a.flat[int(rng.integers(a.size))] = {"nan": np.nan, "inf": -np.inf, "huge": 1e300, "negative": -1e300}[how]
        else:
            a = {"empty": lambda: a[:0], "one": lambda: a[:1], "ndim": lambda: a.reshape(-1),
                 "complex": lambda: a + 1j, "object": lambda: a.astype(object), "str": lambda: a.astype(str),
                 "bool": lambda: a.astype(bool), "rows": lambda: a[:-1], "cols": lambda: a[:, :-1],
                 "list": lambda: a.tolist(), "masked": lambda: np.ma.masked_array(a, mask=True)}[how]()
        bad, field = rep(traj, info={**traj.info, key: a}), key
    elif kind == "dt":
        bad, field = rep(traj, dt=scalar_pool()[int(rng.integers(len(scalar_pool())))]), "dt"
    elif kind == "t":
        t = np.array(traj.t, dtype=float)
        t[int(rng.integers(t.size))] = float(rng.choice([np.nan, -1e9, np.inf]))
        bad, field = rep(traj, t=t), "t"
    elif kind == "tol":
        bad, field = rep(traj, success_tol=scalar_pool()[int(rng.integers(len(scalar_pool())))]), "success_tol"
    elif kind == "voids":
        bad, field = rep(traj, collision_voids_success=scalar_pool()[int(rng.integers(len(scalar_pool())))]), \
            "collision_voids_success"
    elif kind == "missing":
        key = str(rng.choice(keys))
        bad, field = rep(traj, info={k: v for k, v in traj.info.items() if k != key}), key
    elif kind == "agents":
        bad, field = rep(traj, agents=traj.agents[:-1]), "agents"
    elif kind == "compute":
        bad, field = rep(traj, compute_time=np.array([np.nan])), "compute_time"
    elif kind == "fallbacks":
        bad, field = rep(traj, policy_info={"fallbacks": scalar_pool()[int(rng.integers(len(scalar_pool())))]}), \
            "fallbacks"
    else:
        bad, field = traj, "none"
    name = str(rng.choice(METRIC_NAMES))
    kwargs = {"tol": bad_value(rng, 1.0)} if name in ("success", "summary", "time_to_converge") and \
        rng.random() < 0.2 else {}
    if kwargs:
        field += " tol"
    try:
        with time_limit(timeout):
            out = getattr(metrics, name)(bad, **kwargs)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    items = out.items() if isinstance(out, dict) else [(name, out)]
    try:
        ok = all(k in ("time_to_converge", "time_to_converge_s") or not isinstance(v, float | int | np.ndarray)
                 or np.isfinite(np.asarray(v, dtype=float)).all() for k, v in items)
        negative = [k for k, v in items if k in NONNEGATIVE_METRICS and np.any(np.asarray(v, dtype=float) < 0)]
    except (OverflowError, TypeError, ValueError):
        ok, negative = False, []  # a result no float can hold
    if negative:
        LAST_ERROR[0] = f"negative {negative} (a magnitude or count): garbage from a corrupt trajectory"
        ok = False
    return ("accepted" if ok else "nonfinite"), field


NONNEGATIVE_METRICS = frozenset({"delta_v_total", "delta_v", "min_separation", "min_separation_m", "violations",
                                 "safety_cost", "collisions", "rmse", "rmsee", "foe", "final_position_error",
                                 "final_error_m"})
"""Metrics that are magnitudes or counts: a negative value is silent garbage."""


# ------------------------------------------------------------------------------- ids, indices, device, CLIs
def audit_make_id(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.make`` / ``satenv.make_vec`` / ``satenv.training.envs.make_env`` with a bad env id."""
    from satenv.training.envs import make_env

    pool = [["platoon_v0"], None, 3, {"a": 1}, b"platoon_v0", "platoon_v9", "", "PLATOON_V0", "platoon_v0 ",
            ("platoon_v0",), 1.5, "satenv.envs.platoon_v0", "subprocess:run", np.str_("cluster_v0"), object()]
    env_id = pool[int(rng.integers(len(pool)))]
    fn = [satenv.make, lambda e: satenv.make_vec(e, 2), make_env][int(rng.integers(3))]
    if fn is make_env and isinstance(env_id, str) and ":" in env_id:
        fn = satenv.make  # make_env runs a 'module:callable' id by design (the CLI guards it)
    try:
        with time_limit(timeout):
            env = fn(env_id)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, "env id env_id"), "env_id"
    ok = isinstance(env_id, str) and env_id in satenv.ENV_IDS
    return ("accepted" if ok and env is not None else "obscure"), "env_id"


def audit_vec_reset(vec, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``make_vec(...).reset(indices=...)`` with indices of random kinds (floats must not
    silently become copy 0); then one step must work."""
    pool = [[0.5], [1.0], [-1], [2], [0, 1], [], [True, False], [[0], [1]], "0", np.array([0.5]),
            [1 + 0j], [np.nan], [10**20], np.array([True]), [0, 0], object(), [None], range(2), 0]
    indices = pool[int(rng.integers(len(pool)))] if rng.random() < 0.7 else bad_value(rng, np.zeros(2))
    if indices is None:  # None: every copy (documented)
        indices = [0]
    try:
        with time_limit(timeout):
            obs, _ = vec.reset(indices=indices)
            out = vec.step(np.zeros(vec.action_shape))
    except BaseException as exc:  # noqa: BLE001
        vec.reset(seed=0)
        return classify_error(exc, "indices"), "indices"
    with contextlib.suppress(Exception):
        arr = np.asarray(indices)
        if arr.size and arr.dtype.kind not in "biu":
            LAST_ERROR[0] = f"accepted indices={indices!r:.40}"
            return "obscure", "indices"  # a non-integer index silently used
    return ("accepted" if finite(obs, out[0], out[1]) else "nonfinite"), "indices"


def audit_device(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.torchrl.make_env(..., device=...)`` with devices this torch may lack."""
    from satenv.torchrl import make_env

    pool = ["cuda:7", "gpu", None, 3.5, "cpu:0", "meta", "cuda", "mps", "", "cpu", 0, "xla:1", object()]
    device = pool[int(rng.integers(len(pool)))]
    try:
        with time_limit(timeout):
            env = make_env("platoon_v0", 2, device=device)
            td = env.reset()
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, "device"), "device"
    return ("accepted" if finite(td["agents", "observation"].numpy()) else "nonfinite"), "device"


def audit_cli_paths(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``python -m satenv.bench.scoreboard --out PATH`` with PATH a file, a path through a file or
    an existing file's name; ``python -m satenv.bench.reproduce PAPER`` with path-like or unknown
    papers. Either must end in the CLI's own error (a non-zero exit with a message), never a
    traceback, and must leave the file untouched."""
    import io

    target = os.path.join(tmp, "passwd")
    with open(target, "w") as f:
        f.write("root:x:0:0\n")
    if rng.random() < 0.5:
        from satenv.bench.scoreboard.cli import main as board

        out = [target, os.path.join(target, "sub"), target + os.sep][int(rng.integers(3))]
        argv, field = ["--out", out, "--quick", "--no-progress", "--no-plots"], "--out"
        call = board
    else:
        from satenv.bench.reproduce import main as repro

        paper = ["../../etc/passwd", "/etc/passwd", "pereira2023/../x", "", "os", "li2022 ", "subprocess",
                 "satenv.bench.claims", "PEREIRA2023"][int(rng.integers(9))]
        argv, field, call = [paper, "--out", target], "paper", repro
    err = io.StringIO()
    try:
        with time_limit(timeout), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = call(argv)
    except SystemExit as exc:
        code = exc.code
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    with open(target) as f:
        intact = f.read() == "root:x:0:0\n"
    LAST_ERROR[0] = err.getvalue().strip().splitlines()[-1][:120] if err.getvalue().strip() else ""
    if not intact:
        return "nonfinite", field  # the file was overwritten
    return ("clear" if code not in (0, None) and "error" in err.getvalue() else "vague"), field


# ------------------------------------------------------------------------------- safety filter
EXTREMES = (1e300, -1e300, float(np.finfo(float).max), -float(np.finfo(float).max), 1e10, -1e10, 1e154)
"""Finite action values far outside ``[-1, 1]`` (the filtered env must clip or reject them)."""
SAFETY_FIELDS = ("margin", "los_margin", "velocity_margin", "gamma", "penalty")


def extreme_actions(rng: np.random.Generator, agents: list, shape: tuple) -> dict:
    """Every agent (or one) at one extreme finite value, or random huge values per entry."""
    r = rng.random()
    if r < 0.4:
        v = EXTREMES[int(rng.integers(len(EXTREMES)))]
        return {a: np.full(shape, v) for a in agents}
    actions = {a: rng.uniform(-1, 1, shape) for a in agents}
    if r < 0.7:
        actions[agents[int(rng.integers(len(agents)))]] = np.full(shape, EXTREMES[int(rng.integers(len(EXTREMES)))])
    else:
        for a in agents:
            actions[a] = rng.choice(EXTREMES, size=shape)
    return actions


def audit_filtered_step(env, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``step`` of ``satenv.make(env_id, safety_filter=True)``: half the time finite actions far
    outside the box (1e300, the most negative float, ... for every agent or one), else the plain
    step audit's bad actions; the observations, rewards, states and filter records must stay finite."""
    if not env.agents:
        env.reset(seed=int(rng.integers(1000)))
    shape = env.action_space(env.agents[0]).shape
    if rng.random() < 0.5:
        actions = extreme_actions(rng, list(env.agents), shape)
    else:
        actions = {a: rng.uniform(-1, 1, shape) for a in env.agents}
        actions[env.agents[int(rng.integers(len(env.agents)))]] = bad_value(rng, np.ones(shape))
    try:
        with time_limit(timeout):
            obs, rew, _, _, infos = env.step(actions)
    except BaseException as exc:  # noqa: BLE001
        env.reset(seed=0)
        return classify_error(exc, "action actions agent"), "action"
    ok = finite(obs, rew, *[{k: v for k, v in i.items() if k != "safety_active"} for i in infos.values()])
    if not ok:
        LAST_ERROR[0] = "non-finite observation/reward/info after a filtered step"
        env.reset(seed=0)
    return ("accepted" if ok else "nonfinite"), "action"


def audit_filtered_vec(vecs: dict, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``step`` of a filtered ``satenv.make_vec(env_id, 2, safety_filter=True)`` with extreme or bad actions."""
    vec = vecs[str(rng.choice(sorted(vecs)))]
    vec.reset(seed=0)
    if rng.random() < 0.5:
        shape = vec.action_shape
        v = EXTREMES[int(rng.integers(len(EXTREMES)))]
        actions = np.full(shape, v) if rng.random() < 0.5 else rng.choice(EXTREMES, size=shape)
    else:
        actions = bad_value(rng, np.zeros(vec.action_shape))
    try:
        with time_limit(timeout):
            obs, rew, _, _, infos = vec.step(actions)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, "actions"), "actions"
    ok = finite(obs, rew, infos["state"],
                *[infos[k] for k in infos if k.startswith("safety_") and k != "safety_active"])
    return ("accepted" if ok else "nonfinite"), "actions"


def audit_safety_api(envs: dict, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """The safety API: ``SafetyConfig.from_options`` with bad or unknown fields, ``SafetyFilter``
    on non-envs, ``SafetyFilter(env).filter(actions)`` with actions of other shapes (a batch of 2
    for one env, missing agents), dtypes and values, and ``shield(policy, env, ...)`` with
    non-policies; a filtered action must be finite and inside the box."""
    from satenv import baselines
    from satenv.safety import SafetyConfig, SafetyFilter, shield

    env = envs[str(rng.choice(ENVS))]
    kind = str(rng.choice(["config", "config", "target", "filter", "filter", "filter", "shield"]))
    try:
        with time_limit(timeout):
            if kind == "config":
                picks = [str(n) for n in rng.choice(SAFETY_FIELDS + ("no_such_option",),
                                                    size=int(rng.integers(1, 3)), replace=False)]
                options = {n: bad_value(rng, 0.05) for n in picks}
                if rng.random() < 0.3:
                    options[picks[0]] = [10**400, -(10**400), 1e-300, 2**63, np.float64(1e308)][int(rng.integers(5))]
                field = " ".join(picks)
                SafetyConfig.from_options(**options)
                return "accepted", field
            if kind == "target":
                field = "target env"
                SafetyFilter(NON_ENVS[int(rng.integers(len(NON_ENVS)))])
                return "accepted", field
            if kind == "shield":
                field = "policy config"
                policy = [None, object(), 3, "zero", baselines.make("zero", env)][int(rng.integers(5))]
                config = [None, SafetyConfig(), {"margin": 0.1}, 0.1, "x"][int(rng.integers(5))]
                wrapped = shield(policy, env, config)
                obs, _ = env.reset(seed=0)
                act = wrapped.act(obs)
                ok = finite(act) and all(np.all(np.abs(a) <= 1.0) for a in act.values())
                return ("accepted" if ok else "nonfinite"), field
            field = "actions"
            env.reset(seed=0)
            filt = SafetyFilter(env)
            m, d = len(env.possible_agents), env.action_space(env.possible_agents[0]).shape[0]
            shape = [(m, d), (1, m, d), (2, m, d), (m - 1, d), (m, d + 1), (d,), (1, 1, m, d)][int(rng.integers(7))]
            r = rng.random()
            if r < 0.4:
                actions = rng.choice(EXTREMES + (0.5, -0.5), size=shape)
            elif r < 0.8:
                actions = bad_value(rng, np.zeros(shape))
            else:
                actions = bad_value(rng, None)
            safe, _ = filt.filter(actions)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    if not finite(safe):
        return "nonfinite", field
    if not np.all(np.abs(np.asarray(safe, dtype=float)) <= 1.0):
        LAST_ERROR[0] = f"a filtered action outside [-1, 1] (max |u| {np.max(np.abs(safe)):.3g})"
        return "out_of_box", field
    return "accepted", field


# ------------------------------------------------------------------------------- corrupted env states
CORRUPTED_BASELINES = (("apf", "cluster_v0"), ("dmpc", "platoon_v0"), ("nmpc", "servicing_v0"),
                       ("tube_rdmpc", "cluster_v0"), ("cgmres", "formation_v0"))
_CORRUPT: dict = {}


def audit_corrupted_state(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """A scripted baseline deciding after its env's true state went non-finite (NaN/inf at random
    entries of random agents, as an integration blow-up leaves it): the action must be finite, in
    the box, and flagged (``info["fallbacks"]`` > 0) -- never a NaN thrust."""
    from satenv import baselines
    name, env_id = CORRUPTED_BASELINES[int(rng.integers(len(CORRUPTED_BASELINES)))]
    if name not in _CORRUPT:
        env = satenv.make(env_id)
        env.reset(seed=0)
        _CORRUPT[name] = (env, baselines.make(name, env))
    env, policy = _CORRUPT[name]
    obs, _ = env.reset(seed=int(rng.integers(100)))
    policy.reset(seed=0)
    x = env.core.x
    for _ in range(int(rng.integers(1, 4))):
        bad = float(rng.choice([np.nan, np.inf, -np.inf]))   # the value is drawn before the indices
        x[0, int(rng.integers(x.shape[1])), int(rng.integers(x.shape[2]))] = bad
    field = f"{name} state"
    try:
        with time_limit(timeout):
            act = policy.act(obs)
    except BaseException as exc:  # noqa: BLE001
        env.reset(seed=0)
        return classify_error(exc, field), field
    env.reset(seed=0)
    ok = finite(act) and all(np.all(np.abs(a) <= 1.0) for a in act.values())
    if ok and not policy.info.get("fallbacks", 0):
        LAST_ERROR[0] = "a decision on a non-finite state was not flagged (fallbacks == 0)"
        return "vague", field
    return ("accepted" if ok else "nonfinite"), field


# ------------------------------------------------------------------------------- load paths, gymnasium ids, --resume
def audit_load_paths(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.training.load`` of unusable paths (names too long, NUL bytes, missing, a file, a run
    folder without ``final/``), of a shipped filtered folder without ``env`` (must raise, never
    the bare network), and with bad ``env``/``shielded``/``trusted`` arguments."""
    from satenv import training
    shipped = sorted(p for p in training.POLICIES_DIR.iterdir() if (p / "manifest.json").is_file())
    filtered = [p for p in shipped if "safety_filter" in (p / "env.json").read_text()]
    kind = int(rng.integers(8))
    kwargs: dict = {}
    if kind == 0:
        path, field = "x" * int(rng.integers(256, 6000)), "path"
    elif kind == 1:
        path, field = os.path.join(tmp, "a\0b"), "path"
    elif kind == 2:
        path, field = os.path.join(tmp, "missing", "final"), "path"
    elif kind == 3:
        path, field = secret_file(), "path"
    elif kind == 4:
        path, field = tmp, "path final"
    elif kind == 5:
        path, field = str(filtered[int(rng.integers(len(filtered)))]), "shielded filter env"
    elif kind == 6:
        path = str(shipped[int(rng.integers(len(shipped)))])
        env = NON_ENVS[int(rng.integers(len(NON_ENVS)))]
        kwargs, field = {"env": object() if env is None else env}, "env"
    else:
        path = str(shipped[int(rng.integers(len(shipped)))])
        key = str(rng.choice(["shielded", "trusted"]))
        kwargs, field = {key: scalar_pool()[int(rng.integers(len(scalar_pool())))]}, key
        if isinstance(kwargs[key], bool):
            kwargs[key] = "yes"
    try:
        with time_limit(timeout):
            policy = training.load(path, **kwargs)
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    if kind == 5 and type(policy).__name__ != "Shield":
        LAST_ERROR[0] = "a folder shipped behind its filter loaded as the bare network"
        return "nonfinite", field
    return "accepted", field


RENDER_MODES = ("human", "rgb_array", "rgb_array_list", "ansi", "rgb", "", "human_list", "HUMAN")


def audit_gym_make(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``gymnasium.make`` of a registered id with a bad ``render_mode`` (any type) or ``max_steps``."""
    import gymnasium as gym

    gym_id = str(rng.choice(sorted(satenv.GYM_IDS)))
    if rng.random() < 0.6:
        pool = list(RENDER_MODES) + scalar_pool()
        kwargs, field = {"render_mode": pool[int(rng.integers(len(pool)))]}, "render_mode"
        if isinstance(kwargs["render_mode"], str) and kwargs["render_mode"] in ("human", "HUMAN", "human_list"):
            kwargs["render_mode"] = None        # no window in the audit
    else:
        kwargs, field = {"max_steps": bad_value(rng, 300)}, "max_steps"
    try:
        with time_limit(timeout):
            env = gym.make(gym_id, **kwargs)
            obs, _ = env.reset(seed=0)
            out = env.step(np.zeros(env.action_space.shape, np.float32))
            env.close()
    except BaseException as exc:  # noqa: BLE001
        return classify_error(exc, field), field
    return ("accepted" if finite(obs, out[0], out[1]) else "nonfinite"), field


RESUME_EDITS = ("bomb", "stored_big", "truncate", "bytes", "not_zip", "tensors", "npz_bomb", "npz_shape")
_RESUME: dict = {}


def _resume_model(tmp: str):
    """A small PPO model (and SAC with a replay buffer) on platoon_v0 and a checkpoint of each."""
    if not _RESUME:
        from stable_baselines3.common.vec_env import VecNormalize

        from satenv.training.config import TrainConfig
        from satenv.training.envs import make_env
        from satenv.training.train import build_model, save_checkpoint
        from satenv.training.vec_env import SatVecEnv

        for algo in ("ppo", "sac"):
            cfg = TrainConfig(env_id="platoon_v0", num_envs=2, net_arch=(16, 16), algo=algo, buffer_size=64,
                              out_dir=os.path.join(tmp, f"resume_{algo}"), progress=False)
            venv = VecNormalize(SatVecEnv(make_env("platoon_v0"), 2, seed=0))
            model = build_model(cfg, venv)
            folder = save_checkpoint(model, venv, __import__("pathlib").Path(cfg.out_dir), 0)
            _RESUME[algo] = (model, folder, {n: (folder / n).read_bytes() for n in os.listdir(folder)})
    return _RESUME


BOMB_MB = 1024
"""A zip bomb's inflated size [MiB] (about 1 MiB on disk): past ``OVER_CAP_MB``, so reading it
whole is counted ``over_cap``."""
_BOMB: list[bytes] = []


def _zip_bomb(path) -> None:
    """Write the zip bomb (built once: one deflated entry of :data:`BOMB_MB` MiB of zeros)."""
    import io
    import zipfile

    if not _BOMB:   # torch.save's layout (version, byteorder records), its data.pkl deflated
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            zf.writestr("archive/version", "3\n")
            zf.writestr("archive/byteorder", "little")
            info = zipfile.ZipInfo("archive/data.pkl")
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w") as f:
                for _ in range(BOMB_MB):
                    f.write(bytes(2**20))
        _BOMB.append(buf.getvalue())
    with open(path, "wb") as f:
        f.write(_BOMB[0])


def audit_resume(tmp: str, rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.training.train.load_checkpoint`` (what ``--resume`` runs) of a checkpoint with one
    corruption: ``sb3_state.pt`` a zip bomb (:data:`BOMB_MB` inflated), a stored zip beyond the model's
    size, truncated, random bytes, not a zip, other tensors; ``replay_buffer.npz`` a zip bomb or
    arrays of other shapes. Must end in a clear error within the caps (``over_cap`` otherwise)."""
    import zipfile

    import torch

    from satenv.training.train import CHECKPOINT_STATE, load_checkpoint

    algo = "sac" if rng.random() < 0.3 else "ppo"
    model, folder, good = _resume_model(tmp)[algo]
    for name, data in good.items():
        (folder / name).write_bytes(data)
    kind = str(rng.choice(RESUME_EDITS))
    state, buffer = folder / CHECKPOINT_STATE, folder / "replay_buffer.npz"
    if kind == "bomb":
        _zip_bomb(state)
    elif kind == "stored_big":
        with zipfile.ZipFile(state, "w") as zf:
            zf.writestr("archive/data.pkl", bytes(int(rng.integers(8, 64)) * 2**20))
    elif kind == "truncate":
        state.write_bytes(good[CHECKPOINT_STATE][:int(rng.integers(len(good[CHECKPOINT_STATE])))])
    elif kind == "bytes":
        state.write_bytes(rng.bytes(int(rng.integers(0, 4096))))
    elif kind == "not_zip":
        state.write_bytes(b"{}")
    elif kind == "tensors":
        torch.save({"num_timesteps": 1, "n_updates": 0, "state_dicts": {"policy": {"x": torch.zeros(3)}},
                    "tensors": {}}, state)
    elif kind == "npz_bomb" and algo == "sac":
        _zip_bomb(buffer)
    elif kind == "npz_shape" and algo == "sac":
        np.savez(buffer, observations=np.zeros((10**6, 3), np.float32), pos=np.array(0), full=np.array(False))
    field = f"{kind} {CHECKPOINT_STATE} replay_buffer checkpoint"
    with watched(None) as seen:
        try:
            with time_limit(timeout):
                load_checkpoint(model, folder)
            err = None
        except BaseException as exc:  # noqa: BLE001
            err = exc
    if seen["grew_mb"] > OVER_CAP_MB:
        LAST_ERROR[0] = f"peak memory grew {seen['grew_mb']:.0f} MB"
        return "over_cap", field
    if err is not None:
        return classify_error(err, field), field
    return "accepted", field


# ---------------------------------------------------------------- the satenv command's newest sub-commands
POS_INT = ("0", "-1", "1.5", "abc", "", "nan", "null", "[]", "1e999")
"""Values no count of at least 1 may take."""
NONNEG_INT = ("-1", "1.5", "abc", "", "null", "[]")
POS_FLOAT = ("nan", "inf", "-1", "0", "abc", "", "null")
UNIT_FLOAT = ("nan", "-0.1", "1.5", "abc", "", "null")
CHOICE = ("nope", "", "null", "[]")


def _cli_table(tmp: str) -> dict[str, dict]:
    """Per sub-command: a base command line that would run (its output in ``tmp``), the functions
    that start the work (replaced by a stop while auditing: reaching one means the input was
    accepted) and, per flag, values it must refuse."""
    a_file = os.path.join(tmp, "cli_a_file")
    a_dir = os.path.join(tmp, "cli_a_dir")
    missing = os.path.join(tmp, "cli_missing", "config.json")
    os.makedirs(a_dir, exist_ok=True)
    with open(a_file, "w") as f:
        f.write("not json {")
    out_dir = ("", a_file)
    out_file = ("", a_dir, os.path.join(a_file, "sub"))
    in_file = ("", missing, a_dir, a_file)
    folder = good_policy_folder(os.path.join(tmp, "cli_policy"))
    return {
        "train": {"base": ["--out-dir", os.path.join(tmp, "cli_train"), "--eval-every", "0"],
                  "stops": [("satenv.training.train", "build_model")],   # after the env, before the model
                  "flags": {"--budget": POS_INT, "--num-envs": POS_INT, "--n-steps": POS_INT,
                            "--batch-size": POS_INT, "--n-epochs": POS_INT, "--seed": NONNEG_INT,
                            "--lr": POS_FLOAT, "--gamma": UNIT_FLOAT, "--gae-lambda": UNIT_FLOAT,
                            "--algo": CHOICE, "--task": CHOICE, "--env-id": CHOICE, "--out-dir": out_dir,
                            "--config": in_file, "--init-actor": (a_file, a_dir, missing),   # '' is the default: none
                            "--env-kwargs": ("[]", "{", "null", '{"nope": 1}'), "--net-arch": ("0", "-4", "a,b", ""),
                            "--eval-seeds": ("", "5-1", "a"),   # '' is none
                            "--eval-baselines": ("nope", "dmpc,nope")}},
        "ppo": {"base": ["--out-dir", os.path.join(tmp, "cli_ppo")],
                "stops": [("satenv.training.rl.ppo", "Run")],   # after the env, before the learner
                "flags": {"--budget": POS_INT, "--num-envs": POS_INT, "--n-steps": POS_INT,
                          "--minibatch-size": POS_INT, "--n-epochs": POS_INT, "--seed": NONNEG_INT,
                          "--lr": POS_FLOAT, "--gamma": UNIT_FLOAT, "--gae-lambda": UNIT_FLOAT,
                          "--variant": CHOICE, "--task": CHOICE, "--out-dir": out_dir,
                          "--net-arch": ("0", "-4", "a,b", ""), "--test-seeds": ("", "5-1", "a"),
                          "--env-kwargs": ("[]", "{", "null", '{"nope": 1}')}},
        "imitate": {"base": ["--out-dir", os.path.join(tmp, "cli_imitate")],
                    "stops": [("satenv.training.imitation.rounds", "run"),
                              ("satenv.training.imitation.ship", "ship"),
                              ("satenv.training.imitation.ship", "validate_round")],
                    "flags": {"--rounds": ("-1", "1.5", "abc", "", "null"), "--epochs": POS_INT,
                              "--batch-size": POS_INT, "--seed": NONNEG_INT, "--lr": POS_FLOAT,
                              "--task": CHOICE, "--system": CHOICE, "--expert": CHOICE,
                              "--out-dir": out_dir, "--config": in_file, "--warm-start": ("", a_file, missing),
                              "--validate-seeds": POS_INT}},
        "safety-alone": {"base": ["--entry", f"platoon-pereira2023={folder}", "--out",
                                  os.path.join(tmp, "cli_safety")],
                         "stops": [("satenv.bench.safety_alone", "evaluate_entry"),
                                   ("satenv.bench.safety_alone", "write_folders")],
                         "flags": {"--seeds": POS_INT, "--controller-seeds": NONNEG_INT,
                                   "--filter-seeds": NONNEG_INT, "--perturbation-seeds": NONNEG_INT,
                                   "--perturbation-entries": POS_INT, "--out": out_dir,
                                   "--entry": ("", "nope", "platoon-pereira2023=", f"nope={folder}",
                                               f"platoon-pereira2023={a_dir}", f"platoon-pereira2023={folder}@x"),
                                   "--folders-from": in_file}},
        "datasets": {"base": ["write", "--systems", "platoon-pereira2023", "--root", os.path.join(tmp, "cli_minari"),
                              "--manifest", "", "--cache", os.path.join(tmp, "cli_cache")],
                     "stops": [("satenv.bench.learning.datasets", "write"), ("satenv.bench.learning.datasets", "read")],
                     "flags": {"--systems": (",", "nope", "", "all,nope"), "--episodes": POS_INT,
                               "--workers": POS_INT, "--root": out_dir, "--cache": out_dir,
                               "--manifest": (a_dir, os.path.join(a_file, "sub"))}},
        "results": {"base": ["run", "--dry-run", "--log", os.path.join(tmp, "cli_grid", "log.jsonl")],
                    "stops": [("satenv.bench.scoreboard.backends", "stream"),
                              ("satenv.bench.learning.results", "write_results"),
                              ("satenv.bench.learning.render", "write_page")],
                    "flags": {"--log": out_file, "--systems": (",", "nope", ""), "--algorithms": ("nope", ",", ""),
                              "--seeds": ("", "5-1", "a", "-1"), "--rungs": ("0", "a", "9", "2-1"),
                              "--budget": NONNEG_INT, "--workers": POS_INT, "--backend": CHOICE}},
    }


class Started(Exception):
    """A sub-command reached the work it starts: the input was accepted."""


def audit_satenv_cli(tmp: str, rng: np.random.Generator, timeout: float, table: dict) -> tuple[str, str]:
    """``satenv <command> ...`` (train, ppo, imitate, safety-alone, datasets, results) with one
    flag given a value it must refuse: ``clear`` is an exit status 2 (or a satenv ``ValueError``)
    whose one error line names the flag, ``accepted`` (an accepted invalid input) is reaching the
    work the command starts, ``obscure`` any other exception."""
    command = sorted(table)[int(rng.integers(len(table)))]
    spec = table[command]
    flag = sorted(spec["flags"])[int(rng.integers(len(spec["flags"])))]
    value = spec["flags"][flag][int(rng.integers(len(spec["flags"][flag])))]
    return cli_case(command, flag, value, spec, timeout)


def cli_case(command: str, flag: str, value: str, spec: dict, timeout: float) -> tuple[str, str]:
    """One case of :func:`audit_satenv_cli` (``python tests/audit_inputs.py --cli-all`` runs every one)."""
    import importlib
    import io

    from satenv.cli import main as satenv_main

    base = list(spec["base"])
    if flag in base:   # the flag replaces its base value
        i = base.index(flag)
        del base[i:i + 2]
    argv = [command, *base, flag, value]
    field = f"{command} {flag}"

    def stop(*args, **kwargs):
        raise Started

    saved = []
    for module, attr in spec["stops"]:
        mod = importlib.import_module(module)
        saved.append((mod, attr, getattr(mod, attr)))
        setattr(mod, attr, stop)
    err = io.StringIO()
    env_before = os.environ.get("MINARI_DATASETS_PATH")
    try:
        with time_limit(timeout), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = satenv_main(argv)
    except Started:
        LAST_ERROR[0] = f"{flag} {value!r}: accepted (the command started)"
        return "accepted", field
    except SystemExit as exc:
        code = exc.code
    except BaseException as exc:  # noqa: BLE001
        out = classify_error(exc, flag)
        LAST_ERROR[0] = f"{flag} {value!r}: {LAST_ERROR[0]}"
        return out, field
    finally:
        for mod, attr, fn in saved:
            setattr(mod, attr, fn)
        if env_before is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = env_before
    if isinstance(code, str):   # SystemExit("error: ..."): the interpreter prints it on stderr
        err.write(code + "\n")
        code = 1
    text = err.getvalue().strip()
    last = text.splitlines()[-1] if text else ""
    LAST_ERROR[0] = f"{flag} {value!r}: exit {code}: {last[:160]}"
    if code in (0, None):
        return "accepted", field
    if "Traceback" in text:
        return "obscure", field
    names = flag in text or flag.lstrip("-").replace("-", "_") in text
    return ("clear" if "error" in last and names else "vague"), field


def audit_perturbed(rng: np.random.Generator, timeout: float) -> tuple[str, str]:
    """``satenv.perturbations.make_env(task, name)`` with every task and any name (registered or not,
    of the task or another system's): built and stepped once, or a clear error naming the name."""
    from satenv import perturbations, tasks

    names = (*perturbations.PERTURBATIONS, "nope", "", None, 1, "nav-0.1m ")
    task = tasks.get(sorted(tasks.TASKS)[int(rng.integers(len(tasks.TASKS)))])
    name = names[int(rng.integers(len(names)))]
    field = "perturbation"
    try:
        with time_limit(timeout):
            env = perturbations.make_env(task, name)
            obs, _ = env.reset(seed=0)
            out = env.step({a: np.zeros(env.action_space(a).shape, np.float32) for a in env.agents})
    except BaseException as exc:  # noqa: BLE001
        LAST_ERROR[0] = f"{task.name} {name!r}: "
        cat = classify_error(exc, field)
        LAST_ERROR[0] = f"{task.name} {name!r}: {LAST_ERROR[0]}"
        return cat, field
    ok = name is None or name in task.perturbations or isinstance(name, str) and name in perturbations.PERTURBATIONS
    LAST_ERROR[0] = f"{task.name} {name!r}: accepted"
    return ("accepted" if ok and finite(*obs.values(), *out[0].values()) else "nonfinite"), field


def cli_all(timeout: float) -> dict:
    """Every case of the satenv CLIs' table once: counts, and each case not refused clearly."""
    warnings.simplefilter("ignore")
    table = _cli_table(tempfile.mkdtemp(prefix="audit_cli_"))
    counts, unclear = Counter(), []
    for command, spec in sorted(table.items()):
        for flag, values in sorted(spec["flags"].items()):
            for value in values:
                LAST_ERROR[0] = ""
                cat, field = cli_case(command, flag, value, spec, timeout)
                counts[cat] += 1
                if cat != "clear":
                    unclear.append(f"{cat}: {command} {LAST_ERROR[0]}")
    for line in unclear:
        print(line)
    print("satenv CLIs, every case: " + " ".join(f"{k}={counts[k]}" for k in CATEGORIES if counts[k]))
    return {"counts": dict(counts), "unclear": unclear}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=600, help="inputs per entry point")
    ap.add_argument("--n-slow", type=int, default=None, help="inputs for the slow entry points "
                    "(satenv.baselines.make, the CLIs, the TorchRL device; default: --n)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=5.0, help="seconds per call before it counts as a hang")
    ap.add_argument("--out", default=None, help="write the counts (and examples) as JSON")
    ap.add_argument("--only", default="", help="comma-separated substrings: audit only the entry points "
                    "whose name contains one of them ('faults', 'crafted' for the two extra checks)")
    ap.add_argument("--cli-all", action="store_true", help="run every case of the satenv CLIs' table once "
                    "and list those not refused clearly, then stop")
    args = ap.parse_args(argv)
    only = [w for w in args.only.split(",") if w]
    if args.cli_all:
        return cli_all(args.timeout)
    warnings.simplefilter("ignore")
    np.seterr(all="ignore")
    import torch  # noqa: F401  (heavy imports first: an alarm inside an import would leave it half done)
    import torch._dynamo  # noqa: F401  (imported lazily by the first optimiser torch builds)

    import satenv.training.policy  # noqa: F401
    import satenv.training.train  # noqa: F401
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
    entries += [("satenv.baselines.make", lambda r: audit_baseline(envs, r, args.timeout))]
    tmp = tempfile.mkdtemp(prefix="audit_load_")
    entries += [("satenv.training.load", lambda r: audit_load(tmp, r, args.timeout)),
                ("train --config", lambda r: audit_config(tmp, r, args.timeout)),
                ("satenv.metrics", lambda r: audit_metrics(r, args.timeout)),
                ("env ids", lambda r: audit_make_id(r, args.timeout))]
    entries += [(f"{e} vec.reset(indices)", lambda r, e=e: audit_vec_reset(vecs[e], r, args.timeout))
                for e in ENVS]
    entries += [("torchrl device", lambda r: audit_device(r, args.timeout)),
                ("CLI paths", lambda r: audit_cli_paths(tmp, r, args.timeout))]
    filtered = {e: satenv.make(e, safety_filter=True) for e in ENVS}
    for env in filtered.values():
        env.reset(seed=0)
    entries += [(f"{e} filtered.step", lambda r, e=e: audit_filtered_step(filtered[e], r, args.timeout))
                for e in ENVS]
    fvecs = {e: satenv.make_vec(e, 2, seed=0, safety_filter=True) for e in ENVS}
    entries += [("filtered vec.step", lambda r: audit_filtered_vec(fvecs, r, args.timeout)),
                ("safety API", lambda r: audit_safety_api(envs, r, args.timeout)),
                ("baselines, bad state", lambda r: audit_corrupted_state(r, args.timeout)),
                ("satenv.training.load paths", lambda r: audit_load_paths(tmp, r, args.timeout)),
                ("gymnasium.make", lambda r: audit_gym_make(r, args.timeout)),
                ("train --resume", lambda r: audit_resume(tmp, r, args.timeout))]
    entries += [("perturbations.make_env", lambda r: audit_perturbed(r, args.timeout))]
    if not only or any(w in "satenv CLIs" for w in only):
        table = _cli_table(tmp)
        entries += [("satenv CLIs", lambda r: audit_satenv_cli(tmp, r, args.timeout, table))]
    slow = ("satenv.baselines.make", "torchrl device", "CLI paths", "satenv CLIs")
    t0 = time.time()
    entries = [(n, f) for n, f in entries if not only or any(w in n for w in only)]
    for name, fn in entries:
        c = counts[name] = Counter()
        ex = examples[name] = {}
        for _ in range(args.n if name not in slow or args.n_slow is None else args.n_slow):
            LAST_ERROR[0] = ""
            cat, field = fn(rng)
            c[cat] += 1
            if (cat != "clear" and (cat != "accepted" or name == "satenv CLIs")   # there, accepted is invalid
                    and len(ex.setdefault(cat, [])) < 5):
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
