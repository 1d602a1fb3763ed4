"""Learned policies with the baseline interface, and loading them from a run's artefact folder.

An artefact folder (written by ``python -m training.train``, e.g. ``runs/x/final/`` or
``training/policies/<name>/``) holds:

* ``model.zip``      the SB3 model (PPO or SAC);
* ``obs_norm.npz``   the observation normalisation (``mean``, ``var``, ``clip_obs``, ``epsilon``;
                     identity when normalisation was off);
* ``env.json``       env id, version, satenv version, train and eval env kwargs, spaces;
* ``config.json``    the :class:`training.config.TrainConfig` used;
* ``eval.json``      the evaluation summary (optional for loading).

``load(path)`` returns a :class:`LearnedPolicy` with ``reset(seed=None)`` and
``act(observations) -> actions`` (dicts keyed by agent, actions in ``[-1, 1]^3``), usable
anywhere a scripted baseline is (``satenv.rollout.rollout``, the scoreboard).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["LearnedPolicy", "PolicyLoadError", "load", "save_artifacts", "ObsNormalizer"]

ALGO_CLASSES = ("ppo", "sac")


class PolicyLoadError(ValueError):
    """A learned policy cannot be loaded or does not fit the environment."""


class ObsNormalizer:
    """``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` (SB3 ``VecNormalize``)."""

    def __init__(self, mean: np.ndarray | None = None, var: np.ndarray | None = None,
                 clip_obs: float = np.inf, epsilon: float = 1e-8) -> None:
        self.mean = None if mean is None else np.asarray(mean, dtype=np.float64)
        self.var = None if var is None else np.asarray(var, dtype=np.float64)
        self.clip_obs = float(clip_obs)
        self.epsilon = float(epsilon)

    @classmethod
    def from_vecnormalize(cls, venv: Any) -> ObsNormalizer:
        """A frozen copy of a ``VecNormalize``'s current statistics (identity if it does not normalise)."""
        if venv is None or not getattr(venv, "norm_obs", False):
            return cls()
        return cls(venv.obs_rms.mean.copy(), venv.obs_rms.var.copy(), venv.clip_obs, venv.epsilon)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if self.mean is None:
            return obs.astype(np.float32)
        out = (obs - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(out, -self.clip_obs, self.clip_obs).astype(np.float32)

    def save(self, path: Path) -> None:
        if self.mean is None:
            np.savez(path, identity=np.array(True))
        else:
            np.savez(path, identity=np.array(False), mean=self.mean, var=self.var,
                     clip_obs=np.array(self.clip_obs), epsilon=np.array(self.epsilon))

    @classmethod
    def load(cls, path: Path) -> ObsNormalizer:
        with np.load(path) as d:
            if bool(d["identity"]):
                return cls()
            return cls(d["mean"], d["var"], float(d["clip_obs"]), float(d["epsilon"]))


class LearnedPolicy:
    """A trained SB3 model behind the baseline interface (one shared policy for every agent).

    ``act`` stacks the agents' observations (in the dict's order) into one batch, normalises it
    with the saved statistics and returns the deterministic actions.
    """

    name = "learned"

    def __init__(self, model: Any, normalizer: ObsNormalizer | None = None, *,
                 features: Any = None, action_map: Any = None, meta: dict[str, Any] | None = None,
                 deterministic: bool = True) -> None:
        self.model = model
        self.normalizer = normalizer or ObsNormalizer()
        self.features = features
        self.action_map = action_map
        self.meta = dict(meta or {})
        self.deterministic = deterministic
        # the env's per-agent observation shape (before the optional feature map)
        self.obs_shape = tuple(self.meta.get("observation_shape", model.observation_space.shape))
        self.action_shape = tuple(model.action_space.shape)
        self.info: dict[str, Any] = {"fallbacks": 0}

    def reset(self, seed: int | None = None) -> None:
        self.info = {"fallbacks": 0}

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
        if self.features is not None:
            obs = self.features(obs)
        actions, _ = self.model.predict(self.normalizer(obs), deterministic=self.deterministic)
        actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        if self.action_map is not None:
            actions = self.action_map(actions)
        actions = actions.astype(np.float32)
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
            warnings.warn("env scenario differs from the policy's training/evaluation setting: "
                          + ", ".join(mismatched), stacklevel=3)


def features_from_config(config: dict[str, Any]):
    """The observation feature map of a run config (``None`` when off)."""
    from training.shaping import ObsFeatures

    feats = ObsFeatures(config.get("obs_symlog_scale", 0.0), config.get("obs_symlog_dims", 6))
    return feats if feats.active else None


def action_map_from_config(config: dict[str, Any]):
    """The action map of a run config (``None`` when it is the identity)."""
    from training.shaping import ActionMap

    amap = ActionMap(config.get("action_power", 1.0))
    return amap if amap.active else None


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def load(path: str | Path, env: Any = None, *, device: str = "cpu") -> LearnedPolicy:
    """Load the policy in artefact folder ``path``; if ``env`` is given, check its spaces fit.

    Raises :class:`PolicyLoadError` (a ``ValueError``) for a missing/unreadable folder or a
    space mismatch.
    """
    root = Path(path)
    if not root.is_dir():
        raise PolicyLoadError(f"learned policy path {str(path)!r} is not a directory; expected an artefact "
                              "folder with model.zip, obs_norm.npz, env.json, config.json (e.g. "
                              "runs/<run>/final or training/policies/<name>)")
    missing = [f for f in ("model.zip", "obs_norm.npz", "env.json", "config.json") if not (root / f).is_file()]
    if missing:
        raise PolicyLoadError(f"{str(root)!r} is not a complete policy folder: missing {missing}; "
                              "point to the 'final' or 'best' folder written by python -m training.train")
    try:
        meta = json.loads((root / "env.json").read_text())
        config = json.loads((root / "config.json").read_text())
        algo = config["algo"]
        if algo not in ALGO_CLASSES:
            raise KeyError(algo)
        normalizer = ObsNormalizer.load(root / "obs_norm.npz")
        features = features_from_config(config)
        action_map = action_map_from_config(config)
        model = _algo_class(algo).load(root / "model.zip", device=device)
    except (OSError, ValueError, KeyError, EOFError) as err:
        raise PolicyLoadError(f"cannot read the learned policy in {str(root)!r}: {type(err).__name__}: {err}") from None
    policy = LearnedPolicy(model, normalizer, features=features, action_map=action_map, meta=meta)
    if normalizer.mean is not None and normalizer.mean.shape != tuple(model.observation_space.shape):
        raise PolicyLoadError(f"{str(root)!r}: obs_norm.npz has shape {normalizer.mean.shape} but the model "
                              f"expects {policy.obs_shape}; the folder mixes files of different runs")
    if env is not None:
        policy.check_env(env)
    return policy


def save_artifacts(folder: str | Path, model: Any, normalizer: ObsNormalizer, *, env_meta: dict[str, Any],
                   config: dict[str, Any], evaluation: dict[str, Any] | None = None,
                   vecnormalize: Any = None) -> Path:
    """Write an artefact folder (module docstring); returns its path."""
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    model.save(root / "model.zip")
    normalizer.save(root / "obs_norm.npz")
    if vecnormalize is not None:
        vecnormalize.save(str(root / "vecnormalize.pkl"))
    (root / "env.json").write_text(json.dumps(env_meta, indent=2) + "\n")
    (root / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    if evaluation is not None:
        (root / "eval.json").write_text(json.dumps(evaluation, indent=2, default=_jsonable) + "\n")
    return root


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON-serialisable: {type(v).__name__}")
