"""Learned policies with the baseline interface, and their artefact folders (no pickle).

An artefact folder (written by ``python -m satenv.training.train``, e.g. ``runs/x/final/``, by the
BenchMARL/RLlib exports, or shipped in ``satenv/training/policies/<name>/``) holds only data:

* ``policy.json``          format tag and the actor architecture (:mod:`satenv.training.actor`);
* ``weights.safetensors``  the actor's float32 tensors (safetensors: a JSON header of names,
                           dtypes and shapes, then the raw bytes);
* ``obs_norm.json``        the observation normalisation (``mean``, ``var``, ``clip_obs``,
                           ``epsilon``, or ``{"identity": true}``);
* ``env.json``             env id, version, satenv version, train and eval env kwargs, spaces;
* ``config.json``          the training config (replayable: ``python -m satenv.training.train --config``);
* ``manifest.json``        sha256 of the files above; required, checked on load;
* ``eval.json``            the evaluation summary (optional, not read by :func:`load`).

**A policy folder is untrusted data** (the rules are :mod:`satenv.training.trust`'s): :func:`load`
never unpickles and never imports code named by the folder; it reads only regular files inside
the folder (symbolic links are refused), checks each file's size before reading it and the
tensors' names, dtypes and shapes from the safetensors header before anything is allocated
(at most the actor ``policy.json`` describes, itself capped by ``satenv.training.actor.MAX_PARAMETERS``),
checks every byte it uses against ``manifest.json``, and names the file in every error without
echoing its content. ``trusted=True`` (folders you made) admits a folder without a manifest and
the legacy formats — ``weights.pt`` (:func:`convert_weights_pt` converts it) and an SB3
``model.zip``, whose unpickling runs any code it contains (:func:`convert_sb3`) — with a
``UserWarning`` saying what was skipped.

``load(path)`` (a policy folder, or a run folder holding ``final/``) returns a
:class:`LearnedPolicy` with ``reset(seed=None)`` and ``act(observations) -> actions`` (dicts
keyed by agent, actions in ``[-1, 1]``), usable anywhere a scripted baseline is
(``satenv.rollout.rollout``, the scoreboard); a folder that ships behind its safety filter needs
``load(path, env=env)`` (returned filtered) or ``shielded=False`` (the network alone), else it is
refused (:class:`ShippedFilterError`).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import re
import warnings
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from satenv.errors import SatenvError
from satenv.training.trust import (
    MAX_HEADER_BYTES,
    MAX_JSON_BYTES,
    UntrustedDataError,
    member,
    parse_json,
    read_json,
    read_member,
    safetensors_arrays,
    sha256_file,
)

__all__ = ["INFERENCE_THREADS", "LearnedPolicy", "PolicyLoadError", "ShippedFilterError", "load", "policy_folder",
           "save_artifacts", "ObsNormalizer", "from_sb3", "convert_sb3", "convert_weights_pt", "write_manifest"]

FORMAT = "satenv-policy/1"
WEIGHTS = "weights.safetensors"
"""The actor's weights (float32 safetensors: a JSON header of names, dtypes and shapes first)."""
LEGACY_WEIGHTS = "weights.pt"
"""The former torch format (:func:`convert_weights_pt`); loaded only with ``trusted=True``."""
POLICY_FILES = ("policy.json", WEIGHTS, "obs_norm.json", "env.json", "config.json")
"""The files :func:`load` reads (and the manifest covers)."""
MANIFEST = "manifest.json"
MAX_MANIFEST_BYTES = 2**16
"""Cap on ``manifest.json``."""


def max_weights_bytes() -> int:
    """Cap on a weights file: the largest actor :mod:`satenv.training.actor` allows (``MAX_PARAMETERS``
    float32, ~201 MB with the header); a given ``policy.json``'s file may hold only its actor."""
    from satenv.training.actor import MAX_PARAMETERS

    return 8 + MAX_HEADER_BYTES + 4 * MAX_PARAMETERS


class PolicyLoadError(SatenvError):
    """A learned policy cannot be loaded or does not fit the environment."""


INFERENCE_THREADS = 1
"""Torch threads of a loaded policy's forward pass: a small MLP on a few agents is fastest on one
(more threads only add synchronisation, and on a busy machine wait for cores)."""


@contextlib.contextmanager
def torch_threads(n: int):
    """Run the block with ``torch.set_num_threads(n)`` and restore the caller's count after it
    (nothing is set when it is already ``n``)."""
    import torch

    before = torch.get_num_threads()
    if before == n:
        yield
        return
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


