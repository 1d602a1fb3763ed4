"""The training configuration: one frozen, validated dataclass (CleanRL style).

Every field is a command-line flag of ``python -m training.train`` (``--total-timesteps 200000``,
``--env-kwargs '{"randomize": true}'``, ``--net-arch 64,64``); see :func:`parse_args`.
"""

from __future__ import annotations

import argparse
import json
import math
import types
import typing
from dataclasses import MISSING, asdict, dataclass, field, fields
from typing import Any

__all__ = ["TrainConfig", "parse_args", "config_from_json", "load_config", "planned_timesteps"]

ALGOS = ("ppo", "sac")


@dataclass(frozen=True)
class TrainConfig:
    """One training run. Timesteps count agent-steps (SB3 rows: ``n_copies * n_agents`` per env step).

    Environment:
        env_id: satenv env name (``"platoon_v0"``) or ``"package.module:callable"``.
        env_kwargs: keyword arguments of the env used for training (JSON object).
        eval_env_kwargs: overrides applied on top of ``env_kwargs`` for evaluation (e.g. train
            without termination at a collision, evaluate with it).
        n_copies: scenario copies stepped together in one batched core (``SatVecEnv``).
    Algorithm:
        algo: ``"ppo"`` or ``"sac"``; seed. total_timesteps: agent-steps to train for, rounded
            up to whole collection rounds: PPO rollouts of ``n_steps * n_copies * n_agents``
            agent-steps, SAC env steps of ``n_copies * n_agents`` (:func:`planned_timesteps`).
        net_arch: hidden layer sizes of the policy and value/Q networks.
        learning_rate, gamma: shared; lr_schedule: ``"constant"`` or ``"linear"`` (decays to 5 %
            of ``learning_rate`` at ``total_timesteps``). PPO: n_steps (rollout length per row), batch_size,
            n_epochs, gae_lambda, clip_range, ent_coef, vf_coef, max_grad_norm, log_std_init.
            SAC: buffer_size, learning_starts, sac_batch_size, train_freq, gradient_steps, tau.
        norm_obs / norm_reward / clip_obs: ``VecNormalize`` (statistics saved with the model).
        reward_shaping: training-only shaping terms (``training.shaping.RewardShaping`` fields,
            e.g. ``{"precision": 1.0, "proximity": 1.0}``); evaluation uses the env's metrics.
        obs_symlog_scale / obs_symlog_dims: appended symlog features of the first observation
            entries (``training.shaping.ObsFeatures``; 0 disables), re-applied at inference.
        obs_drop_dims: observation entries zeroed before the policy sees them (e.g. platoon_v0's
            entry 14, the fraction of the episode remaining), re-applied at inference.
        action_power: env action = ``sign(y)|y|^action_power`` of the network's ``y``
            (``training.shaping.ActionMap``; 1 = identity), re-applied at inference.
    Evaluation and artefacts:
        eval_every: evaluate every this many agent-steps (0: only at the end) on ``eval_seeds``
            with the PettingZoo env and ``satenv.rollout`` (the scoreboard's path), logged to
            TensorBoard next to the scripted ``eval_baselines`` (names of
            ``baselines.BASELINES``; ``"auto"``, the default, is ``zero`` and the scripted
            controllers without a per-decision NLP that support the env (dmpc, apf), so the
            evaluation stays cheap: the NLP baselines nmpc, tube_rdmpc, cgmres cost 0.5-16 min
            per episode; name them to include them; unsupported names are skipped with a warning).
        test_seeds: held-out seeds of the final evaluation summary (not used for selection).
        checkpoint_every: save model + normalisation every this many agent-steps (0: never).
        out_dir: run directory (``tb/``, ``checkpoints/``, ``best/``, ``final/``).
        torch_threads: ``torch.set_num_threads``; progress: show a tqdm bar.
    """

    env_id: str = "platoon_v0"
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    eval_env_kwargs: dict[str, Any] = field(default_factory=dict)
    n_copies: int = 32
    algo: str = "ppo"
    total_timesteps: int = 1_000_000
    seed: int = 0
    net_arch: tuple[int, ...] = (64, 64)
    learning_rate: float = 3e-4
    lr_schedule: str = "constant"
    gamma: float = 0.99
    n_steps: int = 64
    batch_size: int = 1024
    n_epochs: int = 5
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    log_std_init: float = 0.0
    buffer_size: int = 200_000
    learning_starts: int = 2_000
    sac_batch_size: int = 256
    train_freq: int = 1
    gradient_steps: int = 1
    tau: float = 0.005
    norm_obs: bool = True
    norm_reward: bool = True
    clip_obs: float = 10.0
    reward_shaping: dict[str, Any] = field(default_factory=dict)
    obs_symlog_scale: float = 0.0
    obs_symlog_dims: int = 6
    obs_drop_dims: tuple[int, ...] = ()
    action_power: float = 1.0
    eval_every: int = 100_000
    eval_seeds: tuple[int, ...] = tuple(range(10_000, 10_010))
    test_seeds: tuple[int, ...] = tuple(range(20_000, 20_050))
    eval_baselines: tuple[str, ...] = ("auto",)
    checkpoint_every: int = 100_000
    out_dir: str = "runs/train"
    torch_threads: int = 1
    progress: bool = True

    def __post_init__(self) -> None:
        s = object.__setattr__
        check_run_fields(self, ("env_kwargs", "eval_env_kwargs", "reward_shaping"))
        if self.lr_schedule not in ("constant", "linear"):
            raise ValueError(f"lr_schedule must be 'constant' or 'linear', got {self.lr_schedule!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name in ("n_copies", "total_timesteps", "n_steps", "batch_size", "n_epochs",
                     "buffer_size", "sac_batch_size", "train_freq", "gradient_steps", "torch_threads"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("seed", "learning_starts", "eval_every", "checkpoint_every"):
            check_int(name, getattr(self, name), minimum=0)
        s(self, "net_arch", check_net_arch(self.net_arch))
        for name, lo, hi in (("learning_rate", 0.0, math.inf), ("gamma", 0.0, 1.0),
                             ("gae_lambda", 0.0, 1.0), ("clip_range", 0.0, math.inf),
                             ("tau", 0.0, 1.0), ("clip_obs", 0.0, math.inf),
                             ("max_grad_norm", 0.0, math.inf)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo < v <= hi):
                raise ValueError(f"{name} must be a number in ({lo}, {hi}], got {v!r}")
        for name in ("ent_coef", "vf_coef"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 <= v < math.inf):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not isinstance(self.log_std_init, (int, float)) or not math.isfinite(self.log_std_init):
            raise ValueError(f"log_std_init must be a finite number, got {self.log_std_init!r}")
        from training.shaping import ActionMap, ObsFeatures, RewardShaping

        ActionMap(self.action_power)
        RewardShaping.from_dict(self.reward_shaping)
        ObsFeatures(self.obs_symlog_scale, self.obs_symlog_dims, self.obs_drop_dims)

    @property
    def resolved_eval_env_kwargs(self) -> dict[str, Any]:
        """The evaluation env's kwargs: ``env_kwargs`` updated with ``eval_env_kwargs``."""
        return {**self.env_kwargs, **self.eval_env_kwargs}

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        return d

    def replace(self, **changes: Any) -> TrainConfig:
        return config_from_json({**self.to_json(), **changes})


def round_timesteps(cfg: TrainConfig, n_agents: int) -> int:
    """Agent-steps of one collection round: a PPO rollout, or one SAC env step of every row."""
    return cfg.n_copies * n_agents * (cfg.n_steps if cfg.algo == "ppo" else 1)


def planned_timesteps(cfg: TrainConfig, n_agents: int) -> int:
    """``cfg.total_timesteps`` rounded up to whole collection rounds (what SB3 actually runs)."""
    per_round = round_timesteps(cfg, n_agents)
    return -(-cfg.total_timesteps // per_round) * per_round


def check_run_fields(cfg: Any, dict_fields: tuple[str, ...]) -> None:
    """Validate (and freeze) the fields every run config shares: ``env_id``, the JSON-object
    ``dict_fields``, ``eval_seeds``/``test_seeds`` (tuples of ints >= 0), ``eval_baselines``
    (a tuple of names) and ``out_dir``."""
    if not isinstance(cfg.env_id, str) or not cfg.env_id:
        raise ValueError(f"env_id must be a non-empty string such as 'platoon_v0', got {cfg.env_id!r}")
    for name in dict_fields:
        value = getattr(cfg, name)
        if not isinstance(value, dict):
            raise ValueError(f"{name} must be a dict (a JSON object on the command line), got {value!r}")
        try:
            json.dumps(value)
        except TypeError:
            raise ValueError(f"{name} must be JSON-serialisable (it is saved with the model), got {value!r}") from None
    for name in ("eval_seeds", "test_seeds"):
        seeds = tuple(getattr(cfg, name))
        for v in seeds:
            check_int(name, v, minimum=0)
        object.__setattr__(cfg, name, seeds)
    object.__setattr__(cfg, "eval_baselines", tuple(str(b) for b in cfg.eval_baselines))
    if not isinstance(cfg.out_dir, str) or not cfg.out_dir:
        raise ValueError(f"out_dir must be a non-empty path string, got {cfg.out_dir!r}")


def check_int(name: str, v: Any, minimum: int) -> None:
    """Raise ``ValueError`` unless ``v`` is an int (not a bool) >= ``minimum``."""
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}, got {v!r}")


def check_net_arch(value: Any) -> tuple[int, ...]:
    """Hidden layer sizes as a non-empty tuple of positive ints (``ValueError`` otherwise)."""
    arch = tuple(value)
    if not arch or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in arch):
        raise ValueError(f"net_arch must be a non-empty tuple of positive ints (e.g. 64,64), got {value!r}")
    return arch


