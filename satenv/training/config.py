"""Run configs of every training CLI and their one command-line grammar.

Each trainer (``satenv train``, ``satenv train-marl``, ``satenv train-rllib``; ``satenv imitate``
and ``satenv ppo`` share :class:`RunConfig`) is a frozen, validated dataclass whose fields are its flags: the
shared ones (:class:`RunConfig`: ``--env-id``, ``--env-kwargs``, ``--lr``, ``--eval-seeds``,
``--test-seeds``, ``--out-dir``, ...) have the same name, type and meaning everywhere. The
command line is parsed by argparse through :mod:`satenv.cliargs` (:func:`parse_args`), so
``--help`` shows each field's description (its docstring below), default and choices.

Grammar: JSON objects for kwargs (``--env-kwargs '{"randomize": true}'``), comma or space
separated lists (``--net-arch 64,64``), seeds as ``A-B`` (inclusive) or lists (``--test-seeds
0-49``, ``1,5,9``; at most :data:`MAX_SEEDS`), booleans as ``--flag true|false`` (or ``--flag`` /
``--no-flag``).
"""

from __future__ import annotations

import argparse
import json
import math
import typing
import warnings
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Annotated, Any, Literal

from satenv.cliargs import (
    Arg,
    add_config_flags,
    config_from_args,
    new_parser,
    out_folder,
    parse_bool,
    parse_json_object,
)
from satenv.tasks import MAX_SEEDS, SEED_SPLITS, parse_seeds, show_seeds  # the one seed grammar

__all__ = ["BUDGET_FLAG", "RunConfig", "announce", "TrainConfig", "canonical_flags", "parse_args", "parse_bool",
           "parse_seeds", "check_env_kwargs", "config_from_json", "load_config", "planned_timesteps", "MAX_SEEDS"]

ALGOS = ("ppo", "sac")

RENAMED = {"n_copies": "num_envs", "learning_rate": "lr", "num_envs_per_env_runner": "num_envs"}
"""Old config keys (``config.json`` written before the common grammar) -> current field names."""
DEPRECATED_FLAGS = {"--n-copies": "--num-envs", "--learning-rate": "--lr",
                    "--num-envs-per-env-runner": "--num-envs", "--ray-address": "--address",
                    "--total-timesteps": "--budget", "--algorithm": "--algo"}
"""Old flags still accepted (renamed to the canonical flag before parsing, with a
``FutureWarning`` naming it); ``--help`` lists only the canonical names."""
BUDGET_FLAG = "--budget"
"""Every trainer's training budget, in agent-steps (one agent's one decision)."""
OLD_BUDGET_FLAGS = {"--max-frames": "frames: env steps of one copy, all agents at once (budget / agents)",
                    "--iterations": "RLlib iterations of about train_batch_size env steps"}
"""Old budget flags in their own units, still accepted (``FutureWarning``): the trainer converts
``--budget`` to them; giving one with ``--budget`` is an error."""


def _ints(tokens: list[str]) -> tuple[int, ...]:
    try:
        return tuple(int(p) for a in tokens for p in a.split(",") if p.strip())
    except ValueError:
        raise ValueError(f"expected ints, e.g. 64,64, got {' '.join(tokens)!r}") from None


JsonDict = Annotated[dict[str, Any], Arg(parse=parse_json_object, metavar="JSON", show=json.dumps)]
Ints = Annotated[tuple[int, ...], Arg(parse=_ints, many=True, metavar="INT,...")]
Names = Annotated[tuple[str, ...], Arg(
    parse=lambda a: tuple(p.strip() for s in a for p in s.split(",") if p.strip()), many=True,
    metavar="NAME,...")]
Seeds = Annotated[tuple[int, ...], Arg(parse=parse_seeds, many=True, metavar="A-B|A,B,...", show=show_seeds)]
Flag = bool
"""A boolean field (``--flag``, ``--flag true|false``, ``--no-flag``)."""