class ObsNormalizer:
    """``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` (SB3 ``VecNormalize``).

    Validated: ``mean`` and ``var`` finite arrays of one shape with ``var >= 0``, ``epsilon >= 0``
    and ``var + epsilon > 0``, ``clip_obs > 0``.
    """

    def __init__(self, mean: Any = None, var: Any = None, clip_obs: float = math.inf,
                 epsilon: float = 1e-8) -> None:
        if (mean is None) != (var is None):
            raise ValueError("obs normaliser: give both mean and var, or neither (identity)")
        self.clip_obs, self.epsilon = float(clip_obs), float(epsilon)
        if not self.clip_obs > 0 or not (math.isfinite(self.epsilon) and self.epsilon >= 0):
            raise ValueError(f"obs normaliser: clip_obs must be > 0 and epsilon finite >= 0, got "
                             f"clip_obs={clip_obs!r}, epsilon={epsilon!r}")
        self.mean = self.var = None
        if mean is not None:
            self.mean, self.var = np.asarray(mean, dtype=np.float64), np.asarray(var, dtype=np.float64)
            if self.mean.ndim != 1 or self.mean.shape != self.var.shape:
                raise ValueError(f"obs normaliser: mean and var must be 1-D of one shape, got "
                                 f"{self.mean.shape} and {self.var.shape}")
            if not (np.isfinite(self.mean).all() and np.isfinite(self.var).all()):
                raise ValueError("obs normaliser: mean and var must be finite, got NaN/inf entries")
            if (self.var < 0).any() or not (self.var + self.epsilon > 0).all():
                raise ValueError(f"obs normaliser: variance must be >= 0 with var + epsilon > 0, got "
                                 f"min var {self.var.min()!r}, epsilon {self.epsilon!r}")

    @classmethod
    def from_vecnormalize(cls, venv: Any) -> ObsNormalizer:
        """A frozen copy of a ``VecNormalize``'s current statistics (identity if it does not normalise)."""
        if venv is None or not getattr(venv, "norm_obs", False):
            return cls()
        return cls(venv.obs_rms.mean.copy(), venv.obs_rms.var.copy(), venv.clip_obs, venv.epsilon)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):   # beyond float32: inf, flagged by predict
            if self.mean is None:
                return obs.astype(np.float32)
            out = (obs - self.mean) / np.sqrt(self.var + self.epsilon)
            return np.clip(out, -self.clip_obs, self.clip_obs).astype(np.float32)

    def to_json(self) -> dict[str, Any]:
        if self.mean is None:
            return {"identity": True}
        return {"identity": False, "mean": self.mean.tolist(), "var": self.var.tolist(),
                "clip_obs": self.clip_obs if math.isfinite(self.clip_obs) else "inf", "epsilon": self.epsilon}

    @classmethod
    def from_json(cls, data: Any) -> ObsNormalizer:
        if not isinstance(data, dict) or not isinstance(data.get("identity"), bool):
            raise ValueError("obs_norm.json must be an object with a bool 'identity'")
        if data["identity"]:
            return cls()
        unknown = set(data) - {"identity", "mean", "var", "clip_obs", "epsilon"}
        if unknown:
            raise ValueError(f"obs_norm.json: unknown field(s) {sorted(unknown)}")
        clip = data.get("clip_obs", "inf")
        return cls(data["mean"], data["var"], math.inf if clip == "inf" else clip, data.get("epsilon", 1e-8))