def config_from_json(data: dict[str, Any], cls: type = TrainConfig) -> Any:
    """Rebuild a config dataclass ``cls`` (:class:`TrainConfig`, or another frozen run config such
    as :class:`training.imitate.ImitationConfig`) from its ``to_json`` output (unknown keys rejected)."""
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known: {sorted(known)}")
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for k, v in data.items():
        if _is_tuple(hints[k]) and isinstance(v, list):
            v = tuple(v)
        kwargs[k] = v
    return cls(**kwargs)


def load_config(path: str, cls: type = TrainConfig) -> Any:
    """The ``cls`` config saved in a ``config.json`` (a clear ``ValueError`` otherwise)."""
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"--config {path!r}: cannot read a JSON config ({err})") from None
    if not isinstance(data, dict):
        raise ValueError(f"--config {path!r}: expected a JSON object of {cls.__name__} fields")
    return config_from_json(data, cls)


def _is_tuple(tp: Any) -> bool:
    return typing.get_origin(tp) is tuple


def _parse_value(tp: Any, text: str, name: str) -> Any:
    origin = typing.get_origin(tp)
    try:
        if tp is bool:
            low = text.lower()
            if low not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return low in ("true", "1", "yes")
        if tp is int:
            return int(text)
        if tp is float:
            return float(text)
        if tp is str:
            return text
        if origin is tuple:
            (elem, _) = typing.get_args(tp)
            parts = [p for p in text.replace(" ", "").split(",") if p]
            if len(parts) == 1 and ":" in parts[0]:  # "a:b" -> range(a, b)
                lo, hi = parts[0].split(":")
                return tuple(range(int(lo), int(hi)))
            return tuple(elem(p) for p in parts)
        if origin is dict or tp is dict:
            value = json.loads(text)
            if not isinstance(value, dict):
                raise ValueError
            return value
    except (ValueError, json.JSONDecodeError):
        pass
    else:
        raise TypeError(f"unsupported config field type {tp!r} for {name}")  # pragma: no cover
    raise ValueError(f"--{name.replace('_', '-')}: cannot parse {text!r} as {getattr(tp, '__name__', tp)}"
                     + (" (a JSON object, e.g. '{\"randomize\": true}')" if origin is dict else "")
                     + (" (comma-separated, or 'a:b' for a range)" if origin is tuple else ""))


