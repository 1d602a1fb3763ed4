"""Shared machinery of satenv's environments: a batched core and its PettingZoo wrapper.

Every satenv environment has two layers:

* a :class:`BatchedCore` subclass holding the physics and task logic for ``B`` independent
  copies of the scenario at once (arrays ``(B, M, ...)``, pure numpy, no dicts). The training
  path (``satenv.training.vec_env``) drives this core directly with ``B`` = number of env copies.
* :class:`SatParallelEnv`, the PettingZoo ``ParallelEnv`` wrapper (``B = 1``), which only
  converts dicts to arrays and back, validates input, seeds, truncates and renders.

A core subclass implements :meth:`BatchedCore.sample_initial_state`, :meth:`BatchedCore.reset`,
:meth:`BatchedCore.step`, :meth:`BatchedCore.observe` (and optionally
:meth:`BatchedCore.global_state`, :meth:`BatchedCore.render_scene` and a fused
:meth:`BatchedCore.step_observe`, which the PettingZoo step calls). An env subclass sets
``core_class``, ``agent_prefix``, ``metadata["name"]`` and builds its scenario in ``__init__``.

Conventions: float32 ``Box`` spaces cached per env (``observation_spaces`` / ``action_spaces``
dicts, ``state_space`` a float64 ``Box`` containing ``state()``); actions in
``[-1, 1]^3`` scaled to the scenario's ``u_max`` (per axis, or clipped to the ``u_max`` ball when
``scenario.thrust_mode == "norm"``); one ``np.random.Generator`` per env seeded in
``reset(seed=...)``; team termination (a collision or leaving the allowed region ends the
episode for every agent); truncation at ``scenario.max_steps``; per-agent ``infos`` carry raw
physical quantities (``INFO_KEYS``) at reset and after every step; ``metadata["render_fps"]``
is ``render_speedup / dt`` (playback at ``render_speedup`` x real time), set per instance.

Every scenario has the same surface: ``max_steps``, ``dt`` [s], ``u_max`` (the action scale; unit
in each env's docstring), ``randomize``, ``terminate_on_collision``, and the success rule of
:func:`satenv.metrics.success`: ``success_tol`` [m] and ``collision_voids_success``.
"""

from __future__ import annotations

import dataclasses
import functools
import operator
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from satenv.dynamics import unit_box_to_accel
from satenv.dynamics._checks import StepGuard, all_finite, first_nonfinite, numeric
from satenv.errors import SatenvError, SatenvTypeError
from satenv.rewards import RewardState, TrainingReward, check_reward, with_safety_cost
from satenv.scenarios._fields import states_in_region

__all__ = ["INFO_KEYS", "BatchedCore", "SatParallelEnv", "SatenvError", "SatenvTypeError", "StepResult",
           "reject_unknown_kwargs", "resolve_preset"]

INFO_KEYS: tuple[str, ...] = (
    "state", "accel", "delta_v", "tracking_error", "min_separation", "collision", "violations", "cost",
)
"""Per-agent info entries every environment provides (SI units):

``state`` true state; ``accel`` applied acceleration over the last step [m/s^2] (zeros at reset);
``delta_v`` spent in the last step [m/s]; ``tracking_error`` the quantity the paper's RMSE
measures (vector); ``min_separation`` distance to the nearest other body [m]; ``collision``
(bool); ``violations`` constraint violations this step (int); ``cost`` safety cost (float)."""


_PLAIN_ACTION_TYPES = frozenset({np.ndarray, list, tuple})
"""Action values the env's fast path converts as a whole (anything else, e.g. a masked array, is
checked one agent at a time)."""


@dataclass
class StepResult:
    """What :meth:`BatchedCore.step` returns for ``B`` copies and ``M`` agents."""

    rewards: np.ndarray          # (B, M) float
    terminated: np.ndarray       # (B,) bool: collision / left the allowed region
    info: dict[str, np.ndarray]  # key -> (B, M, ...) raw physical quantities (INFO_KEYS at least)
    finite: np.ndarray | None = None  # (B,) bool: states, rewards (and observations of
    # step_observe) all finite, when the core checked them in its own pass; None: not checked