class LearnedPolicy:
    """A trained actor (:class:`satenv.training.actor.MLPActor`) behind the baseline interface.

    One shared actor for every agent: ``act`` stacks the agents' observations (in the dict's
    order), applies the feature map and the saved normalisation, and returns the deterministic
    actions clipped to ``[-1, 1]`` (then the action map).
    """

    name = "learned"

    def __init__(self, actor: Any, normalizer: ObsNormalizer | None = None, *, obs_shape: tuple[int, ...],
                 features: Any = None, action_map: Any = None, meta: dict[str, Any] | None = None,
                 terminal: Any = None) -> None:
        self.actor = actor.eval()
        self.normalizer = normalizer or ObsNormalizer()
        self.features = features
        self.action_map = action_map
        self.terminal = terminal      # satenv.training.shaping.TerminalFeedback (None: the network alone)
        self.meta = dict(meta or {})
        self.obs_shape = tuple(obs_shape)  # the env's per-agent observation (before the features)
        self.action_shape = (int(actor.spec["act_dim"]),)
        self.info: dict[str, Any] = {"fallbacks": 0}

    def reset(self, seed: int | None = None) -> None:
        self.info = {"fallbacks": 0}

    def network_input(self, obs: np.ndarray) -> np.ndarray:
        """The actor's float32 input for raw observations ``(..., *obs_shape)``: the feature map, then
        the saved normalisation."""
        return self.normalizer(self.features(obs) if self.features is not None else obs)

    def env_action(self, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """What the env is given for network actions ``actions`` at raw observations ``obs``: clipped to
        ``[-1, 1]``, then the action map and the terminal feedback (which reads ``obs``)."""
        actions = np.clip(actions, -1.0, 1.0)
        if self.action_map is not None:
            actions = self.action_map(actions)
        return self.terminal(obs, actions) if self.terminal is not None else actions

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, act_dim)`` in ``[-1, 1]`` for raw per-agent observations ``(n, *obs_shape)``."""
        import torch

        with torch.no_grad(), torch_threads(INFERENCE_THREADS):
            y = self.actor(torch.as_tensor(self.network_input(obs))).numpy()
        actions = self.env_action(obs, y.astype(np.float64))   # non-finite entries checked below
        bad = ~np.isfinite(actions).all(axis=-1)
        if bad.any():  # e.g. an observation beyond the float range: the safe action, flagged
            actions[bad] = 0.0
            self.info["fallbacks"] = self.info.get("fallbacks", 0) + int(bad.sum())
            self.info["solver_status"] = "non-finite action (actor output or terminal feedback): zero action"
        return actions.astype(np.float32)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        if not isinstance(observations, dict) or not observations:
            raise ValueError(f"observations must be a non-empty dict {{agent: array {self.obs_shape}}}, "
                             f"got {type(observations).__name__}")
        agents = list(observations)
        obs = np.empty((len(agents), *self.obs_shape), dtype=np.float64)
        for i, a in enumerate(agents):
            o = np.asarray(observations[a], dtype=np.float64)
            if o.shape != self.obs_shape:
                raise PolicyLoadError(f"observation of {a} has shape {o.shape} but the policy was trained "
                                      f"on shape {self.obs_shape} ({self.meta.get('env_id', '?')}, "
                                      f"kwargs {self.meta.get('env_kwargs', {})}); use the env it was trained on")
            obs[i] = o
        actions = self.predict(obs)
        return {a: actions[i] for i, a in enumerate(agents)}

    def check_env(self, env: Any) -> None:
        """Raise :class:`PolicyLoadError` if ``env``'s per-agent spaces differ from the policy's.

        Also warns (``UserWarning``) when ``env`` is another env than the one trained on, or its
        scenario differs from the training kwargs (same spaces, but out of distribution).
        """
        for agent in env.possible_agents:
            o, a = env.observation_space(agent).shape, env.action_space(agent).shape
            if tuple(o) != self.obs_shape or tuple(a) != self.action_shape:
                raise PolicyLoadError(
                    f"policy expects observations {self.obs_shape} / actions {self.action_shape}, but "
                    f"{agent} of {env.metadata.get('name', type(env).__name__)} has {tuple(o)} / {tuple(a)}; "
                    f"the policy was trained on {self.meta.get('env_id', '?')} with kwargs "
                    f"{self.meta.get('env_kwargs', {})}")
        trained_on = self.meta.get("env_name")
        name = env.metadata.get("name") if hasattr(env, "metadata") else None
        if trained_on and name and trained_on != name:
            warnings.warn(f"policy trained on {trained_on}, used on {name}", stacklevel=3)
        scenario = getattr(env, "scenario", None)
        mismatched = []
        for key, value in (self.meta.get("eval_env_kwargs") or {}).items():
            if scenario is None or not hasattr(scenario, key):
                continue
            have = getattr(scenario, key)
            try:
                same = np.array_equal(np.asarray(have, dtype=float), np.asarray(value, dtype=float))
            except (TypeError, ValueError):
                same = have == value
            if not same:
                mismatched.append(f"{key}={have!r} (trained with {value!r})")
        if mismatched:
            message = "env scenario differs from the policy's training/evaluation setting: " + ", ".join(mismatched)
            if message not in _WARNED_SETTINGS:   # once per process, however many policies or loads
                _WARNED_SETTINGS.add(message)
                warnings.warn(message, stacklevel=3)


_WARNED_SETTINGS: set[str] = set()
"""The scenario-mismatch warnings :meth:`LearnedPolicy.check_env` has given in this process."""


def features_from_config(config: dict[str, Any]):
    """The observation feature map of a run config (``None`` when off)."""
    from satenv.training.shaping import ObsFeatures

    feats = ObsFeatures(config.get("obs_symlog_scale", 0.0), config.get("obs_symlog_dims", 6),
                        tuple(config.get("obs_drop_dims", ())))
    return feats if feats.active else None


def terminal_from_config(config: dict[str, Any]):
    """The terminal feedback of a run config (``None`` when off)."""
    from satenv.training.shaping import TerminalFeedback

    term = TerminalFeedback.from_config(config)
    return term if term.active else None


def action_map_from_config(config: dict[str, Any]):
    """The action map of a run config (``None`` when it is the identity)."""
    from satenv.training.shaping import ActionMap

    amap = ActionMap(config.get("action_power", 1.0))
    return amap if amap.active else None




# ----------------------------------------------------------------------------- SB3 export
def _sb3_actor(model: Any):
    """The deterministic actor of an SB3 PPO/SAC ``MlpPolicy`` as an :class:`MLPActor`."""
    from torch import nn

    from satenv.training.actor import MLPActor

    policy = model.policy
    if hasattr(policy, "action_net"):  # PPO / A2C: mlp_extractor.policy_net -> action_net [-> tanh]
        body, head, squash = policy.mlp_extractor.policy_net, policy.action_net, False
        if isinstance(head, nn.Sequential):   # satenv.training.train.build_model of a squashed seed
            if len(head) != 2 or not isinstance(head[0], nn.Linear) or not isinstance(head[1], nn.Tanh):
                raise PolicyLoadError(f"cannot export a PPO action head {head}: expected Linear or Linear -> Tanh")
            head, squash = head[0], True
    elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):  # SAC: latent_pi -> mu -> tanh
        body, head, squash = policy.actor.latent_pi, policy.actor.mu, True
    else:
        raise PolicyLoadError(f"cannot export a {type(policy).__name__}: expected an SB3 PPO/SAC MlpPolicy")
    linears = [m for m in body if isinstance(m, nn.Linear)]
    acts = {type(m).__name__.lower() for m in body if not isinstance(m, nn.Linear)}
    if len(acts) > 1:
        raise PolicyLoadError(f"cannot export an actor mixing activations {sorted(acts)}")
    activation = acts.pop() if acts else "tanh"
    obs_dim = int(np.prod(model.observation_space.shape))
    actor = MLPActor(obs_dim, int(head.out_features), [m.out_features for m in linears], activation, squash)
    return actor.copy_linear_weights([*linears, head])


def from_sb3(model: Any, normalizer: ObsNormalizer, *, obs_shape: tuple[int, ...], features: Any = None,
             action_map: Any = None, meta: dict[str, Any] | None = None) -> LearnedPolicy:
    """The :class:`LearnedPolicy` of an in-memory SB3 model (a copy of its actor's weights)."""
    return LearnedPolicy(_sb3_actor(model), normalizer, obs_shape=obs_shape, features=features,
                         action_map=action_map, meta=meta)


# ----------------------------------------------------------------------------- load / save
def _manifest(root: Path) -> dict[str, str] | None:
    """The ``{file: sha256}`` table of ``manifest.json`` (``None`` when the folder has none)."""
    try:
        member(root, MANIFEST, MAX_MANIFEST_BYTES)
    except UntrustedDataError:
        if not os.path.lexists(root / MANIFEST):
            return None
        raise
    listed = read_json(root, MANIFEST, MAX_MANIFEST_BYTES)
    table = listed.get("sha256") if isinstance(listed, dict) else None
    if not (isinstance(table, dict) and all(isinstance(k, str) and isinstance(v, str) and len(v) == 64
                                            for k, v in table.items())):
        raise PolicyLoadError(f"{root / MANIFEST}: expected {{\"sha256\": {{file: 64 hex digits}}}}")
    return table


def _check_manifest(root: Path, table: dict[str, str], blobs: dict[str, bytes]) -> None:
    """Raise unless every file read (``blobs``: name -> the bytes that will be parsed) is listed
    in the manifest ``table`` with its sha256 (so what is checked is what is used)."""
    missing = sorted(set(blobs) - set(table))
    if missing:
        raise PolicyLoadError(f"{root / MANIFEST}: does not list {missing}; re-save the folder "
                              "(satenv.training.policy.write_manifest) if you made it")
    bad = [name for name in blobs if hashlib.sha256(blobs[name]).hexdigest() != table[name]]
    if bad:
        raise PolicyLoadError(f"{str(root)!r}: {bad} do not match {MANIFEST} (changed after saving?); "
                              "re-save the folder or restore the files")


def load(path: str | Path, env: Any = None, *, trusted: bool = False, shielded: bool = True) -> Any:
    """Load the policy in artefact folder ``path``; if ``env`` is given, check its spaces fit.

    ``path`` is a policy folder or a run folder (``--out-dir`` of a trainer), whose ``final/``
    is then loaded.

    A folder whose ``env.json`` has ``"safety_filter"`` ships behind the safety filter: with
    ``env`` given (and ``shielded``, the default) it is returned as shipped,
    ``satenv.safety.shield(network, env, **options)``; ``shielded=False`` returns the network
    alone (its own numbers, reported beside the shipped ones). Without ``env`` the filter cannot
    be built (it reads the env's state), so loading fails closed: :class:`ShippedFilterError`
    unless ``shielded=False`` asks for the network alone.

    Inference runs on one torch thread (:data:`INFERENCE_THREADS`, set around each forward pass
    and restored after it, so the caller's ``torch.get_num_threads()`` is unchanged): a small MLP
    is fastest on one thread, and much slower with the default threads on a busy machine.

    The folder is untrusted data (module docstring, :mod:`satenv.training.trust`): nothing in it runs,
    nothing outside it is read, sizes are capped before reading, and ``manifest.json`` must list
    the sha256 of every file read. ``trusted=True`` (for folders you made) lifts only: the
    requirement that a manifest exists (a present one is still checked), and the refusal of
    the legacy formats — ``weights.pt`` (read with ``torch.load(weights_only=True)``, sizes not
    checked before allocation) and an SB3 ``model.zip`` (unpickled: runs any code in it); a
    ``UserWarning`` says what was skipped. Every failure raises :class:`PolicyLoadError` (a
    ``ValueError``) naming the file.
    """
    if not isinstance(path, str | PathLike) or not isinstance(trusted, bool):
        raise PolicyLoadError(f"load(path, env=None, *, trusted=False): path must be a str or os.PathLike "
                              f"and trusted a bool, got path={path!r:.80}, trusted={trusted!r:.40}")
    if not isinstance(shielded, bool):
        raise PolicyLoadError(f"shielded must be a bool, got {shielded!r:.40}")
    root = policy_folder(path)
    try:
        if not os.path.lexists(root / WEIGHTS) and not os.path.lexists(root / LEGACY_WEIGHTS) \
                and os.path.lexists(root / "model.zip"):
            policy = _load_sb3_zip(root, trusted)
        else:
            policy = _load_safe(root, trusted)
    except UntrustedDataError as err:
        raise PolicyLoadError(str(err)) from None
    if env is not None:
        if not (isinstance(getattr(env, "possible_agents", None), list | tuple)
                and callable(getattr(env, "observation_space", None))):
            raise PolicyLoadError(f"env must be a PettingZoo env (possible_agents, observation_space), "
                                  f"got {type(env).__name__}")
        policy.check_env(env)
    config = shipped_filter(root, getattr(policy, "meta", {}))
    if config is None or not shielded:
        return policy
    if env is None:
        raise ShippedFilterError(
            f"{root}: this policy ships behind the safety filter (env.json 'safety_filter'), which needs "
            f"the env it flies in: load it with satenv.training.load(path, env=env) to get it as shipped, "
            f"filter included, or with shielded=False for the network alone (not safe to fly by itself)")
    from satenv.safety import shield

    return shield(policy, env, config)


class ShippedFilterError(PolicyLoadError):
    """A policy that ships behind its safety filter was loaded without the env the filter needs."""


def policy_folder(path: str | PathLike) -> Path:
    """The artefact folder ``path`` names: ``path`` itself, or its ``final/`` when ``path`` is a
    run folder (no network of its own — ``policy.json``, weights, ``model.zip`` — and a
    ``final/`` folder inside; a run folder's ``config.json`` is its own). A symbolic link is followed
    only to a sibling folder (``runs/latest -> runs/x``); one out of its folder is refused. A path
    the OS cannot look up (too long, a loop, no permission) is a :class:`PolicyLoadError`."""
    root = Path(path)
    shown = f"{str(path)!r:.200}"
    try:
        if root.is_symlink() and root.resolve().parent != root.parent.resolve():
            raise PolicyLoadError(f"learned policy path {shown} is a symbolic link out of its folder; a link is "
                                  "followed only to a sibling (runs/latest -> runs/x): pass the folder it points to")
        if not root.is_dir():
            raise PolicyLoadError(f"learned policy path {shown} is not a directory; expected an artefact "
                                  f"folder with {list(POLICY_FILES)} (e.g. runs/<run>/final or "
                                  "satenv/training/policies/<name>) or a run folder holding final/")
        own = any(os.path.lexists(root / name) for name in ("policy.json", WEIGHTS, LEGACY_WEIGHTS, "model.zip"))
        if not own and (root / "final").is_dir() and not (root / "final").is_symlink():
            return root / "final"
    except OSError as err:
        raise PolicyLoadError(f"learned policy path {shown}: cannot be looked up ({err.strerror or err})") from None
    return root


SHIELD_WRAPPER = "satenv.safety.shield"
"""The one wrapper a folder's ``env.json`` ``"safety_filter"`` may name (it is compared, never imported)."""


def shipped_filter(root: Path, meta: dict[str, Any]) -> Any:
    """The ``satenv.safety.SafetyConfig`` a folder ships with (``env.json`` ``"safety_filter"``),
    or None. The entry is data: ``wrapper`` must be :data:`SHIELD_WRAPPER` and ``options`` a JSON
    object of ``SafetyConfig`` fields (validated here, so a bad one names the file)."""
    entry = meta.get("safety_filter")
    if entry is None:
        return None
    if not (isinstance(entry, dict) and entry.get("wrapper") == SHIELD_WRAPPER
            and isinstance(entry.get("options", {}), dict)):
        raise PolicyLoadError(f"{root / 'env.json'}: safety_filter must be an object with wrapper "
                              f"{SHIELD_WRAPPER!r} and options (an object of SafetyConfig fields)")
    from satenv.safety import SafetyConfig

    try:
        return SafetyConfig.from_options(**entry.get("options", {}))
    except (ValueError, TypeError) as err:
        raise PolicyLoadError(f"{root / 'env.json'}: safety_filter options: {err}") from None


_QUOTED = re.compile(r"'[^'\n]*'|\"[^\"\n]*\"")
_VOCABULARY = frozenset({"mlp", "identity", "mean", "var", "clip_obs", "epsilon", "inf", "type", "obs_dim",
                         "act_dim", "hidden", "activation", "squash", "format", "actor", "tanh", "relu",
                         "elu", "silu", "set", "own_dim", "slot_dim", "n_slots", "encoder"})
"""Words a load error may quote; any other quoted text in it came from the file and is hidden."""


def _parsed(root: Path, name: str, fn: Any, *args: Any) -> Any:
    """``fn(*args)``; any failure becomes a :class:`PolicyLoadError` naming ``root / name``, its
    message with every quoted text that is not a field or choice name hidden (``'...'``): an
    error never echoes the file's strings."""
    try:
        return fn(*args)
    except (PolicyLoadError, UntrustedDataError):
        raise
    except Exception as err:  # noqa: BLE001 - every failure of reading data is a load error
        msg = _QUOTED.sub(lambda m: m[0] if m[0][1:-1] in _VOCABULARY else "'...'", str(err))
        raise PolicyLoadError(f"{root / name}: {type(err).__name__}: {msg[:200]}") from None


def _actor_from_spec(spec: Any) -> Any:
    """The actor of a ``policy.json`` ``actor`` entry: ``"set"`` (:mod:`satenv.training.set_policy`) or an MLP."""
    if isinstance(spec, dict) and spec.get("type") == "set":
        from satenv.training.set_policy import set_actor_from_spec

        return set_actor_from_spec(spec)
    from satenv.training.actor import actor_from_spec

    return actor_from_spec(spec)


def _load_safe(root: Path, trusted: bool) -> LearnedPolicy:
    import torch

    legacy = not os.path.lexists(root / WEIGHTS) and os.path.lexists(root / LEGACY_WEIGHTS)
    missing = [f for f in POLICY_FILES if not os.path.lexists(root / f) and not (legacy and f == WEIGHTS)]
    if missing:
        raise PolicyLoadError(f"{str(root)!r} is not a complete policy folder: missing {missing}; "
                              "point to the 'final' or 'best' folder written by python -m satenv.training.train")
    if legacy and not trusted:
        raise PolicyLoadError(
            f"{root / LEGACY_WEIGHTS}: the legacy torch format, whose tensor sizes cannot be checked "
            f"before they are allocated; convert the folder once with satenv.training.policy.convert_weights_pt"
            f"(path) (for a folder you trust), or load it with trusted=True")
    blobs = {name: read_member(root, name, MAX_JSON_BYTES) for name in POLICY_FILES if name != WEIGHTS}
    table = _manifest(root)
    if table is None and not trusted:
        raise PolicyLoadError(f"{root / MANIFEST}: missing; every policy folder needs one (it detects "
                              f"changed files). If you made this folder, write one with "
                              f"satenv.training.policy.write_manifest(path), or load with trusted=True")
    if table is None or legacy:
        warnings.warn(f"loading {root} with trusted=True: " + (
            f"{LEGACY_WEIGHTS} read with torch.load(weights_only=True), tensor sizes not checked first; "
            if legacy else "") + ("no manifest.json: changed files are not detected; " if table is None
                                  else "") + "nothing is run and nothing outside the folder is read",
            UserWarning, stacklevel=3)
    if table is not None:
        _check_manifest(root, table, blobs)
    spec = _parsed(root, "policy.json", parse_json, blobs["policy.json"], root / "policy.json")
    if not isinstance(spec, dict) or spec.get("format") != FORMAT:
        raise PolicyLoadError(f"{root / 'policy.json'}: expected a JSON object with format {FORMAT!r}")
    meta = _parsed(root, "env.json", parse_json, blobs["env.json"], root / "env.json")
    config = _parsed(root, "config.json", parse_json, blobs["config.json"], root / "config.json")
    if not isinstance(meta, dict) or not isinstance(config, dict):
        raise PolicyLoadError(f"{str(root)!r}: env.json and config.json must be JSON objects")
    normalizer = _parsed(root, "obs_norm.json", lambda b: ObsNormalizer.from_json(
        parse_json(b, root / "obs_norm.json")), blobs["obs_norm.json"])
    with torch.device("meta"):  # validated and sized without allocating
        actor = _parsed(root, "policy.json", _actor_from_spec, spec.get("actor"))
    shapes = {k: tuple(v.shape) for k, v in actor.state_dict().items()}
    if legacy:
        data = read_member(root, LEGACY_WEIGHTS, max_weights_bytes() + 2**24)
        if table is not None:
            _check_manifest(root, table, {LEGACY_WEIGHTS: data})
        state = _parsed(root, LEGACY_WEIGHTS, lambda: torch.load(io.BytesIO(bytes(data)), map_location="cpu",
                                                                  weights_only=True))
    else:
        cap = 8 + MAX_HEADER_BYTES + 4 * sum(math.prod(s) for s in shapes.values())
        data = read_member(root, WEIGHTS, cap)
        if table is not None:
            _check_manifest(root, table, {WEIGHTS: data})
        state = {k: torch.from_numpy(v) for k, v in safetensors_arrays(data, shapes, root / WEIGHTS).items()}
    actor = actor.to_empty(device="cpu")
    _parsed(root, WEIGHTS if not legacy else LEGACY_WEIGHTS, actor.load_state_dict, state)
    del state
    if not all(torch.isfinite(t).all() for t in actor.state_dict().values()):
        raise PolicyLoadError(f"{root / (LEGACY_WEIGHTS if legacy else WEIGHTS)}: the weights contain NaN/inf")
    if normalizer.mean is not None and normalizer.mean.shape != (actor.spec["obs_dim"],):
        raise PolicyLoadError(f"{str(root)!r}: obs_norm.json has shape {normalizer.mean.shape} but the actor "
                              f"expects ({actor.spec['obs_dim']},); the folder mixes files of different runs")
    features = _parsed(root, "config.json", features_from_config, config)
    obs_shape = meta.get("observation_shape", [actor.spec["obs_dim"]])
    if not (isinstance(obs_shape, list) and len(obs_shape) == 1 and isinstance(obs_shape[0], int)
            and not isinstance(obs_shape[0], bool) and 1 <= obs_shape[0] <= 2**31):
        raise PolicyLoadError(f"{root / 'env.json'}: observation_shape must be [n] with n an int in "
                              f"[1, 2**31], got a {type(obs_shape).__name__}")
    inputs = _parsed(root, "config.json", features.out_dim, obs_shape[0]) if features else obs_shape[0]
    if inputs != actor.spec["obs_dim"]:
        feats = (f" through the features of {root / 'config.json'} (obs_symlog_scale, obs_symlog_dims, "
                 f"obs_drop_dims)" if features else "")
        raise PolicyLoadError(f"{root / 'env.json'}: observation_shape [{obs_shape[0]}] gives {inputs} "
                              f"network inputs{feats}, but the actor of {root / 'policy.json'} has obs_dim "
                              f"{actor.spec['obs_dim']}; the folder mixes files of different runs")
    action_map = _parsed(root, "config.json", action_map_from_config, config)
    terminal = _parsed(root, "config.json", terminal_from_config, config)
    return LearnedPolicy(actor, normalizer, obs_shape=tuple(obs_shape), features=features,
                         action_map=action_map, meta=meta, terminal=terminal)


def _load_sb3_zip(root: Path, trusted: bool) -> LearnedPolicy:
    """An old-format folder (SB3 ``model.zip`` + ``obs_norm.npz``): unpickles, so ``trusted`` only."""
    if not trusted:
        raise PolicyLoadError(
            f"{root / 'model.zip'}: an SB3 model with no {WEIGHTS}: loading it would unpickle the file, "
            "which runs any code it contains. Load it with satenv.training.load(path, trusted=True) only if you "
            "made it or trust its source, or convert it once with satenv.training.policy.convert_sb3(path)")
    warnings.warn(f"unpickling the SB3 model in {root} (trusted=True): only do this for files you trust",
                  UserWarning, stacklevel=3)
    try:
        from stable_baselines3 import PPO, SAC

        meta, config = read_json(root, "env.json"), read_json(root, "config.json")
        with np.load(member(root, "obs_norm.npz", MAX_JSON_BYTES)[0], allow_pickle=False) as d:
            normalizer = ObsNormalizer() if bool(d["identity"]) else ObsNormalizer(
                d["mean"], d["var"], float(d["clip_obs"]), float(d["epsilon"]))
        zip_path = member(root, "model.zip", max_weights_bytes() * 4)[0]
        model = {"ppo": PPO, "sac": SAC}[config["algo"]].load(zip_path, device="cpu")
        return from_sb3(model, normalizer, obs_shape=tuple(meta["observation_shape"]),
                        features=features_from_config(config), action_map=action_map_from_config(config),
                        meta=meta)
    except (PolicyLoadError, UntrustedDataError):
        raise
    except Exception as err:  # noqa: BLE001
        raise PolicyLoadError(f"cannot read the SB3 policy in {str(root)!r}: {type(err).__name__}: "
                              f"{str(err)[:200]}") from None


def save_artifacts(folder: str | Path, policy: LearnedPolicy, *, env_meta: dict[str, Any],
                   config: dict[str, Any], evaluation: dict[str, Any] | None = None,
                   source: str = "") -> Path:
    """Write an artefact folder in the safe format with its manifest (module docstring); returns
    its path. A legacy ``weights.pt`` left in the folder is removed (it is replaced)."""
    from safetensors.torch import save_file

    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    spec = {"format": FORMAT, "actor": policy.actor.spec, "source": source}
    (root / "policy.json").write_text(json.dumps(spec, indent=2) + "\n")
    state = {k: v.detach().cpu().contiguous().clone() for k, v in policy.actor.state_dict().items()}
    save_file(state, str(root / WEIGHTS))
    (root / LEGACY_WEIGHTS).unlink(missing_ok=True)
    (root / "obs_norm.json").write_text(json.dumps(policy.normalizer.to_json()) + "\n")
    (root / "env.json").write_text(json.dumps(env_meta, indent=2) + "\n")
    (root / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    write_manifest(root)
    if evaluation is not None:
        (root / "eval.json").write_text(json.dumps(evaluation, indent=2, default=_jsonable) + "\n")
    return root


def write_manifest(root: str | Path) -> None:
    """(Re)write ``manifest.json`` with the sha256 of :data:`POLICY_FILES` (``weights.pt`` in
    place of ``weights.safetensors`` in a legacy folder), hashed in chunks; links are refused."""
    root = Path(root)
    names = [LEGACY_WEIGHTS if n == WEIGHTS and not os.path.lexists(root / WEIGHTS)
             and os.path.lexists(root / LEGACY_WEIGHTS) else n for n in POLICY_FILES]
    digests = {name: sha256_file(member(root, name, 2**62)[0]) for name in names}
    (root / MANIFEST).write_text(json.dumps({"sha256": digests}, indent=2) + "\n")


def convert_sb3(folder: str | Path) -> Path:
    """Convert an old SB3 folder in place (unpickles ``model.zip`` once: trusted files only).

    Writes the safe files beside ``model.zip``/``obs_norm.npz``, which :func:`load` then ignores
    (delete them). Returns the folder.
    """
    root = Path(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        policy = _load_sb3_zip(root, trusted=True)
    config = read_json(root, "config.json")
    source = f"stable-baselines3 {str(config.get('algo', '')).upper()} (converted from model.zip)"
    return save_artifacts(root, policy, env_meta=policy.meta, config=config, source=source)


def convert_weights_pt(folder: str | Path) -> Path:
    """Convert a legacy folder (``weights.pt``) in place to ``weights.safetensors`` with a new
    manifest; its manifest, if any, is checked first. Reads the torch file with
    ``torch.load(weights_only=True)`` (no code, but sizes unchecked): folders you trust only.
    Every other file is kept byte for byte. Returns the folder."""
    from safetensors.torch import save_file

    root = Path(folder)
    if not os.path.lexists(root / LEGACY_WEIGHTS):
        raise PolicyLoadError(f"{root / LEGACY_WEIGHTS}: missing; nothing to convert")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        policy = load(root, trusted=True)
    state = {k: v.detach().cpu().contiguous().clone() for k, v in policy.actor.state_dict().items()}
    save_file(state, str(root / WEIGHTS))
    (root / LEGACY_WEIGHTS).unlink()
    write_manifest(root)
    return root


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON-serialisable: {type(v).__name__}")