def build_parser(description: str = "", cls: type = TrainConfig) -> argparse.ArgumentParser:
    """An argparse parser with ``--config FILE`` and one ``--flag`` per field of the config
    dataclass ``cls`` (each default shown once)."""
    parser = argparse.ArgumentParser(
        description=description,
        epilog="Flags given override --config (or, with --resume, the run's saved config.json). "
               f"The fields are documented in {cls.__module__}.{cls.__name__}.")
    parser.add_argument("--config", metavar="FILE", default=None,
                        help="replay a run: start from this config.json (e.g. runs/x/config.json or "
                             "training/policies/<name>/config.json)")
    hints = typing.get_type_hints(cls)
    for f in fields(cls):
        default = f.default if f.default is not MISSING else f.default_factory()  # type: ignore[misc]
        shown = json.dumps(default) if isinstance(default, dict) else (
            _show_tuple(default) if isinstance(default, tuple) else default)
        parser.add_argument(f"--{f.name.replace('_', '-')}", dest=f.name, default=None, metavar=_metavar(hints[f.name]),
                            help=f"(default: {shown})")
    return parser


def _show_tuple(values: tuple) -> str:
    """``a:b`` for a run of consecutive ints (the flag's range syntax), else comma-separated."""
    if len(values) > 2 and all(isinstance(v, int) for v in values) and \
            list(values) == list(range(values[0], values[0] + len(values))):
        return f"{values[0]}:{values[0] + len(values)}"
    return ",".join(map(str, values))


def _metavar(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin is tuple:
        return "A,B,..."
    if origin is dict:
        return "JSON"
    return getattr(tp, "__name__", "X").upper() if not isinstance(tp, types.UnionType) else "X"


def parse_args(argv: list[str] | None = None, parser: argparse.ArgumentParser | None = None,
               base: Any = None, cls: type = TrainConfig) -> tuple[Any, argparse.Namespace]:
    """Parse ``argv`` into a ``cls`` config (:class:`TrainConfig` by default; flags given override
    ``base``, else ``--config FILE``, else the defaults); returns also the namespace."""
    parser = parser or build_parser(cls=cls)
    ns = parser.parse_args(argv)
    if base is None and ns.config is not None:
        base = load_config(ns.config, cls)
    hints = typing.get_type_hints(cls)
    changes = {}
    for f in fields(cls):
        text = getattr(ns, f.name)
        if text is not None:
            changes[f.name] = _parse_value(hints[f.name], text, f.name)
    base = base or cls()
    cfg = config_from_json({**base.to_json(), **changes}, cls) if changes else base
    return cfg, ns
