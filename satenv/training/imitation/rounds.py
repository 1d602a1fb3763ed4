"""The one rounds loop of imitation, resumable after a kill at any moment.

Every round ``k``: fly and label the round's episodes (:func:`satenv.training.imitation.collect.collect_episode`),
save them to ``labels/round_NNNN.npz``, fit the network on every round's labels (warm start),
score it on the validation seeds (alone, and behind the filter for the safe variants or
``learner_shield``), save it to ``rounds/NNNN/`` and append the round to ``history.json``, written
last: a run resumes after the last round it records. Round ``k``'s randomness (the flights' draws,
the minibatch order) comes from ``(seed, k)`` alone and the network is read back from round
``k - 1``'s folder bit for bit, so a resumed run equals an uninterrupted one. After the last round,
``final/`` (:func:`finish`): the network with ``eval.json`` on the held-out test seeds.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from satenv import tasks
from satenv.training.imitation import setup
from satenv.training.imitation.config import ImitationConfig
from satenv.training.imitation.folder import (
    check_folder,
    label_path,
    read_history,
    read_labels,
    round_folder,
)
from satenv.training.imitation.plot import total_loss
from satenv.training.imitation.setup import score

__all__ = ["RECIPE", "finish", "run"]

RECIPE = "satenv.training.imitation"
"""The ``recipe`` a run's policy folders name."""


def round_seeds(seed: int, k: int) -> tuple[np.random.Generator, Any]:
    """Round ``k``'s generators: the flights' (numpy) and the fit's (torch), from ``(seed, k)``."""
    import torch

    return np.random.default_rng([seed, k]), torch.Generator().manual_seed(seed + k)


def read_prior(names: tuple[str, ...], obs_dim: int) -> dict[str, np.ndarray] | None:
    """``obs`` and ``act`` of the prior label files (a folder: its ``round_*.npz``)."""
    files = [f for n in names for f in (sorted(Path(n).glob("round_*.npz")) if Path(n).is_dir() else [Path(n)])]
    if names and not files:
        raise ValueError(f"prior_labels {list(names)}: no round_*.npz label files there")
    parts = []
    for f in files:
        d = read_labels(f, "prior labels (obs, act)")
        if "obs" not in d or "act" not in d or d["obs"].ndim != 2 or d["obs"].shape[1] != obs_dim:
            raise ValueError(f"prior_labels {f}: expected obs of {obs_dim} entries per row and act, got "
                             f"{ {k: v.shape for k, v in d.items()} }")
        parts.append({"obs": d["obs"].astype(np.float32), "act": np.clip(d["act"], -1, 1).astype(np.float32)})
    return {k: np.concatenate([p[k] for p in parts]) for k in ("obs", "act")} if parts else None