def check_number(name: str, v: Any, lo: float, hi: float) -> None:
    """Raise ``ValueError`` unless ``v`` is a real number in ``(lo, hi]``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo < v <= hi):
        raise ValueError(f"{name} must be a number in ({lo}, {hi}], got {v!r}")


DEFAULT_TASK = "platoon-pereira2022-random"
"""The task a run trains on when neither ``--task`` nor ``--env-id`` is given (randomised starts)."""
DEFAULT_EVAL_SEEDS = tuple(SEED_SPLITS["validation"][:5])
DEFAULT_TEST_SEEDS = tuple(SEED_SPLITS["test"][:20])


@dataclass(frozen=True)
class RunConfig:
    """The fields every training CLI shares (same flag, same meaning, same grammar)."""

    task: str | None = None
    """A task of ``satenv.tasks`` (e.g. ``cluster-case1-random``): its env id and kwargs
    (``env_kwargs`` given are applied on top). Without ``--task`` and ``--env-id``:
    ``platoon-pereira2022-random`` (:data:`DEFAULT_TASK`)."""
    env_id: str | None = None
    """satenv env name (``platoon_v0``, ``cluster_v0``, ``servicing_v0``, ``formation_v0``) or
    ``package.module:callable`` (default: the task's)."""
    env_kwargs: JsonDict = field(default_factory=dict)
    """Keyword arguments of the training env, a JSON object (e.g. ``'{"randomize": true}'``)."""
    eval_env_kwargs: JsonDict = field(default_factory=dict)
    """Overrides applied on top of ``env_kwargs`` for evaluation (JSON object)."""
    seed: int = 0
    """Seed of the networks, the optimiser and the training env copies."""
    net_arch: Ints = (64, 64)
    """Hidden layer sizes of the networks (``64,64`` or ``64 64``)."""
    lr: float = 3e-4
    """Learning rate."""
    eval_seeds: Seeds = DEFAULT_EVAL_SEEDS
    """Seeds of the evaluations during training (``A-B`` inclusive, or a list ``1,5,9``); default:
    the first 5 validation seeds of ``satenv.tasks.SEED_SPLITS`` (one for a deterministic env)."""
    test_seeds: Seeds = DEFAULT_TEST_SEEDS
    """Held-out seeds of the final ``eval.json`` (never used for selection); default: the first 20
    test seeds of ``satenv.tasks.SEED_SPLITS`` (one for a deterministic env: every seed gives the
    same episode)."""
    eval_baselines: Names = ("auto",)
    """Scripted baselines evaluated beside the learned policy (names of ``satenv.baselines.BASELINES``;
    ``auto``: ``zero`` and the cheap controllers that support the env; the NLP controllers
    nmpc, tube_rdmpc, cgmres run only when named)."""
    out_dir: str = "runs/train"
    """Run folder: ``config.json`` (replayable, the budget actually run), ``final/`` (the policy
    with ``eval.json``; what ``satenv.training.load`` and ``satenv board --policy`` take)."""
    torch_threads: int = 1
    """``torch.set_num_threads``."""
    progress: Flag = True
    """Show progress bars (training and every evaluation)."""
    workers: int = 0
    """Processes for evaluation episodes (0: one per idle core, at most 2; 1: in this process)."""

    def __post_init__(self) -> None:
        self._resolve_task()
        check_run_fields(self, ("env_kwargs", "eval_env_kwargs"))
        check_env_kwargs(self)
        check_int("seed", self.seed, minimum=0)
        check_int("torch_threads", self.torch_threads, minimum=1)
        check_int("workers", self.workers, minimum=0)
        object.__setattr__(self, "net_arch", check_net_arch(self.net_arch))
        check_number("lr", self.lr, 0.0, math.inf)
        if not math.isfinite(self.lr):
            raise ValueError(f"lr must be a finite number > 0, got {self.lr!r}")
        if not isinstance(self.progress, bool):
            raise ValueError(f"progress must be a bool, got {self.progress!r}")

    def _resolve_task(self) -> None:
        """Fill ``env_id`` and ``env_kwargs`` from the task (or :data:`DEFAULT_TASK` when neither
        is given); one seed each for a satenv env that does not randomise its start."""
        from satenv import ENV_IDS, tasks

        task = self.task if self.task is not None or self.env_id is not None else DEFAULT_TASK
        if task is not None:
            t = tasks.get(task)
            if self.env_id not in (None, t.env_id):
                raise ValueError(f"env_id {self.env_id!r} does not match task {t.name!r} (env {t.env_id}); "
                                 "give one of --task and --env-id, or the task's env")
            object.__setattr__(self, "task", t.name)
            object.__setattr__(self, "env_id", t.env_id)
            if isinstance(self.env_kwargs, dict):
                object.__setattr__(self, "env_kwargs", {**t.env_kwargs, **self.env_kwargs})
        if (self.env_id in ENV_IDS and isinstance(self.env_kwargs, dict) and isinstance(self.eval_env_kwargs, dict)
                and not self.resolved_eval_env_kwargs.get("randomize", False)):
            for name, default in (("eval_seeds", DEFAULT_EVAL_SEEDS), ("test_seeds", DEFAULT_TEST_SEEDS)):
                if getattr(self, name) == default:
                    object.__setattr__(self, name, default[:1])

    @property
    def resolved_eval_env_kwargs(self) -> dict[str, Any]:
        """The evaluation env's kwargs: ``env_kwargs`` updated with ``eval_env_kwargs``."""
        return {**self.env_kwargs, **self.eval_env_kwargs}

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def replace(self, **changes: Any) -> Any:
        return config_from_json({**self.to_json(), **changes}, type(self))


@dataclass(frozen=True)
class TrainConfig(RunConfig):
    """One stable-baselines3 run (``satenv train``). Timesteps count agent-steps
    (SB3 rows: ``num_envs * n_agents`` per env step)."""

    algo: Literal["ppo", "sac"] = "ppo"
    """The algorithm."""
    total_timesteps: Annotated[int, Arg(name="budget")] = 1_000_000
    """The budget: agent-steps to train for, rounded up to whole collection rounds (PPO: ``n_steps
    * num_envs * n_agents``; SAC: ``num_envs * n_agents``); the rounded figure is printed and
    saved (``total_timesteps`` in ``config.json``)."""
    num_envs: int = 32
    """Scenario copies stepped together in one batched core."""
    lr_schedule: Literal["constant", "linear"] = "constant"
    """``linear`` decays to 5 % of ``lr`` at ``total_timesteps``."""
    gamma: float = 0.99
    """Discount factor."""
    n_steps: int = 64
    """PPO: rollout length per row."""
    batch_size: int = 1024
    """PPO: minibatch size."""
    n_epochs: int = 5
    """PPO: epochs per rollout."""
    gae_lambda: float = 0.95
    """PPO: GAE lambda."""
    clip_range: float = 0.2
    """PPO: clip range."""
    ent_coef: float = 0.0
    """PPO: entropy coefficient."""
    vf_coef: float = 0.5
    """PPO: value-loss coefficient."""
    max_grad_norm: float = 0.5
    """PPO: gradient-norm clip."""
    log_std_init: float = 0.0
    """Initial log standard deviation of the Gaussian policy."""
    buffer_size: int = 200_000
    """SAC: replay buffer size."""
    learning_starts: int = 2_000
    """SAC: agent-steps before learning starts."""
    sac_batch_size: int = 256
    """SAC: minibatch size."""
    train_freq: int = 1
    """SAC: env steps between updates."""
    gradient_steps: int = 1
    """SAC: gradient steps per update."""
    tau: float = 0.005
    """SAC: target smoothing coefficient."""
    norm_obs: Flag = True
    """``VecNormalize`` observations (statistics saved with the model)."""
    norm_reward: Flag = True
    """``VecNormalize`` rewards."""
    clip_obs: float = 10.0
    """``VecNormalize`` observation clip."""
    reward_shaping: JsonDict = field(default_factory=dict)
    """Training-only shaping terms (``satenv.training.shaping.RewardShaping`` fields, JSON object, e.g.
    ``'{"precision": 1.0}'``); evaluation uses the env's metrics."""
    obs_symlog_scale: float = 0.0
    """Scale of appended symlog features of the first observation entries (0 disables)."""
    obs_symlog_dims: int = 6
    """How many observation entries get symlog features."""
    obs_drop_dims: Ints = ()
    """Observation entries zeroed before the policy sees them (re-applied at inference)."""
    action_power: float = 1.0
    """Env action = ``sign(y)|y|^action_power`` of the network's ``y`` (1 = identity)."""
    eval_every: int = 100_000
    """Evaluate on ``eval_seeds`` every this many agent-steps (0: only at the end); the best
    model by (success rate, -RMSE) is kept in ``best/``."""
    checkpoint_every: int = 100_000
    """Save model + normalisation every this many agent-steps (0: never)."""
    init_actor: str = ""
    """PPO: start the actor and the observation normaliser from this policy folder (e.g. a DAgger
    network of ``satenv imitate``: its hidden sizes, activation and
    ``tanh`` output; ``--net-arch`` and the observation features must match it; no terminal
    feedback) instead of at random (``satenv.training.train.seed_actor``)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        check_run_fields(self, ("reward_shaping",))
        if not isinstance(self.init_actor, str):
            raise ValueError(f"init_actor must be a policy folder path or '', got {self.init_actor!r}")
        if self.init_actor and self.algo != "ppo":
            raise ValueError(f"init_actor seeds a PPO actor; algo is {self.algo!r}")
        if self.lr_schedule not in ("constant", "linear"):
            raise ValueError(f"lr_schedule must be 'constant' or 'linear', got {self.lr_schedule!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name in ("num_envs", "total_timesteps", "n_steps", "batch_size", "n_epochs",
                     "buffer_size", "sac_batch_size", "train_freq", "gradient_steps"):
            check_int(name, getattr(self, name), minimum=1)
        for name in ("learning_starts", "eval_every", "checkpoint_every"):
            check_int(name, getattr(self, name), minimum=0)
        for name, lo, hi in (("gamma", 0.0, 1.0),
                             ("gae_lambda", 0.0, 1.0), ("clip_range", 0.0, math.inf),
                             ("tau", 0.0, 1.0), ("clip_obs", 0.0, math.inf),
                             ("max_grad_norm", 0.0, math.inf)):
            check_number(name, getattr(self, name), lo, hi)
        for name in ("ent_coef", "vf_coef"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 <= v < math.inf):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not isinstance(self.log_std_init, (int, float)) or not math.isfinite(self.log_std_init):
            raise ValueError(f"log_std_init must be a finite number, got {self.log_std_init!r}")
        from satenv.training.shaping import ActionMap, ObsFeatures, RewardShaping

        ActionMap(self.action_power)
        RewardShaping.from_dict(self.reward_shaping)
        ObsFeatures(self.obs_symlog_scale, self.obs_symlog_dims, self.obs_drop_dims)


def announce(cfg: RunConfig, budget: str, *, tensorboard: bool = True, periodic: str = "") -> str:
    """What a run is about to do, printed (stderr) before it starts and returned: its budget, its
    evaluations, that the final evaluation takes time and how to shrink it, where it writes and
    how to watch it."""
    import sys

    from satenv.training.evaluate import AUTO

    named = ", ".join("zero and the cheap controllers" if b == AUTO else b for b in cfg.eval_baselines)
    text = (f"training on {cfg.task or cfg.env_id}: {budget}"
            + (f"; {periodic}" if periodic else "")
            + f".\nThe final evaluation then runs {len(cfg.test_seeds)} held-out episodes of the policy and of "
            f"each baseline ({named}) and can take longer than a small run's training (--test-seeds 900000-900004 "
            "and --eval-baselines zero shrink it; the baselines are cached for the next run).\n"
            f"Writes to {cfg.out_dir}/ (config.json, final/ with eval.json)"
            + (f"; watch it with: tensorboard --logdir {cfg.out_dir}/tb" if tensorboard else ""))
    print(text, file=sys.stderr, flush=True)
    return text


def round_timesteps(cfg: TrainConfig, n_agents: int) -> int:
    """Agent-steps of one collection round: a PPO rollout, or one SAC env step of every row."""
    return cfg.num_envs * n_agents * (cfg.n_steps if cfg.algo == "ppo" else 1)


def planned_timesteps(cfg: TrainConfig, n_agents: int) -> int:
    """``cfg.total_timesteps`` rounded up to whole collection rounds (what SB3 actually runs)."""
    per_round = round_timesteps(cfg, n_agents)
    return -(-cfg.total_timesteps // per_round) * per_round


def check_run_fields(cfg: Any, dict_fields: tuple[str, ...]) -> None:
    """Validate (and freeze) the fields every run config shares: ``env_id``, the JSON-object
    ``dict_fields``, ``eval_seeds``/``test_seeds`` (tuples of ints >= 0), ``eval_baselines``
    (a tuple of names) and ``out_dir``."""
    import satenv
    from satenv.baselines.registry import BASELINES

    if not isinstance(cfg.env_id, str) or not cfg.env_id:
        raise ValueError(f"env_id must be a non-empty string such as 'platoon_v0', got {cfg.env_id!r}")
    if cfg.env_id not in satenv.ENV_IDS and ":" not in cfg.env_id:
        raise ValueError(f"env_id {cfg.env_id!r:.80} is not registered; expected one of {list(satenv.ENV_IDS)} "
                         "(or a 'module:callable' id)")
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
        if len(seeds) > MAX_SEEDS:
            raise ValueError(f"{name}: {len(seeds)} seeds, more than the cap of {MAX_SEEDS}")
        for v in seeds:
            check_int(name, v, minimum=0)
        object.__setattr__(cfg, name, seeds)
    object.__setattr__(cfg, "eval_baselines", tuple(str(b) for b in cfg.eval_baselines))
    unknown = [b for b in cfg.eval_baselines if b not in BASELINES and b != "auto"]
    if unknown:
        raise ValueError(f"eval_baselines: {unknown!r:.80} not registered; expected names of {sorted(BASELINES)} "
                         "(or 'auto')")
    if not isinstance(cfg.out_dir, str) or not cfg.out_dir:
        raise ValueError(f"out_dir must be a non-empty path string, got {cfg.out_dir!r}")
    try:
        out_folder(cfg.out_dir)
    except argparse.ArgumentTypeError as err:
        raise ValueError(f"out_dir: {err}") from None


def check_env_kwargs(cfg: Any) -> None:
    """``env_kwargs`` and ``eval_env_kwargs`` of a satenv env id are accepted by its env (built
    once with each, about a millisecond): an unknown keyword or a bad value is an error naming the
    field, before a run folder is made. A ``module:callable`` id is not built here (that runs code)."""
    import satenv

    if cfg.env_id not in satenv.ENV_IDS:
        return
    for name, kwargs in (("env_kwargs", cfg.env_kwargs), ("eval_env_kwargs", cfg.resolved_eval_env_kwargs)):
        try:
            satenv.make(cfg.env_id, **kwargs).close()
        except (ValueError, TypeError) as err:
            raise type(err)(f"{name}: {err}") from None


def check_int(name: str, v: Any, minimum: int) -> None:
    """Raise ``ValueError`` unless ``v`` is an int (not a bool) >= ``minimum``."""
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}, got {v!r}")


MAX_LAYER_WIDTH = 8192
"""The widest hidden layer ``net_arch`` takes: an 8192 x 8192 layer has 67 M weights (256 MB in
float32); a wider one is a typo, not a network, and would fail in the allocator."""


def check_net_arch(value: Any) -> tuple[int, ...]:
    """Hidden layer sizes as a non-empty tuple of ints in ``[1, MAX_LAYER_WIDTH]`` (``ValueError``
    otherwise)."""
    arch = tuple(value)
    if not arch or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in arch):
        raise ValueError(f"net_arch must be a non-empty tuple of positive ints (e.g. 64,64), got {value!r}")
    if max(arch) > MAX_LAYER_WIDTH:
        raise ValueError(f"net_arch: a layer of {max(arch)} units is wider than MAX_LAYER_WIDTH = "
                         f"{MAX_LAYER_WIDTH}, got {value!r:.80}")
    return arch


def config_from_json(data: dict[str, Any], cls: type = TrainConfig) -> Any:
    """Rebuild a config dataclass ``cls`` (a :class:`RunConfig` subclass) from its ``to_json``
    output: old key names (:data:`RENAMED`) are mapped, unknown keys rejected."""
    known = {f.name for f in fields(cls)}
    data = {RENAMED.get(k, k) if k not in known and RENAMED.get(k) in known else k: v for k, v in data.items()}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known: {sorted(known)}")
    hints = typing.get_type_hints(cls)
    kwargs = {k: tuple(v) if typing.get_origin(_bare(hints[k])) is tuple and isinstance(v, list) else v
              for k, v in data.items()}
    return cls(**kwargs)


def _bare(tp: Any) -> Any:
    return typing.get_args(tp)[0] if typing.get_origin(tp) is Annotated else tp


def load_config(path: str, cls: type = TrainConfig, *, allow_code_env_id: bool = False) -> Any:
    """The ``cls`` config saved in a ``config.json`` (a clear ``ValueError`` otherwise).

    The file is untrusted data: :func:`satenv.training.trust.check_replayed_config` vets the names it
    holds (registered env ids and baselines only; a ``module:callable`` env id needs
    ``allow_code_env_id``, the CLI flag ``--allow-code-env-id``) before anything is built.
    """
    from satenv.training.trust import UntrustedDataError, check_replayed_config, read_json

    where = Path(path)
    try:
        data = read_json(where.parent, where.name)
    except UntrustedDataError as err:
        raise UntrustedDataError(f"--config: {err}") from None
    check_replayed_config(data, allow_code_env_id=allow_code_env_id, source=f"--config {path}")
    return config_from_json(data, cls)


class CliOptions(typing.NamedTuple):
    """The options outside the config dataclass."""

    config: str | None
    resume: bool
    allow_code_env_id: bool = False


def parse_args(argv: list[str] | None = None, *, cls: type = TrainConfig, base: Any = None,
               description: str | None = None, resume: bool = False,
               prog: str | None = None) -> tuple[Any, CliOptions]:
    """Parse ``argv`` into a ``cls`` config: flags override ``base``, else ``--config FILE`` (a
    saved ``config.json`` to replay), else, with ``--resume`` (when ``resume`` is offered), the run
    folder's saved ``config.json``, else the field defaults.

    A bad flag or value exits (``SystemExit(2)``) with one ``error:`` line naming the flag; a bad
    ``--config`` file raises ``ValueError``.
    """
    import sys

    from satenv.training import runfolder
    from satenv.training.trust import CODE_FLAG

    argv = canonical_flags(list(sys.argv[1:] if argv is None else argv))
    old_flags = ", ".join(f"{o} (now {n})" for o, n in DEPRECATED_FLAGS.items())
    parser = new_parser(prog, description or cls.__doc__,
                        f"Old flags still accepted, with a FutureWarning: {old_flags}.", usage="%(prog)s [OPTIONS]")
    add_config_flags(parser, cls)
    runs = parser.add_argument_group("replay and resume")
    runs.add_argument("--config", metavar="FILE", help="replay a run: its config.json (flags given override it)")
    runs.add_argument(CODE_FLAG, dest="allow_code_env_id", action="store_true",
                      help="a replayed config may name only registered env ids and baselines; this also "
                           "admits a 'module:callable' env id, which imports and runs that code (only for a "
                           "file you trust)")
    if resume:
        runs.add_argument("--resume", action="store_true",
                          help="continue the run in --out-dir from its saved config.json and last checkpoint "
                               "(flags given override it); a folder with neither starts the run fresh")
    ns = parser.parse_args(argv)
    if ns.config == "":
        parser.error("--config '': expected a FILE (a run's config.json)")
    opts = CliOptions(ns.config, getattr(ns, "resume", False), ns.allow_code_env_id)
    if base is None and opts.config is not None:
        base = load_config(opts.config, cls, allow_code_env_id=opts.allow_code_env_id)
    # without a base the field defaults (not a resolved instance: the default task's env must not
    # stick to a run given another --task)
    cfg = config_from_args(parser, cls, ns, base)
    if opts.resume and base is None and runfolder.resumable(cfg.out_dir):
        saved = f"{cfg.out_dir}/config.json"
        try:
            saved_cfg = load_config(saved, cls, allow_code_env_id=opts.allow_code_env_id)
        except ValueError as err:
            raise ValueError(f"--resume: {err} (a run folder's config.json, written by a run without "
                             "--resume)") from None
        cfg = config_from_args(parser, cls, ns, saved_cfg)
    return cfg, opts


def canonical_flags(argv: list[str]) -> list[str]:
    """``argv`` with every old flag (:data:`DEPRECATED_FLAGS`, also as ``--old=value``) renamed to
    its canonical name, one ``FutureWarning`` per old flag; an old budget flag
    (:data:`OLD_BUDGET_FLAGS`) is kept (its unit differs) with a ``FutureWarning``, and giving
    two budget flags is an error (``SystemExit``)."""
    out, budgets = [], []
    for arg in argv:
        flag, sep, value = arg.partition("=")
        if flag in DEPRECATED_FLAGS:
            warnings.warn(f"{flag} is deprecated: use {DEPRECATED_FLAGS[flag]}", FutureWarning, stacklevel=3)
            flag = DEPRECATED_FLAGS[flag]
        elif flag in OLD_BUDGET_FLAGS:
            warnings.warn(f"{flag} is the old budget flag ({OLD_BUDGET_FLAGS[flag]}); use {BUDGET_FLAG} N, "
                          "N in agent-steps, as for every trainer", FutureWarning, stacklevel=3)
        if flag == BUDGET_FLAG or flag in OLD_BUDGET_FLAGS:
            budgets.append(flag)
        out.append(flag + sep + value)
    if len(budgets) > 1:
        raise SystemExit(f"error: give one budget flag, got {' and '.join(budgets)} ({BUDGET_FLAG} N: agent-steps)")
    return out
