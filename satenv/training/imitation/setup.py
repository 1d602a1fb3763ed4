"""What a run flies and trains: its envs, its expert, its network (cold or a warm start) and the
safety filter a warm start ships with."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

from satenv import tasks

__all__ = ["Envs", "Network", "cold_network", "make_envs", "make_expert", "paper_task", "score", "warm_network",
           "warm_start_filter", "warm_start_folder"]


class Envs(NamedTuple):
    """The run's envs: collection (the training task; collisions may not end it), the paper
    start's collection env (``None`` without a paper task), and their evaluation twins."""

    collect: Any
    paper: Any
    eval: Any
    paper_eval: Any


class Network(NamedTuple):
    """The learner: its policy (``LearnedPolicy``, normaliser ``None`` until the first labels of a
    cold run), the ``env.json`` and ``config.json`` its round folders carry, and the filter it
    ships behind (``None``: none)."""

    policy: Any
    meta: dict[str, Any]
    config: dict[str, Any]
    shipped_filter: Any


def score(env: Any, policy: Any, seeds: Any) -> dict[str, Any]:
    """:func:`satenv.scoring.aggregate` of ``policy``'s episodes on ``seeds``."""
    from satenv.scoring import aggregate, run_episodes

    return aggregate(run_episodes(env, policy, seeds))


def paper_task(task: str | None, system: str | None) -> Any:
    """The paper task of ``system`` (``None`` without a system, or when it is ``task`` itself)."""
    if system is None:
        return None
    paper = tasks.paper_task(system)
    return None if paper.name == task else paper


def collect_kwargs(env_id: str, kwargs: dict[str, Any], through_collisions: bool) -> dict[str, Any]:
    """A collection env's kwargs: ``kwargs``, and no end at a collision when asked (satenv envs)."""
    import satenv

    through = through_collisions and env_id in satenv.ENV_IDS
    return {**kwargs, "terminate_on_collision": False} if through else dict(kwargs)


def make_envs(env_id: str, env_kwargs: dict[str, Any], eval_env_kwargs: dict[str, Any], task: str | None,
              system: str | None, through_collisions: bool) -> Envs:
    """:class:`Envs` (the paper envs get the run's own ``env_kwargs`` overrides)."""
    from satenv.training.envs import make_env

    collect = make_env(env_id, **collect_kwargs(env_id, env_kwargs, through_collisions))
    ev = make_env(env_id, **{**env_kwargs, **eval_env_kwargs})
    paper = paper_task(task, system)
    if paper is None:
        return Envs(collect, None, ev, None)
    own = dict(tasks.get(task).env_kwargs)
    extra = {k: v for k, v in env_kwargs.items() if k not in own or own[k] != v}
    kwargs = {**paper.env_kwargs, **extra}
    return Envs(collect, make_env(paper.env_id, **collect_kwargs(paper.env_id, kwargs, through_collisions)), ev,
                make_env(paper.env_id, **{**kwargs, **eval_env_kwargs}))


def make_expert(name: str, env: Any, options: dict[str, Any]) -> Any:
    """The expert ``name`` for ``env`` (``satenv.baselines.experts.make``)."""
    from satenv.baselines.experts import make

    return make(name, env, **options)


def cold_network(env: Any, config: dict[str, Any], meta: dict[str, Any], seed: int) -> Network:
    """A new network for ``env`` from the run's ``config`` (architecture, features, terminal
    feedback), its weights drawn from ``seed``."""
    import torch

    from satenv.training.actor import MLPActor
    from satenv.training.policy import LearnedPolicy, terminal_from_config
    from satenv.training.shaping import ObsFeatures

    agent = env.possible_agents[0]
    obs_dim, act_dim = env.observation_space(agent).shape[0], env.action_space(agent).shape[0]
    feats = ObsFeatures(config["obs_symlog_scale"], config["obs_symlog_dims"], tuple(config["obs_drop_dims"]))
    torch.manual_seed(seed)
    hidden, act, squash = list(config["net_arch"]), config["activation"], config["squash"]
    if config["architecture"] == "set":
        from satenv.training.set_policy import SetActor, slot_layout

        own, slot, k = slot_layout(env)
        if feats.drop_dims and feats.drop_dims[-1] >= own:
            raise ValueError(f"obs_drop_dims {list(feats.drop_dims)} must be own entries (< {own}) with "
                             "architecture='set' (a dropped slot entry would break the permutation invariance)")
        actor = SetActor(feats.out_dim(obs_dim), act_dim, own, slot, k, list(config["set_encoder"]), hidden, act,
                         squash)
    else:
        actor = MLPActor(feats.out_dim(obs_dim), act_dim, hidden, act, squash)
    policy = LearnedPolicy(actor, None, obs_shape=(obs_dim,), features=feats,
                           meta=meta, terminal=terminal_from_config(config))
    return Network(policy, meta, config, None)


def warm_start_folder(folder: str | Path) -> Path:
    """``folder`` if it is a real folder; absent, a file or a symbolic link is a
    :class:`~satenv.training.imitation.folder.RunFolderError` naming ``warm_start``."""
    from satenv.training.imitation.folder import check_folder
    from satenv.training.runfolder import RunFolderError

    root = check_folder(Path(folder), "warm_start policy folder")
    if not root.is_dir():
        raise RunFolderError(f"warm_start {folder}: no such policy folder")
    return root


def warm_start_filter(folder: str | Path) -> Any:
    """The :class:`satenv.safety.SafetyConfig` a policy folder ships with (``env.json``
    ``"safety_filter"``; the default filter when it ships none): the filter of the labels, the
    rows, the flights behind it and the validation."""
    from satenv.safety import SafetyConfig
    from satenv.training.imitation.folder import read_run_json
    from satenv.training.policy import shipped_filter
    from satenv.training.trust import MAX_JSON_BYTES

    root = warm_start_folder(folder)
    meta = read_run_json(root, "env.json", "the warm start's env.json", MAX_JSON_BYTES)
    if not isinstance(meta, dict):
        raise ValueError(f"warm_start {folder}: env.json must be a JSON object")
    return shipped_filter(root, meta) or SafetyConfig()


def warm_network(folder: str, imitation: dict[str, Any]) -> Network:
    """The network of the policy folder ``folder`` (its own features, normaliser and feedback),
    whose rounds carry its ``env.json`` and its ``config.json`` with the run's config under
    ``"imitation"``; the filter it ships with (the default filter when it ships none)."""
    from satenv.training.imitation.folder import read_run_json
    from satenv.training.policy import load
    from satenv.training.trust import MAX_JSON_BYTES

    root = warm_start_folder(folder)
    meta = read_run_json(root, "env.json", "the warm start's env.json", MAX_JSON_BYTES)
    config = read_run_json(root, "config.json", "the warm start's config.json", MAX_JSON_BYTES)
    if not isinstance(meta, dict) or not isinstance(config, dict):
        raise ValueError(f"warm_start {folder}: env.json and config.json must be JSON objects")
    policy = load(root, shielded=False)
    config = {k: v for k, v in config.items() if k not in ("imitation", "safe_dagger", "round", "recipe")}
    return Network(policy, meta, {**config, "imitation": imitation}, warm_start_filter(root))