def run(cfg: ImitationConfig, run_dir: str | Path | None = None, *, resume: bool = True) -> Path | None:
    """Run (or continue after the last round ``history.json`` records) ``cfg`` in ``run_dir``
    (default: ``cfg.out_dir``); returns ``final/`` (``None`` when ``final_eval`` is off or no round ran)."""
    import torch

    from satenv.training import runfolder
    from satenv.training.envs import policy_env_meta

    run_dir = check_folder(Path(cfg.out_dir if run_dir is None else run_dir))
    history = read_history(run_dir)
    if (run_dir / "eval_history.json").is_file() and not history:
        raise ValueError(f"{run_dir} is a run folder of an earlier DAgger (eval_history.json, data.npz), which "
                         f"this engine cannot continue; replay it in a new folder: --config "
                         f"{run_dir / 'config.json'} --out-dir NEW_DIR")
    if history and not resume:
        raise ValueError(f"{run_dir} already has {len(history)} rounds; resume it or choose another out_dir")
    for sub in ("labels", "rounds"):
        check_folder(run_dir / sub, f"{sub} folder")
    torch.set_num_threads(cfg.torch_threads)
    envs = setup.make_envs(cfg.env_id, cfg.env_kwargs, cfg.eval_env_kwargs, cfg.task, cfg.system,
                           cfg.collect_through_collisions)
    meta = policy_env_meta(cfg.env_id, envs.collect, setup.collect_kwargs(cfg.env_id, cfg.env_kwargs,
                           cfg.collect_through_collisions), cfg.resolved_eval_env_kwargs)
    net = (setup.warm_network(cfg.warm_start, cfg.to_json()) if cfg.warm_start is not None else
           setup.cold_network(envs.collect, {**cfg.to_json(), "out_dir": str(run_dir), "recipe": RECIPE}, meta,
                              cfg.seed))
    experts = _experts(cfg.label, cfg.expert, cfg.expert_options, cfg.warm_start, envs)
    label_config = label_filter_config(cfg.label_filter, net.shipped_filter)
    if cfg.safe:
        check_label_space(cfg.label, cfg.imitation_space, net.policy)
    (run_dir / "labels").mkdir(parents=True, exist_ok=True)   # written once the warm start and experts are read
    runfolder.write_json(run_dir / "config.json", {**cfg.to_json(), "out_dir": str(run_dir)}, indent=2)
    fitted = cfg.warm_start is not None          # the normaliser is the warm start's, or round 0's
    if history:
        _restore(net.policy, round_folder(run_dir, len(history) - 1))
        fitted = True
    obs_dim = net.policy.obs_shape[0]
    prior = read_prior(cfg.prior_labels, obs_dim)
    episode = int(history[-1].get("episodes", 0)) if history else 0
    flights = Flights.of(cfg)
    norm_mode = _norm_mode(envs.collect) if cfg.safe else False
    paper_seeds = tasks.paper_task(cfg.system).seeds("validation", 1) if envs.paper_eval is not None else ()
    shield_seeds = ((cfg.eval_seeds[:cfg.shield_seeds] if cfg.shield_seeds else cfg.eval_seeds)
                    if cfg.safe or cfg.learner_shield else None)
    t_start = time.perf_counter()
    for k in range(len(history), cfg.rounds):
        rng, generator = round_seeds(cfg.seed, k)
        t0 = time.perf_counter()
        n_eps = cfg.round0_episodes if k == 0 else cfg.episodes_per_round
        batch, flown = fly_round(flights, k, n_eps, envs, experts, net, label_config, rng, episode, fitted)
        episode += len(flown)
        _save_labels(run_dir, k, batch)
        collect_s = time.perf_counter() - t0
        data = _all_rows(run_dir, k + 1)
        if not fitted:
            seen = data["obs"] if prior is None else np.concatenate([prior["obs"], data["obs"]])
            net.policy.normalizer = _normalizer(net.policy, seen, cfg.clip_obs, cfg.architecture)
            fitted = True
        t1 = time.perf_counter()
        cold = k == 0 and cfg.warm_start is None                 # a cold network's first fit is longer
        loss, n_rows = _fit(net.policy, data, prior, generator, safe_loss(cfg) if cfg.safe else None, norm_mode,
                            lr=cfg.lr, epochs=cfg.epochs * (cfg.round0_epoch_factor if cold else 1),
                            batch_size=cfg.batch_size, weight_decay=cfg.weight_decay)
        entry = {"task": cfg.task, "system": cfg.system, "round": k, "labels": n_rows, "episodes": episode,
                 "loss": loss, "beta": cfg.beta ** k if not cfg.safe else 0.0, "collect_s": round(collect_s, 1),
                 "fit_s": round(time.perf_counter() - t1, 1),
                 **validate(envs, net, cfg.eval_seeds, paper_seeds, shield_seeds)}
        if cfg.safe:
            steps = sum(s["agent_steps"] for s in flown)
            entry["flown_interventions_per_agent_step"] = sum(s["interventions"] for s in flown) / max(1, steps)
        history.append({**entry, "session_wall_s": round(time.perf_counter() - t_start, 1), "collected": flown})
        _save_round(run_dir, k, net, history)
        _report(k, history[-1])
    if not cfg.final_eval or not history:
        return None
    return finish(run_dir, net, history, envs.eval, reference=reference_name(cfg.expert, cfg.env_id),
                  baselines=cfg.eval_baselines, test_seeds=cfg.test_seeds, baseline_seeds=cfg.baseline_seeds,
                  eval_key={"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs},
                  expert=cfg.expert, teacher=cfg.expert or cfg.label, progress=cfg.progress, workers=cfg.workers)


def _experts(label: str, expert: str | None, options: dict[str, Any], warm_start: str | None,
             envs: setup.Envs) -> dict[int, Any]:
    """The labeller of each collection env: the expert, the frozen warm start (``label="teacher"``)
    or none (``label="self"``: the network's own action)."""
    if label == "self":
        return {}
    if label == "teacher":
        from satenv.training.policy import load

        teacher = load(check_folder(Path(warm_start), "warm-start policy folder"), shielded=False)
        return {id(e): teacher for e in (envs.collect, envs.paper) if e is not None}
    return {id(e): setup.make_expert(expert, e, options) for e in (envs.collect, envs.paper) if e is not None}


def label_filter_config(options: dict[str, Any], shipped: Any) -> Any:
    """The filter of the labels and barrier rows: the shipped one with ``options`` replaced
    (``None`` without options: the shipped filter itself)."""
    if not options:
        return None
    from satenv.safety import SafetyConfig

    return SafetyConfig.from_options(shipped, **options)


def check_label_space(label: str, imitation_space: str, policy: Any) -> None:
    """Refuse teacher labels compared with the network's own output when the network blends in
    terminal feedback: the teacher's label is a flown action (feedback blended in, then filtered),
    so ``"network"`` space would pull the raw output away from the warm start even where the
    filter passes it; ``"flown"`` has the warm start as its minimiser there."""
    from satenv.errors import SatenvError

    term = getattr(policy, "terminal", None)
    if label == "teacher" and imitation_space == "network" and term is not None and getattr(term, "active", True):
        raise SatenvError("imitation_space must be 'flown' with label 'teacher' when the warm start has terminal "
                          "feedback (the teacher's label is a flown action), got 'network'")


class Flights(NamedTuple):
    """How a round's episodes are flown (the collection fields of :class:`ImitationConfig`)."""

    fly: str
    train_seed: int
    paper_start_share: float
    beta: float
    noise_share: float
    noise_std: float
    learner_shield: bool
    collect_decisions: int
    progress: bool

    @classmethod
    def of(cls, cfg: ImitationConfig) -> Flights:
        return cls(*(getattr(cfg, name) for name in cls._fields))


def fly_round(flights: Flights, k: int, n_episodes: int, envs: setup.Envs, experts: dict[int, Any],
              net: setup.Network, label_config: Any, rng: np.random.Generator, episode: int,
              fitted: bool) -> tuple[dict[str, np.ndarray], list[dict[str, Any]]]:
    """Round ``k``'s ``n_episodes`` (seeds ``train_seed + episode ...``), each from the paper start
    with probability ``paper_start_share``, a round 0's with noise with probability ``noise_share``."""
    from satenv.safety import shield
    from satenv.training.imitation.collect import collect_episode, episode_flight

    f = flights
    parts, flown = [], []
    for j in range(n_episodes):
        from_paper = envs.paper is not None and rng.random() < f.paper_start_share
        env = envs.paper if from_paper else envs.collect
        seed = f.train_seed + episode + j
        if f.fly != "dagger":
            part, stats = collect_episode(env, experts.get(id(env)), net.policy, seed, fly=episode_flight(f.fly, j),
                                          filter_config=net.shipped_filter, label_config=label_config,
                                          max_decisions=f.collect_decisions)
        else:
            noise = f.noise_std if (k == 0 and rng.random() < f.noise_share) else 0.0
            learner = None if not fitted else (shield(net.policy, env) if f.learner_shield else net.policy)
            part, stats = collect_episode(env, experts[id(env)], learner, seed, beta=f.beta ** k, noise=noise, rng=rng)
        parts.append(part)
        flown.append({**stats, "paper_start": from_paper})
        if f.progress:
            print(f"  episode {json.dumps(flown[-1])}", flush=True)
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}, flown