class BatchedCore(ABC):
    """Task logic and physics for ``batch`` copies of one scenario (arrays ``(B, M, ...)``).

    Subclasses set ``obs_dim``, ``state_dim`` (per-agent true-state size, 6 for translation) and
    ``action_dim`` (3 accelerations by default; e.g. 6 for force + torque) and keep ``self.t``
    (``(B,)`` step counters) up to date. ``step`` receives the physical inputs: the normalised
    actions times ``scenario.u_max`` (a scalar or an ``(action_dim,)`` array).
    """

    obs_dim: int
    state_dim: int = 6
    action_dim: int = 3

    def __init__(self, scenario: Any, batch: int = 1) -> None:
        self.scenario = scenario
        self.batch = int(batch)
        self.n_agents = int(scenario.n_agents)
        self.t = np.zeros(self.batch, dtype=np.int64)

    @abstractmethod
    def sample_initial_state(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Initial true states ``(n, M, state_dim)`` (the preset's, or random draws)."""

    @abstractmethod
    def reset(self, x0: np.ndarray, idx: np.ndarray | None = None,
              rng: np.random.Generator | None = None) -> dict[str, np.ndarray]:
        """Reset copies ``idx`` (all when ``None``) to ``x0`` ``(len(idx), M, state_dim)``.

        Returns the info arrays ``(len(idx), M, ...)`` of the reset copies (``INFO_KEYS``), new
        arrays as in :meth:`step`.
        """

    @abstractmethod
    def step(self, accel: np.ndarray, rng: np.random.Generator | None = None) -> StepResult:
        """Advance every copy one decision period under inputs ``(B, M, action_dim)`` (SI).

        The returned arrays are new: the core never writes into them later (the env hands out
        views of them in ``infos``)."""

    @abstractmethod
    def observe(self) -> np.ndarray:
        """Normalised observations ``(B, M, obs_dim)`` float32."""

    def observe_copies(self, idx: np.ndarray) -> np.ndarray:
        """Observations of copies ``idx`` only ``(len(idx), M, obs_dim)`` (what ``make_vec`` needs
        after an auto-reset); the default observes every copy and takes the rows."""
        return self.observe()[idx]

    def step_observe(self, accel: np.ndarray, rng: np.random.Generator | None = None) -> tuple[StepResult, np.ndarray]:
        """:meth:`step` then :meth:`observe` (a core may do both in one pass)."""
        res = self.step(accel, rng)
        return res, self.observe()

    def global_state(self) -> np.ndarray:
        """The global state ``(B, ...)`` returned by ``env.state()`` (default: all true states)."""
        raise NotImplementedError

    def render_scene(self, b: int = 0) -> dict[str, Any]:
        """What to draw for copy ``b``: ``positions`` (M, 3), optional ``spheres`` list of
        ``(center (3,), radius, label)``, ``targets`` (M, 3), ``title``."""
        raise NotImplementedError


class SatParallelEnv(ParallelEnv):
    """PettingZoo ``ParallelEnv`` over a :class:`BatchedCore` with ``B = 1``.

    Subclasses set ``core_class``, ``agent_prefix``, ``metadata["name"]`` (and optionally
    ``render_speedup``) and call ``super().__init__(scenario, render_mode=...)`` with the resolved
    frozen scenario (which must provide ``n_agents``, ``dt``, ``max_steps``, ``u_max``,
    ``thrust_mode`` and ``max_distance``, the radius of the allowed region that bounds
    ``initial_state`` positions).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10,
                                          "is_parallelizable": True}
    core_class: ClassVar[type[BatchedCore]]
    agent_prefix: ClassVar[str] = "sat"
    render_speedup: ClassVar[float] = 1.0
    """Playback speed of rendered episodes relative to real time (``render_fps = speedup / dt``)."""
    reset_option_keys: ClassVar[frozenset[str]] = frozenset({"initial_state"})
    api_probe_option_keys: ClassVar[frozenset[str]] = frozenset({"options"})
    """Reset options passed only to check that ``reset`` takes ``options`` (PettingZoo's
    ``parallel_api_test`` passes ``{"options": 1}``): ignored without a warning."""

    def __init__(self, scenario: Any, *, render_mode: str | None = None, reward: str = "paper") -> None:
        self.reward = check_reward(reward)
        if render_mode is not None and (not isinstance(render_mode, str)
                                        or render_mode not in self.metadata["render_modes"]):
            raise SatenvError(f"render_mode must be one of {self.metadata['render_modes']} or None, "
                              f"got {render_mode!r}")
        self.scenario = scenario
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": self.render_speedup / scenario.dt,
                         "reward": self.reward}
        self.core = self._build_core(scenario)
        m = self.core.n_agents
        self.possible_agents = [f"{self.agent_prefix}_{i + 1}" for i in range(m)]
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        # the rows of a (M, ...) array as a tuple of views, and the actions of a dict in agent
        # order, in one call each (2-3x faster than iterating in Python)
        self._rows = operator.itemgetter(*range(m)) if m > 1 else (lambda arr: (arr[0],))
        self._pick = (operator.itemgetter(*self.possible_agents) if m > 1
                      else (lambda d, a=self.possible_agents[0]: (d[a],)))
        self.agents: list[str] = []
        self._finite_step = StepGuard(m * self.core.obs_dim, m * self.core.state_dim)
        self._obs_space = spaces.Box(-np.inf, np.inf, (self.core.obs_dim,), np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (self.core.action_dim,), np.float32)
        self.observation_spaces = dict.fromkeys(self.possible_agents, self._obs_space)
        self.action_spaces = dict.fromkeys(self.possible_agents, self._act_space)
        self._rng: np.random.Generator | None = None
        self.reward_state = (RewardState(TrainingReward.of(scenario), 1, m)
                             if self.reward == "training" else None)
        self._last_info: dict[str, np.ndarray] | None = None
        self._trails: list[np.ndarray] = []
        self._fig = None

    def _build_core(self, scenario: Any) -> BatchedCore:
        """The core, after a probe episode step (from the first initial state, at full thrust)
        whose observations, rewards and states must be finite: a scenario whose derived
        quantities overflow (e.g. ``u_max=1e300``) is rejected here, not at the first step."""
        name = self.metadata["name"]
        try:
            with np.errstate(all="ignore"):
                core = self.core_class(scenario, batch=1)
                rng = np.random.default_rng(0)
                info = core.reset(core.sample_initial_state(rng, 1), None, rng)
                quantities = {"observation": core.observe()[0], "state": info["state"][0]}
                if all_finite(*quantities.values()):
                    full = np.ones((1, core.n_agents, core.action_dim))
                    res = core.step(unit_box_to_accel(full, scenario.u_max, scenario.thrust_mode), rng)
                    quantities = {"observation": core.observe()[0], "reward": res.rewards[0],
                                  "state": res.info["state"][0]}
        except SatenvError as exc:
            raise type(exc)(f"{name}: {exc}") from None
        except (ArithmeticError, ValueError) as exc:
            raise SatenvError(f"{name}: the scenario's derived quantities are out of range "
                              f"({type(exc).__name__}: {exc}); use physically sized values (SI)") from None
        if not all_finite(*quantities.values()):
            agents = [f"{self.agent_prefix}_{i + 1}" for i in range(core.n_agents)]
            raise SatenvError(f"{name}: the scenario gives a non-finite "
                              f"{first_nonfinite(quantities, agents)} in its first step at full thrust; "
                              "its parameters (u_max, dt, scales, initial state) are out of range")
        return core

    def _nonfinite(self, obs: np.ndarray, rewards: np.ndarray | None, state: np.ndarray) -> None:
        """Raise :class:`SatenvError` naming the agents, the step and the quantities that are not
        finite after a step (or reset); the episode ends (``reset`` starts a new one)."""
        quantities = {"observation": obs[0], "state": state[0]}
        if rewards is not None:
            quantities["reward"] = rewards[0]
        if all_finite(*quantities.values()):
            return  # a false alarm of the fast check (a reward sum overflowed)
        t = int(self.core.t[0])
        where = f"at step {t}" if t else "at reset (step 0)"
        self.agents = []
        raise SatenvError(f"{self.metadata['name']}: non-finite "
                          f"{first_nonfinite(quantities, self.possible_agents)} {where}; the episode "
                          "is over, call reset()")

    # ----------------------------------------------------------------- spaces
    def observation_space(self, agent: str) -> spaces.Box:
        self._check_agent(agent)
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Box:
        self._check_agent(agent)
        return self._act_space

    @functools.cached_property
    def state_space(self) -> spaces.Box:
        """The space of :meth:`state` (float64, unbounded)."""
        return spaces.Box(-np.inf, np.inf, self.core.global_state()[0].shape, np.float64)

    def _check_agent(self, agent: str) -> None:
        if agent not in self._index:
            raise SatenvError(f"unknown agent {agent!r}; this env's agents are {self.possible_agents}")

    @property
    def np_random(self) -> np.random.Generator:
        """The env's random generator (created unseeded if ``reset`` has not seeded it)."""
        if self._rng is None:
            self._rng = np.random.default_rng()
        return self._rng

    # ------------------------------------------------------------------- API
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``options={"initial_state": array (M, state_dim)}`` overrides x0."""
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise SatenvTypeError(f"options must be a dict or None, got {type(options).__name__}")
        unknown = set(options) - self.reset_option_keys - self.api_probe_option_keys
        if unknown and not unknown <= self.__dict__.setdefault("_warned_options", set()):
            self._warned_options |= unknown    # once per env and key, not once per episode
            warnings.warn(f"ignoring unknown reset option(s) {sorted(unknown)}; "
                          f"known keys: {sorted(self.reset_option_keys)}", stacklevel=2)
        x0 = None  # every check before any change: a rejected reset leaves the env as it was
        if options.get("initial_state") is not None:
            x0 = self._check_initial_state(options["initial_state"])
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
                raise SatenvTypeError(f"seed must be a non-negative int or None, got {type(seed).__name__}")
            if seed < 0:
                raise SatenvError(f"seed must be a non-negative int or None, got {seed!r}")
            self._rng = np.random.default_rng(int(seed))
        rng = self.np_random
        if x0 is None:
            x0 = self.core.sample_initial_state(rng, 1)[0]
        info = with_safety_cost(self.core.reset(x0[None], None, rng))
        if self.reward_state is not None:
            self.reward_state.reset(info)
        self._last_info = info
        self._trails = []
        obs = self.core.observe()
        if not all_finite(obs, info["state"]):
            self._nonfinite(obs, None, info["state"])
        self.agents = list(self.possible_agents)
        return dict(zip(self.possible_agents, obs[0], strict=True)), self._info_dicts(info)

    def _check_initial_state(self, value: Any) -> np.ndarray:
        """A ``(M, state_dim)`` array inside the scenario's allowed region (``max_distance``)."""
        return states_in_region(value, f"options['initial_state'] (rows {self.possible_agents})",
                                self.scenario.max_distance, n_agents=self.core.n_agents,
                                width=self.core.state_dim)

    def step(self, actions: dict[str, Any]):
        """Apply normalised actions ``{agent: (action_dim,) in [-1, 1]}``; returns the 5 PettingZoo dicts."""
        if not self.agents:
            raise SatenvError("step() called with no live agents: call reset() first "
                              "(the episode has ended or never started)")
        a = self._action_array(actions)
        accel = unit_box_to_accel(a, self.scenario.u_max, self.scenario.thrust_mode)
        res, obs_arr = self.core.step_observe(accel[None], self.np_random)
        info = with_safety_cost(res.info)
        self._last_info = info
        truncated = bool(self.core.t[0] >= self.scenario.max_steps)
        terminated = bool(res.terminated[0])
        step_rewards = res.rewards if self.reward_state is None else self.reward_state.step(
            info, res.terminated, self.core.t >= self.scenario.max_steps)
        reward_list = step_rewards[0].tolist()
        if not (res.finite[0] if res.finite is not None
                else self._finite_step(obs_arr, res.info["state"], sum(reward_list))):
            self._nonfinite(obs_arr, step_rewards, res.info["state"])
        # zips of equal lengths (the core's rows); strict= costs time
        obs = dict(zip(self.possible_agents, self._rows(obs_arr[0])))  # noqa: B905
        rewards = dict(zip(self.possible_agents, reward_list))  # noqa: B905
        terms = dict.fromkeys(self.agents, terminated)
        truncs = dict.fromkeys(self.agents, truncated and not terminated)
        infos = self._info_dicts(info)
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    def _action_array(self, actions: Any) -> np.ndarray:
        if not isinstance(actions, dict):
            raise SatenvTypeError(f"actions must be a dict {{agent: array of shape ({self.core.action_dim},)}}, "
                              f"got {type(actions).__name__}")
        dim = self.core.action_dim
        if len(actions) == len(self.agents) == self.core.n_agents:
            # fast path: one conversion and one finiteness check for the whole team (real,
            # unmasked values only: anything else takes the checked path below)
            try:
                values = self._pick(actions)
                out = np.array(values)
            except (KeyError, TypeError, ValueError, OverflowError):
                out = None
            if (out is not None and out.dtype.kind in "fiu" and out.shape == (self.core.n_agents, dim)
                    and set(map(type, values)) <= _PLAIN_ACTION_TYPES and all_finite(out)):
                return out.astype(np.float64, copy=False)
        missing = [a for a in self.agents if a not in actions]
        extra = [a for a in actions if a not in self._index]
        if missing or extra:
            raise SatenvError(f"actions must have exactly one entry per live agent {self.agents}; "
                              f"missing {missing}, unknown {extra}")
        out = np.zeros((self.core.n_agents, dim))
        for agent, value in actions.items():
            arr = numeric(value, f"action for {agent} (normalised inputs in [-1, 1])")
            if arr.shape != (dim,):
                raise SatenvError(f"action for {agent} must have shape ({dim},), got {arr.shape}")
            out[self._index[agent]] = arr
        return out

    def _info_dicts(self, info: dict[str, np.ndarray]) -> dict[str, dict[str, Any]]:
        # one conversion per key: python scalars for per-agent scalars, rows for per-agent vectors
        # (views of the core's info arrays, which it never writes into again); new dicts each call
        columns = [arr[0].tolist() if arr.ndim == 2 else self._rows(arr[0]) for arr in info.values()]
        keys = tuple(info)
        rows = [dict(zip(keys, row)) for row in zip(*columns)]  # noqa: B905 (equal lengths)
        return dict(zip(self.possible_agents, rows))  # noqa: B905 (the core's rows)

    def state(self) -> np.ndarray:
        """The global state (true states of every agent, plus scenario extras)."""
        return np.asarray(self.core.global_state()[0], dtype=np.float64)

    # ---------------------------------------------------------------- render
    def render(self):
        """Draw the current scene (matplotlib, 3-D positions and trails); without a
        ``render_mode`` it warns and draws nothing."""
        if self.render_mode is None:
            warnings.warn(f"render() without a render mode draws nothing: make the env with "
                          f"render_mode='rgb_array' (frames) or 'human' (a window), e.g. "
                          f"satenv.make({self.metadata.get('name', 'platoon_v0')!r}, render_mode='rgb_array')",
                          UserWarning, stacklevel=2)
            return None
        from satenv.render import render_frame

        scene = self.core.render_scene(0)
        self._trails.append(np.asarray(scene["positions"]))
        frame, self._fig = render_frame(scene, np.array(self._trails), self._fig,
                                        show=self.render_mode == "human")
        return frame if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        if self._fig is not None:
            from satenv.render import close_figure

            close_figure(self._fig)
            self._fig = None


def resolve_preset(env_name: str, preset: str, presets: dict[str, Any], resolve: Any,
                   kwargs: dict[str, Any]) -> Any:
    """The frozen scenario of ``preset`` with ``kwargs`` overriding its fields.

    Unknown presets, unknown keywords and invalid values raise :class:`SatenvError` naming the
    env; ``resolve(preset, **overrides)`` is the scenario module's resolver.
    """
    if not isinstance(preset, str) or preset not in presets:
        raise SatenvError(f"{env_name}: unknown preset {preset!r}; expected one of {sorted(presets)}")
    allowed = {f.name for f in dataclasses.fields(presets[preset]) if f.init and not f.name.startswith("_")} - {"name"}
    reject_unknown_kwargs(kwargs, allowed, env_name)
    try:
        return resolve(preset, **kwargs)
    except SatenvError:
        raise
    except ValueError as exc:
        raise (SatenvTypeError if isinstance(exc, TypeError) else SatenvError)(f"{env_name}: {exc}") from None


def reject_unknown_kwargs(kwargs: dict[str, Any], allowed: set[str], env_name: str) -> None:
    """Raise :class:`SatenvError` for keyword arguments the env does not know."""
    unknown = sorted(set(kwargs) - allowed)
    if unknown:
        raise SatenvError(f"{env_name}: unknown keyword argument(s) {unknown}; "
                          f"accepted: {sorted(allowed)}")
