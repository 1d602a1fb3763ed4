"""The batched, framework-neutral (numpy) multi-agent vector env over a satenv core.

:func:`make_vec` runs ``num_envs`` copies ``B`` of one scenario in ONE batched core
(``env.core_class(env.scenario, batch=B)``): one ``step`` is one numpy call for every agent of
every copy. Arrays are ``(B, M, ...)`` with ``M`` agents (order of ``env.possible_agents``)::

    vec = satenv.make_vec("platoon_v0", 64, seed=0)
    obs, infos = vec.reset()                                   # obs (B, M, obs_dim) float32
    obs, rew, term, trunc, infos = vec.step(actions)           # actions (B, M, act_dim) in [-1, 1]
    vec.state()                                                # (B, state_dim) for central critics

Semantics (the same as the PettingZoo env, :class:`satenv.envs.base.SatParallelEnv`):

* actions in ``[-1, 1]`` are scaled with :func:`satenv.dynamics.unit_box_to_accel`
  (``scenario.u_max``, ``scenario.thrust_mode``); values outside are clipped; NaN/inf, complex,
  bool, text and masked arrays are rejected (``SatenvError``/``SatenvTypeError``);
* **finiteness guard**: after every ``reset`` and ``step`` one vectorised check of the
  observations, states and rewards; a non-finite value raises ``SatenvError`` naming the copy,
  the agent, the step and the quantity, and ends that copy's episode (``reset()`` or
  ``reset(indices=[b])`` starts a new one);
* ``rewards`` (float64, the PettingZoo env's values: the paper's cost, or with
  ``reward="training"`` the training reward of :mod:`satenv.rewards`, computed for the whole
  batch at once), ``terminations``, ``truncations`` (bool) are ``(B, M)``; ``infos["safety_cost"]``
  ``(B, M)`` is 1.0 where an agent collides or violates a hard bound in the step; termination is team-wide (a
  collision or leaving the allowed region ends the copy for every agent), truncation is the step
  limit ``scenario.max_steps`` (never both);
* **auto-reset, same step**: a copy that ends is reset inside the same ``step``. The returned
  ``obs`` row is then the first observation of its next episode. Gymnasium 1.x's names:
  ``infos["_final_obs"]`` ``(B,)`` marks those copies, ``infos["final_obs"]`` ``(B, M, obs_dim)``
  holds the last observation of the finished episode, ``infos["final_info"]`` the info arrays
  of that last step and ``infos["_final_info"]`` the same mask (full-batch arrays, meaningful
  where the mask is true; the keys are present only in a step where some copy ended). The
  former names ``final_observation`` and ``_final`` (:data:`FINAL_ALIASES`) are kept, same
  arrays, for one release. The other ``infos`` entries are the per-agent physical
  quantities (``satenv.envs.base.INFO_KEYS`` and the env's own) as ``(B, M, ...)`` arrays, of
  the new episode's reset for the reset copies;
* ``SatVectorEnv(env, B, autoreset=False)`` (what the TorchRL env uses) leaves finished copies
  alone: the caller resets them with ``reset(indices=...)`` before the next ``step``;
* **safety filter**: a filtered template (``satenv.make(..., safety_filter=True)``) gives a
  filtered batch (its :class:`satenv.safety.SafetyConfig`), as does ``safety_filter=True`` or a
  config here: every ``step`` filters the actions first (:mod:`satenv.safety`), the infos get the
  record arrays ``safety_*`` ``(B, M)`` (in ``final_info`` too) and the rewards ``- penalty * |du|``.
  ``safety_filter=False`` with a filtered template is an error (never a silently unfiltered batch);
* **seeding**: ``reset(seed=s)`` (or ``make_vec(..., seed=s)``, applied at the first reset) gives
  copy ``b`` its own generator ``np.random.default_rng(s + b)``, used for its initial states and
  for any randomness inside its steps, exactly as the PettingZoo env's ``reset(seed=s + b)``:
  copy ``b`` reproduces that env's episodes bit for bit under the same actions, including the
  episodes after an auto-reset (the PettingZoo env's ``reset()`` without a seed).
  ``reset()`` without a seed keeps the generators (fresh entropy if never seeded).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from gymnasium import spaces

from satenv.dynamics import unit_box_to_accel
from satenv.dynamics._checks import MAX_COPIES, all_finite, first_nonfinite, integer, numeric
from satenv.envs.base import SatParallelEnv
from satenv.errors import SatenvError, SatenvTypeError
from satenv.rewards import RewardState, TrainingReward, with_safety_cost

__all__ = ["FINAL_ALIASES", "FilteredVectorEnv", "SatVectorEnv", "filtered_vec", "make_vec"]

FINAL_ALIASES = {"final_observation": "final_obs", "_final": "_final_obs"}
"""The auto-reset ``infos`` keys of earlier releases -> Gymnasium 1.x's names (both present, the
same arrays, for one release; read the new ones)."""


def make_vec(env_id: str, num_envs: int, *, seed: int | None = None, **env_kwargs: Any) -> SatVectorEnv:
    """``num_envs`` batched copies of ``satenv.make(env_id, **env_kwargs)`` (module docstring)."""
    import satenv

    return SatVectorEnv(satenv.make(env_id, **env_kwargs), num_envs, seed=seed)


class CopyGenerators:
    """One ``np.random.Generator`` per copy behind the ``Generator`` methods a core calls.

    A draw of ``size=(B, ...)`` stacks ``B`` draws of ``size=(...)``, copy ``b`` from its own
    generator, so copy ``b`` sees the same stream as the PettingZoo env with ``B = 1``.
    """

    def __init__(self, generators: list[np.random.Generator]) -> None:
        self.generators = generators

    def subset(self, idx: np.ndarray) -> CopyGenerators:
        return CopyGenerators([self.generators[b] for b in idx])

    def _stack(self, method: str, size: Any, **kwargs: Any) -> np.ndarray:
        size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
        if not size or size[0] != len(self.generators):
            raise SatenvError(f"a batched draw must have size (B={len(self.generators)}, ...), got {size}")
        return np.stack([getattr(g, method)(size=size[1:], **kwargs) for g in self.generators])

    def normal(self, loc: Any = 0.0, scale: Any = 1.0, size: Any = None) -> np.ndarray:
        return self._stack("normal", size, loc=loc, scale=scale)

    def random(self, size: Any = None) -> np.ndarray:
        return self._stack("random", size)

    def uniform(self, low: Any = 0.0, high: Any = 1.0, size: Any = None) -> np.ndarray:
        return self._stack("uniform", size, low=low, high=high)


class SatVectorEnv:
    """``num_envs`` copies of a satenv env's scenario stepped as one batch (module docstring).

    Args:
        env: the :class:`SatParallelEnv` whose ``core_class`` and ``scenario`` are batched (it is
            not stepped).
        num_envs: number of copies ``B`` (``1 <= B <= MAX_COPIES``).
        seed: applied at the first :meth:`reset` that has no seed of its own.
        autoreset: reset finished copies inside :meth:`step` (default). With ``False`` the caller
            resets them with ``reset(indices=...)`` (TorchRL's convention); stepping a finished
            copy before that raises.
        safety_filter: ``None`` (default): filtered iff ``env`` is; ``True`` or a
            ``satenv.safety.SafetyConfig``: filtered; ``False``: unfiltered (an error for a
            filtered ``env``). The filter is :attr:`safety` (``None`` when unfiltered).
    """

    def __init__(self, env: SatParallelEnv, num_envs: int, *, seed: int | None = None,
                 autoreset: bool = True, safety_filter: Any = None) -> None:
        if not isinstance(getattr(env, "unwrapped", env), SatParallelEnv):   # a wrapper (satenv.safety) too
            raise SatenvTypeError(f"SatVectorEnv needs a satenv env (satenv.make(...)), got {type(env).__name__}")
        num_envs = integer(num_envs, "num_envs", minimum=1, maximum=MAX_COPIES,
                           why="MAX_COPIES: the batch is allocated at once")
        self.env = env
        self.scenario = env.scenario
        self.num_envs = int(num_envs)
        self.core = env.core_class(self.scenario, batch=self.num_envs)
        self.agents = list(env.possible_agents)
        self.n_agents = len(self.agents)
        self.metadata = dict(env.metadata)
        self.single_observation_space: spaces.Box = env.observation_space(self.agents[0])
        self.single_action_space: spaces.Box = env.action_space(self.agents[0])
        self.action_shape = (self.num_envs, self.n_agents, *self.single_action_space.shape)
        self.max_steps = int(self.scenario.max_steps)
        self._pending_seed = check_seed(seed)
        self._rngs: CopyGenerators | None = None
        self.autoreset = bool(autoreset)
        self._ended = np.zeros(self.num_envs, dtype=bool)
        self.safety = _bind_filter(self, env, safety_filter)
        self.reward_state = (RewardState(TrainingReward.of(self.scenario), self.num_envs, self.n_agents)
                             if env.reward == "training" else None)

    def __repr__(self) -> str:
        return f"SatVectorEnv({self.metadata.get('name')}, num_envs={self.num_envs}, n_agents={self.n_agents})"

    # ----------------------------------------------------------------- episode
    def seed(self, seed: int | None) -> None:
        """Seed the next full :meth:`reset` without a seed of its own (copy ``b``: ``seed + b``)."""
        self._pending_seed = check_seed(seed)

    def reset(self, seed: int | None = None, *, indices: Any = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy, or only ``indices`` (ints or a ``(B,)`` bool mask; they keep their
        generators); returns ``obs (B, M, obs_dim)`` of every copy and the info arrays of the
        reset copies."""
        if indices is not None:
            if seed is not None:
                raise SatenvError("reset(seed=..., indices=...): a seed applies to all copies; "
                                  "reset all copies to reseed")
            return self._reset_some(indices)
        seed = check_seed(seed)
        if seed is None:
            seed, self._pending_seed = self._pending_seed, None
        if seed is not None:
            self._rngs = CopyGenerators([np.random.default_rng(seed + b) for b in range(self.num_envs)])
        elif self._rngs is None:
            self._rngs = CopyGenerators([np.random.default_rng(s) for s in
                                         np.random.SeedSequence().spawn(self.num_envs)])
        idx = np.arange(self.num_envs)
        info = self._reset_info(self.core.reset(self._sample(idx), None, self._rngs), None)
        self._ended[:] = False
        obs = self.core.observe()
        self._guard(idx, obs[idx], info["state"])
        return obs, dict(info)

    def _reset_some(self, indices: Any) -> tuple[np.ndarray, dict[str, Any]]:
        try:
            idx = np.asarray(indices)
        except (TypeError, ValueError):
            idx = np.asarray(None)
        if idx.size and idx.dtype.kind not in "biu":  # e.g. [0.5] must not become copy 0
            raise SatenvTypeError(f"reset(indices=...) must be int copy indices or a bool mask of shape "
                                  f"({self.num_envs},), got {type(indices).__name__} of dtype {idx.dtype}")
        if idx.ndim > 1:
            raise SatenvError(f"reset(indices=...) must be a flat list of copy indices or a ({self.num_envs},) "
                              f"bool mask, got an array of shape {idx.shape}")
        if self._rngs is None:
            return self.reset()
        if idx.dtype == bool:
            if idx.shape != (self.num_envs,):
                raise SatenvError(f"reset(indices=mask): the mask must have shape ({self.num_envs},), got {idx.shape}")
            idx = np.flatnonzero(idx)
        idx = idx.astype(np.int64, copy=False).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= self.num_envs):
            raise SatenvError(f"reset(indices=...) must be copy indices in [0, {self.num_envs}), "
                              f"got {str(idx.tolist())[:80]}")
        info = (self._reset_info(self.core.reset(self._sample(idx), idx, self._rngs.subset(idx)), idx)
                if idx.size else {})
        self._ended[idx] = False
        obs = self.core.observe()
        if idx.size:
            self._guard(idx, obs[idx], info["state"])
        return obs, dict(info)

    def _reset_info(self, info: dict[str, np.ndarray], idx: np.ndarray | None) -> dict[str, np.ndarray]:
        """The reset copies' infos with ``safety_cost``; their training-reward memory restarted."""
        info = with_safety_cost(info)
        if self.reward_state is not None:
            self.reward_state.reset(info, idx)
        return info

    def _sample(self, idx: np.ndarray) -> np.ndarray:
        gens = self._rngs.generators
        return np.concatenate([self.core.sample_initial_state(gens[b], 1) for b in idx])

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Apply ``actions (B, M, act_dim)`` in ``[-1, 1]``; returns obs, rewards, terminations,
        truncations ``(B, M)`` and infos (auto-reset: module docstring)."""
        if self._rngs is None:
            raise SatenvError("step() called before reset(): call reset() first")
        if self._ended.any():
            raise SatenvError(f"copies {np.flatnonzero(self._ended).tolist()} have ended: call "
                              "reset(indices=...) (or reset()) first")
        a = self._check_actions(actions)
        record = None
        if self.safety is not None:
            a, record = self.safety.filter(a)
        accel = unit_box_to_accel(a, self.scenario.u_max, self.scenario.thrust_mode)
        res, obs = self.core.step_observe(accel, self._rngs)
        terminated = np.asarray(res.terminated, dtype=bool)
        truncated = (self.core.t >= self.max_steps) & ~terminated
        step_info = with_safety_cost(res.info)
        rewards = (np.asarray(res.rewards, dtype=np.float64) if self.reward_state is None
                   else self.reward_state.step(step_info, terminated, self.core.t >= self.max_steps))
        if record is not None:
            step_info = {**step_info, **record.infos()}
            if self.safety.config.penalty:
                rewards = rewards - self.safety.config.penalty * record.delta
        done = terminated | truncated
        if not (res.finite.all() if res.finite is not None and record is None
                else all_finite(obs, res.info["state"], rewards)):
            self._ended |= done   # copies that also ended normally wait for a reset too
            self._nonfinite(np.arange(self.num_envs), obs, res.info["state"], rewards)
        infos: dict[str, Any] = dict(step_info)
        if not self.autoreset:
            self._ended |= done
        elif done.any():
            idx = np.flatnonzero(done)
            reset_info = self._reset_info(self.core.reset(self._sample(idx), idx, self._rngs.subset(idx)), idx)
            infos = {k: v.copy() for k, v in step_info.items()}
            for k, v in reset_info.items():
                infos[k][idx] = v
            infos.update(final_obs=obs, _final_obs=done, final_info=step_info, _final_info=done.copy())
            infos.update({old: infos[new] for old, new in FINAL_ALIASES.items()})
            if 2 * idx.size <= self.num_envs:   # observe only the copies that reset
                obs = obs.copy()
                obs[idx] = self.core.observe_copies(idx)
            else:
                obs = self.core.observe()
            self._guard(idx, obs[idx], reset_info["state"])
        m = self.n_agents
        return (obs, rewards, np.repeat(terminated[:, None], m, axis=1),
                np.repeat(truncated[:, None], m, axis=1), infos)

    def _check_actions(self, actions: Any) -> np.ndarray:
        if (type(actions) is np.ndarray and actions.dtype.kind == "f"
                and actions.shape == self.action_shape and all_finite(actions)):
            return actions.astype(np.float64, copy=False)   # the fast path of a training loop
        a = numeric(actions, f"actions (normalised inputs in [-1, 1], shape {self.action_shape})")
        if a.shape != self.action_shape:
            raise SatenvError(f"actions must have shape {self.action_shape} (copies, agents, action_dim), "
                              f"got {a.shape}")
        return a

    def _guard(self, idx: np.ndarray, obs: np.ndarray, state: np.ndarray) -> None:
        """The finiteness check after a reset of copies ``idx`` (their rows of obs and state)."""
        if not all_finite(obs, state):
            self._nonfinite(idx, obs, state, None)

    def _nonfinite(self, idx: np.ndarray, obs: np.ndarray, state: np.ndarray, rewards: np.ndarray | None) -> None:
        """Raise :class:`SatenvError` naming the copies, agents, steps and quantities that are not
        finite (rows of ``idx``); those copies' episodes end."""
        parts = []
        for row, b in enumerate(idx):
            quantities = {"observation": obs[row], "state": state[row]}
            if rewards is not None:
                quantities["reward"] = rewards[row]
            if not all_finite(*quantities.values()):
                t = int(self.core.t[b])
                parts.append(f"copy {int(b)}: {first_nonfinite(quantities, self.agents)} "
                             + (f"at step {t}" if t else "at reset (step 0)"))
                self._ended[b] = True
        if not parts:
            return
        more = f" (and {len(parts) - 3} more copies)" if len(parts) > 3 else ""
        raise SatenvError(f"{self.metadata.get('name')}: non-finite " + "; ".join(parts[:3]) + more
                          + "; those episodes are over: call reset() or reset(indices=[...])")

    def state(self) -> np.ndarray:
        """The global state of every copy ``(B, ...)`` (the PettingZoo env's ``state()``), float64."""
        return np.asarray(self.core.global_state(), dtype=np.float64)

    # ----------------------------------------------------------------- state (resume)
    def get_state(self) -> dict[str, np.ndarray]:
        """The episodes in flight as arrays (no pickle): the batched core's arrays (``core.<name>``),
        every generator's state (``generators``, JSON text), the finished copies (``ended``) and the
        training reward's memory of each copy (``reward.<name>``). :meth:`set_state` puts them back:
        a checkpoint resumes mid-episode, bit for bit (both trainers save it)."""
        if self._rngs is None:
            raise SatenvError("get_state(): reset() first (there is no episode yet)")
        state = {f"core.{k}": v.copy() for k, v in vars(self.core).items() if isinstance(v, np.ndarray)}
        gens = {k: v.bit_generator.state for k, v in vars(self.core).items() if isinstance(v, np.random.Generator)}
        state["generators"] = np.array(json.dumps({"copies": [g.bit_generator.state for g in self._rngs.generators],
                                                   "core": gens}))
        state["ended"] = self._ended.copy()
        if self.reward_state is not None:
            state.update({f"reward.{k}": v.copy() for k, v in vars(self.reward_state).items()
                          if isinstance(v, np.ndarray)})
        return state

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`get_state` (names, shapes and dtypes checked: a ``SatenvError`` naming the
        entry, before anything changes)."""
        arrays = [(self.core, k, v) for k, v in state.items() if k.startswith("core.")]
        if self.reward_state is not None:
            arrays += [(self.reward_state, f"reward.{k}", _entry(state, f"reward.{k}"))
                       for k, v in vars(self.reward_state).items() if isinstance(v, np.ndarray)]
        for owner, key, value in arrays:
            old = getattr(owner, key.partition(".")[2], None)
            value = np.asarray(value)
            if not isinstance(old, np.ndarray) or old.shape != value.shape or old.dtype != value.dtype:
                raise SatenvError(f"env state: {key} does not match this env's {type(owner).__name__} "
                                  f"({getattr(old, 'shape', None)} {getattr(old, 'dtype', None)}, got {value.shape} "
                                  f"{value.dtype})")
        try:
            gens = json.loads(str(_entry(state, "generators")))
            rngs = []
            for g in gens["copies"]:
                rngs.append(np.random.default_rng())
                rngs[-1].bit_generator.state = g
            core_gens = [(getattr(self.core, name), g) for name, g in gens["core"].items()]
            for gen, g in core_gens:                       # checked on a copy: nothing changes yet
                type(gen.bit_generator)().state = g
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise SatenvError(f"env state: the generators' entry is malformed ({type(err).__name__}: {err})") from None
        ended = np.asarray(_entry(state, "ended"), dtype=bool)
        if len(rngs) != self.num_envs or ended.shape != (self.num_envs,):
            raise SatenvError(f"env state: {len(rngs)} copies, this env has {self.num_envs}")
        for owner, key, value in arrays:
            setattr(owner, key.partition(".")[2], np.array(value, copy=True))
        for gen, g in core_gens:
            gen.bit_generator.state = g
        self._rngs = CopyGenerators(rngs)
        self._ended = ended.copy()

    def close(self) -> None:
        self.env.close()


def _bind_filter(vec: SatVectorEnv, env: SatParallelEnv, requested: Any) -> Any:
    """The ``satenv.safety.SafetyFilter`` of a batch (``SatVectorEnv``'s ``safety_filter``), or ``None``."""
    template = getattr(env, "safety", None)     # a filtered env (satenv.safety.filtered_env) carries it
    if template is None and requested in (None, False):
        return None
    from satenv.safety import SafetyFilter, safety_config

    if template is not None and not isinstance(template, SafetyFilter):
        template = None
    if requested is False:
        if template is not None:
            raise SatenvError("safety_filter=False with a filtered env (satenv.make(..., safety_filter=...)): "
                              "the batch would fly unfiltered; build the env without the filter instead")
        return None
    if requested is None or (requested is True and template is not None):
        if template is None:
            return None
        config = template.config
    else:
        config = safety_config(requested)
    return SafetyFilter(vec, config)


def check_seed(seed: Any) -> int | None:
    """``None`` or a non-negative int seed (``SatenvError`` otherwise)."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SatenvError(f"seed must be a non-negative int or None, got {seed!r}")
    return int(seed)


def filtered_vec(env: Any, num_envs: int, *, seed: int | None = None, autoreset: bool = True,
                 config: Any = None, **options: Any) -> Any:
    """A :class:`SatVectorEnv` over ``env``'s scenario whose ``step`` filters the
    actions first (infos get the record arrays ``safety_*`` ``(B, M)``; rewards
    ``- penalty * |du|``). ``config`` and ``options`` as for :class:`SafetyFilter` (default: the
    config of a filtered ``env``, else ``SafetyConfig()``)."""
    from satenv.safety import SafetyConfig, SafetyFilter

    if config is None and not options and isinstance(getattr(env, "safety", None), SafetyFilter):
        config = env.safety.config
    return FilteredVectorEnv(env, num_envs, seed=seed, autoreset=autoreset,
                             safety_filter=SafetyConfig.from_options(config, **options))


class FilteredVectorEnv(SatVectorEnv):
    """A :class:`SatVectorEnv` that is always filtered (:func:`filtered_vec`); the filtering itself
    is :class:`SatVectorEnv`'s (any batch of a filtered env has it)."""

    safety: Any    # satenv.safety.SafetyFilter

    def __init__(self, env: Any, num_envs: int, *, seed: int | None = None, autoreset: bool = True,
                 safety_filter: Any = True) -> None:
        if safety_filter is False or safety_filter is None:
            from satenv.safety import SafetyTypeError

            raise SafetyTypeError("FilteredVectorEnv: safety_filter must be True or a SafetyConfig, "
                                  f"got {safety_filter!r}")
        super().__init__(env, num_envs, seed=seed, autoreset=autoreset, safety_filter=safety_filter)


def _entry(state: dict[str, np.ndarray], key: str) -> np.ndarray:
    """``state[key]``; a missing entry is a ``SatenvError`` naming it."""
    if key not in state:
        raise SatenvError(f"env state: no {key!r} entry (a state of get_state() holds it)")
    return state[key]