def _normalizer(policy: Any, obs: np.ndarray, clip: float, architecture: str) -> Any:
    """The observation normaliser of round 0's features (mean and variance)."""
    from satenv.training.policy import ObsNormalizer

    fx = policy.features(obs.astype(np.float64))
    if architecture == "set":
        from satenv.training.set_policy import set_statistics

        return ObsNormalizer(*set_statistics(policy.actor.spec, fx), clip)
    return ObsNormalizer(fx.mean(0), fx.var(0), clip)


def _fit(policy: Any, data: dict[str, np.ndarray], prior: dict[str, np.ndarray] | None, generator: Any,
         loss: Any, norm_mode: bool, *, lr: float, epochs: int, batch_size: int,
         weight_decay: float) -> tuple[Any, int]:
    """The round's fit: the safe ``loss`` (a :class:`satenv.training.imitation.fit.SafeLoss`), or
    without one DAgger's regression on the prior and own labels; the loss and the rows fitted on."""
    from satenv.training.imitation.fit import fit_safe, inputs, regress

    if loss is not None:
        terms = fit_safe(policy, data, loss, lr=lr, epochs=epochs, batch_size=batch_size, norm_mode=norm_mode,
                         generator=generator, prior=prior)
        return terms, int(len(data["obs"]))
    x, y = data["obs"], np.clip(data["act"], -1, 1)
    if prior is not None:
        x, y = np.concatenate([prior["obs"], x]), np.concatenate([prior["act"], y])
    mse = regress(policy.actor, inputs(policy, x).numpy(), y, lr=lr, epochs=epochs, batch_size=batch_size,
                  generator=generator, weight_decay=weight_decay)
    return mse, int(len(x))


def _norm_mode(env: Any) -> bool:
    """Whether the env's action bound is a norm ball (the barrier's attainable bound), else a box."""
    from satenv.safety import safety_model

    return safety_model(env).norm_mode if hasattr(env, "core") else False


def safe_loss(cfg: ImitationConfig) -> Any:
    """The safe loss's terms and weights of ``cfg``."""
    from satenv.training.imitation.fit import SafeLoss

    return SafeLoss(cfg.label, cfg.w_int, cfg.w_bar, cfg.bar_margin, cfg.alone_weight, cfg.prior_weight,
                    cfg.imitation_space, cfg.prior_space)


def validate(envs: setup.Envs, net: setup.Network, eval_seeds: tuple[int, ...], paper_seeds: tuple[int, ...],
             shield_seeds: tuple[int, ...] | None) -> dict[str, Any]:
    """The network alone on ``eval_seeds`` (``val``) and the paper start's ``paper_seeds``
    (``paper``), and behind the filter it ships with on ``shield_seeds`` (``shield``; ``None``: not
    scored)."""
    from satenv.safety import shield

    policy = net.policy
    out = {"val": score(envs.eval, policy, eval_seeds)}
    if envs.paper_eval is not None:
        out["paper"] = score(envs.paper_eval, policy, paper_seeds)
    if shield_seeds is not None:
        out["shield"] = {"val": score(envs.eval, shield(policy, envs.eval, net.shipped_filter), shield_seeds)}
        if envs.paper_eval is not None:
            out["shield"]["paper"] = score(envs.paper_eval, shield(policy, envs.paper_eval, net.shipped_filter),
                                           paper_seeds)
    return out


def _restore(policy: Any, folder: Path) -> None:
    """The network of a finished round (its weights and normaliser) into ``policy``."""
    from satenv.training import runfolder
    from satenv.training.policy import load

    runfolder.recover_folder(folder)                          # a swap a kill interrupted
    last = load(check_folder(folder, "round folder"), shielded=False)
    policy.actor.load_state_dict(last.actor.state_dict())
    policy.normalizer = last.normalizer


def _save_labels(run_dir: Path, k: int, batch: dict[str, np.ndarray]) -> None:
    from satenv.training.imitation.folder import save_labels

    save_labels(label_path(run_dir, k), batch)


def _all_rows(run_dir: Path, rounds: int) -> dict[str, np.ndarray]:
    """Every row of rounds ``0 .. rounds - 1`` (a row without the ``alone`` flag flew behind the filter)."""
    parts = [read_labels(label_path(run_dir, k), f"the labels of round {k}") for k in range(rounds)]
    keys = set(parts[0]).intersection(*parts)
    return {key: np.concatenate([p[key] for p in parts]) for key in sorted(keys)}


def _save_round(run_dir: Path, k: int, net: setup.Network, history: list[dict[str, Any]]) -> None:
    """Round ``k``'s policy folder swapped in whole, then ``history.json``, then the curve."""
    from satenv.training import runfolder
    from satenv.training.imitation.plot import plot_curve
    from satenv.training.policy import save_artifacts

    staged = runfolder.staging(round_folder(run_dir, k))
    save_artifacts(staged, net.policy, env_meta=net.meta, config={**net.config, "round": k},
                   source=f"{RECIPE} round checkpoint")
    runfolder.replace_folder(staged, round_folder(run_dir, k))
    runfolder.write_json(run_dir / "history.json", history, default=_json_scalar)
    runfolder.save_with(run_dir / "learning_curve.png", lambda tmp: plot_curve(history, tmp))


def _json_scalar(v: Any) -> Any:
    return v.item() if isinstance(v, np.generic) else str(v)


def _report(k: int, h: dict[str, Any]) -> None:
    val = h["val"]
    loss = total_loss(h)
    line = (f"round {k}: labels {h['labels']} loss {loss:.4f} val success {val['success_rate']:.2f} "
            f"coll {val['collision_episodes']} viol {val.get('violation_episodes')}")
    if "shield" in h:
        sv = h["shield"]["val"]
        line += (f" | +filter success {sv['success_rate']:.2f} coll {sv['collision_episodes']} "
                 f"interv/step {sv.get('interventions_per_agent_step') or 0:.4f}")
    print(f"{line} collect {h['collect_s']:.0f}s fit {h['fit_s']:.0f}s", flush=True)


def reference_name(expert: str | None, env_id: str) -> str:
    """The controller ``eval.json``'s ratios are taken against: the expert when it is a baseline,
    else the env's paper controller (``satenv.tasks.CONTROLLERS``)."""
    from satenv.baselines.registry import BASELINES

    return expert if expert in BASELINES else tasks.CONTROLLERS.get(env_id, "zero")


def finish(run_dir: Path, net: setup.Network, history: list[dict[str, Any]], eval_env: Any, *, reference: str,
           baselines: Sequence[str], test_seeds: Sequence[int], baseline_seeds: int, eval_key: dict[str, Any],
           expert: str | None, teacher: str, progress: bool, workers: int) -> Path:
    """``final/``: the last round's network with ``eval.json`` on ``test_seeds`` beside the
    ``reference`` controller and ``baselines`` (on the first ``baseline_seeds`` seeds, 0: all; cached
    under ``eval_key``), swapped in whole; ``teacher`` names what was imitated."""
    from satenv.training import runfolder
    from satenv.training.evaluate import cached_baselines, test_summary
    from satenv.training.policy import save_artifacts

    names = list(dict.fromkeys([reference, *baselines]))
    seeds = test_seeds[:baseline_seeds] if baseline_seeds else test_seeds
    opts = {"progress": progress, "workers": workers}
    found = cached_baselines(run_dir / "baselines_test.json", eval_env, names, seeds, eval_key, **opts)
    summary = test_summary(eval_env, net.policy, found, test_seeds, reference=reference, **opts,
                           labels=int(history[-1]["labels"]), rounds=len(history), expert=expert)
    final = run_dir / "final"
    runfolder.recover_folder(final)
    staged = runfolder.staging(final)
    save_artifacts(staged, net.policy, env_meta={**net.meta, "rounds": len(history)}, config=net.config,
                   evaluation=summary, source=f"imitation of '{teacher}' ({RECIPE}, "
                   f"{len(history)} rounds)")
    if os.path.lexists(run_dir / "learning_curve.png"):
        from satenv.training.imitation.folder import MAX_PICTURE_BYTES
        from satenv.training.trust import read_member

        curve = read_member(run_dir, "learning_curve.png", MAX_PICTURE_BYTES)
        (staged / "learning_curve.png").write_bytes(bytes(curve))
    runfolder.replace_folder(staged, final)
    print(f"final policy after {len(history)} rounds on {len(test_seeds)} held-out seeds:\n{summary['table']}")
    return final
