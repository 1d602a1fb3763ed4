"""Train a shared policy for a satenv scenario with stable-baselines3 (PPO or SAC).

    satenv train --task platoon-pereira2022-random \\
        --algo ppo --budget 2000000 --num-envs 32 --out-dir runs/platoon_ppo
    satenv train --out-dir runs/platoon_ppo --resume [--budget 3000000]
    tensorboard --logdir runs/platoon_ppo/tb

Every agent of every env copy is one row of the SB3 batch (``satenv.training.vec_env.SatVecEnv``,
parameter sharing); timesteps count agent-steps. Read top to bottom:

1. configuration (``satenv.training.config.TrainConfig``; flags given with ``--resume`` override the
   saved ``config.json``, e.g. a larger ``--budget``);
2. seeding: ``torch``/``numpy``/SB3 from ``seed``; the training env copies from ``seed``;
3. environment: ``SatVecEnv`` -> ``VecMonitor`` -> ``VecNormalize``;
4. reference: the scripted baselines on the evaluation seeds (``baselines_eval.json``);
5. model: new, or the last checkpoint (``checkpoints/step_<N>/``) when resuming — the step
   count continues from ``N``;
6. learning with a tqdm bar, TensorBoard logs (``tb/``), periodic evaluation on fixed seeds
   with the PettingZoo env (logged as ``eval/*`` beside ``baseline/<name>/*``; the best model by
   (success rate, -RMSE) is kept in ``best/``), and checkpoints every ``checkpoint_every`` steps;
7. artefacts: ``final/`` (model, normalisation, env.json, config.json, eval.json) with the
   held-out ``test_seeds`` evaluation of the learned policy and the baselines; ``best/`` gets
   its test evaluation too. ``satenv.training.load(folder)`` loads either.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from satenv.training import runfolder
from satenv.training.config import (
    TrainConfig,
    announce,
    parse_args,
    planned_timesteps,
    round_timesteps,
)
from satenv.training.envs import make_env, policy_env_meta
from satenv.training.evaluate import (
    cached_baselines,
    compare,
    evaluate,
    learning_curve,
    test_summary,
)
from satenv.training.policy import (
    ObsNormalizer,
    action_map_from_config,
    features_from_config,
    from_sb3,
    save_artifacts,
)
from satenv.training.runfolder import RunFolderError
from satenv.training.shaping import RewardShaping
from satenv.training.trust import MAX_CHECKPOINT_BYTES, npz_headers, read_json, stored_zip

__all__ = ["main", "train", "latest_checkpoint", "init_policy", "seed_actor"]


# --------------------------------------------------------------------------- helpers
def latest_checkpoint(out_dir: Path) -> tuple[int, Path] | None:
    """``(steps, folder)`` of the newest complete checkpoint, or ``None``
    (:func:`satenv.training.runfolder.latest_checkpoint`)."""
    return runfolder.latest_checkpoint(out_dir, CHECKPOINT_STATE)


def env_meta(cfg: TrainConfig, env: Any) -> dict[str, Any]:
    return policy_env_meta(cfg.env_id, env, cfg.env_kwargs, cfg.resolved_eval_env_kwargs)


def learning_rate(cfg: TrainConfig):
    """The learning rate or schedule (SB3 passes the remaining progress, 1 -> 0)."""
    if cfg.lr_schedule == "linear":
        lr = cfg.lr
        return lambda progress_remaining: lr * max(progress_remaining, 0.05)
    return cfg.lr


def build_model(cfg: TrainConfig, venv, seed=None):
    """The SB3 model of ``cfg``; with ``init_actor``, a PPO policy of the seed's shape (its
    activation for actor and critic, a ``tanh`` after the action head when the seed squashes:
    the Gaussian's mean is then the seed's action), weights still random (:func:`seed_actor`).
    ``seed``: the seed network when the caller has loaded it (:func:`init_policy`), else loaded here."""
    from stable_baselines3 import PPO, SAC

    common = {"seed": cfg.seed, "device": "cpu", "verbose": 0, "learning_rate": learning_rate(cfg),
              "gamma": cfg.gamma, "tensorboard_log": None}
    if cfg.algo == "ppo":
        arch = list(cfg.net_arch)
        policy_kwargs: dict[str, Any] = {"net_arch": {"pi": arch, "vf": arch}, "log_std_init": cfg.log_std_init}
        if seed is None and cfg.init_actor:
            seed = init_policy(cfg)
        spec = seed.actor.spec if seed is not None else None
        if spec is not None:
            from satenv.training.actor import ACTIVATIONS

            policy_kwargs["activation_fn"] = ACTIVATIONS[spec["activation"]]
        model = PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                    gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range, ent_coef=cfg.ent_coef,
                    vf_coef=cfg.vf_coef, max_grad_norm=cfg.max_grad_norm, policy_kwargs=policy_kwargs, **common)
        if spec is not None and spec["squash"]:   # same parameters: the optimiser already holds them
            from torch import nn

            model.policy.action_net = nn.Sequential(model.policy.action_net, nn.Tanh())
        return model
    return SAC("MlpPolicy", venv, buffer_size=cfg.buffer_size, learning_starts=cfg.learning_starts,
               batch_size=cfg.sac_batch_size, train_freq=cfg.train_freq, gradient_steps=cfg.gradient_steps,
               tau=cfg.tau, policy_kwargs={"net_arch": list(cfg.net_arch), "log_std_init": cfg.log_std_init},
               **common)


SEEDED_OBS_COUNT = 1e9
"""How many observations the seed's normaliser statistics count as in ``VecNormalize``'s running
update: the seeded actor keeps seeing its inputs scaled as in its own training (a batch of a
million observations moves the mean by at most 0.1 % of their difference)."""


def init_policy(cfg: TrainConfig):
    """The network of ``cfg.init_actor`` (alone, never its filter), checked against ``cfg``: an
    MLP of hidden sizes ``net_arch``, the same observation features, action map and clip, no
    terminal feedback (SB3 has none). A mismatch is a ``ValueError`` naming the field."""
    from satenv.training.policy import PolicyLoadError, load

    where = f"init_actor {cfg.init_actor!r}"
    try:
        seed = load(cfg.init_actor, shielded=False)
    except PolicyLoadError as err:
        raise ValueError(f"init_actor: {err}") from None
    spec, norm = seed.actor.spec, seed.normalizer
    if spec.get("type") != "mlp":
        raise ValueError(f"{where}: needs an MLP actor, got type {spec.get('type')!r}")
    if tuple(spec["hidden"]) != tuple(cfg.net_arch):
        raise ValueError(f"{where}: hidden layers {spec['hidden']}; "
                         f"give --net-arch {','.join(map(str, spec['hidden']))}"
                         f" (got {','.join(map(str, cfg.net_arch))})")
    if seed.terminal is not None:
        raise ValueError(f"{where}: has terminal feedback ({seed.terminal}); SB3 PPO trains the network alone")
    features = features_from_config(cfg.to_json())
    if seed.features != features:
        raise ValueError(f"{where}: observation features {seed.features}; the run's are {features} "
                         "(--obs-symlog-scale, --obs-symlog-dims, --obs-drop-dims)")
    if seed.action_map != action_map_from_config(cfg.to_json()):
        raise ValueError(f"{where}: action map {seed.action_map}; give the same --action-power")
    if (norm.mean is not None) != cfg.norm_obs or (norm.mean is not None and norm.clip_obs != cfg.clip_obs):
        kind = "clip " + str(norm.clip_obs) if norm.mean is not None else "none"
        raise ValueError(f"{where}: observation normaliser {kind}"
                         f"; the run has --norm-obs {cfg.norm_obs} --clip-obs {cfg.clip_obs}")
    return seed


def seed_actor(model, venv, seed, observations: np.ndarray, maps: dict[str, Any]) -> float:
    """Copy the network ``seed`` (:func:`init_policy`) into the PPO actor of :func:`build_model`
    and its normaliser statistics into ``venv`` (counted as :data:`SEEDED_OBS_COUNT`), then check
    that the exported policy's actions on the raw per-agent ``observations`` ``(n, obs_dim)`` are
    the seed's; returns the largest difference (``ValueError`` above ``1e-5``). The critic and
    the action standard deviation (``log_std_init``) stay as built."""
    from torch import nn

    policy = model.policy
    head = policy.action_net[0] if isinstance(policy.action_net, nn.Sequential) else policy.action_net
    body = [m for m in policy.mlp_extractor.policy_net if isinstance(m, nn.Linear)]
    layers = seed.actor.linear_layers()
    if len(layers) != len(body) + 1:
        raise ValueError(f"init_actor: {len(layers)} layers, the PPO actor has {len(body) + 1}")
    import torch

    with torch.no_grad():
        for dst, src in zip([*body, head], layers, strict=True):
            if dst.weight.shape != src.weight.shape:
                raise ValueError(f"init_actor: layer {tuple(src.weight.shape)} does not fit {tuple(dst.weight.shape)}")
            dst.weight.copy_(src.weight)
            dst.bias.copy_(src.bias)
    norm = seed.normalizer
    if norm.mean is not None:
        if norm.mean.shape != venv.obs_rms.mean.shape or norm.epsilon != venv.epsilon:
            raise ValueError(f"init_actor: normaliser of shape {norm.mean.shape} (epsilon {norm.epsilon}); the "
                             f"run's is {venv.obs_rms.mean.shape} (epsilon {venv.epsilon})")
        venv.obs_rms.mean, venv.obs_rms.var = norm.mean.copy(), norm.var.copy()
        venv.obs_rms.count = SEEDED_OBS_COUNT
    got = export_policy(model, venv, {"observation_shape": list(seed.obs_shape)}, maps).predict(observations)
    diff = float(np.abs(got - seed.predict(observations)).max())
    if not diff <= 1e-5:
        raise ValueError(f"init_actor: the seeded PPO actor does not reproduce the seed's actions "
                         f"(max difference {diff:.3g})")
    return diff


def _score(agg: dict[str, Any]) -> tuple[float, float]:
    return (agg["success_rate"], -agg["rmse"])


# --------------------------------------------------------------------------- callback
def make_callback(cfg: TrainConfig, out: Path, venv, eval_env, baseline_eval: dict[str, Any],
                  meta: dict[str, Any], history: list[dict[str, Any]], maps: dict[str, Any] | None = None,
                  total: int | None = None):
    """One SB3 callback doing the progress bar, periodic evaluation and checkpoints."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TrainingCallback(BaseCallback):
        def _on_training_start(self) -> None:
            n = self.model.num_timesteps
            self.next_eval = (n // cfg.eval_every + 1) * cfg.eval_every if cfg.eval_every else None
            self.next_ckpt = (n // cfg.checkpoint_every + 1) * cfg.checkpoint_every if cfg.checkpoint_every else None
            self.best = max((_score(h["aggregate"]) for h in history), default=None)
            self.bar = tqdm(total=total or cfg.total_timesteps, initial=n, unit="step", unit_scale=True,
                            disable=not cfg.progress, dynamic_ncols=True, file=sys.stderr)
            self.last_n = n
            for name, res in baseline_eval.items():
                for key in ("success_rate", "rmse", "delta_v", "collision_episodes"):
                    self.logger.record(f"baseline/{name}/{key}", res["aggregate"][key])

        def _on_step(self) -> bool:
            n = self.model.num_timesteps
            self.bar.update(n - self.last_n)
            self.last_n = n
            if self.next_eval is not None and n >= self.next_eval:
                self.next_eval += cfg.eval_every
                self.evaluate_now()
            return True

        def _on_rollout_start(self) -> None:
            # checkpoints between rollouts, after the update of the last one: a checkpoint at step
            # N holds every update of the first N steps (one taken inside a rollout would hold the
            # weights before its update, and resuming from it would skip that update)
            n = self.model.num_timesteps
            if self.next_ckpt is not None and n >= self.next_ckpt:
                self.next_ckpt = (n // cfg.checkpoint_every + 1) * cfg.checkpoint_every
                save_checkpoint(self.model, venv, out, n)

        def evaluate_now(self) -> None:
            n = self.model.num_timesteps
            policy = export_policy(self.model, venv, meta, maps)
            res = evaluate(eval_env, policy, cfg.eval_seeds, desc=f"evaluation at {n} steps",
                           progress=cfg.progress, workers=cfg.workers)
            agg = res["aggregate"]
            for key in ("success_rate", "rmse", "delta_v", "final_error_m", "collision_episodes",
                        "violation_episodes", "min_separation_m", "terminated"):
                if agg[key] is not None:
                    self.logger.record(f"eval/{key}", agg[key])
            ref = _reference(cfg)
            ratios = compare({"learned": res, **baseline_eval}, reference=ref)
            for key in ("rmse_ratio", "delta_v_ratio"):
                if ratios and ratios["matched"].get(key) is not None:
                    self.logger.record(f"eval/{key}_vs_{ref.upper()}", ratios["matched"][key])
            self.logger.dump(n)
            history.append({"step": n, "aggregate": agg, f"vs_{ref.upper()}": ratios})
            runfolder.write_json(out / "eval_history.json", history)
            self.bar.set_postfix(success=f"{agg['success_rate']:.2f}", rmse=f"{agg['rmse']:.3g}",
                                 dv=f"{agg['delta_v']:.3g}", refresh=False)
            if self.best is None or _score(agg) > self.best:
                self.best = _score(agg)
                staged = runfolder.staging(out / "best")          # whole or not at all
                save_artifacts(staged, policy, env_meta={**meta, "step": n}, config=cfg.to_json(),
                               evaluation={"eval_seeds": list(cfg.eval_seeds), "learned": agg},
                               source=f"stable-baselines3 {cfg.algo.upper()}")
                runfolder.replace_folder(staged, out / "best")

        def _on_training_end(self) -> None:
            self.bar.close()

    return TrainingCallback()


def export_policy(model, venv, meta: dict[str, Any], maps: dict[str, Any] | None = None):
    """The current SB3 model as the :class:`satenv.training.policy.LearnedPolicy` that gets saved."""
    return from_sb3(model, ObsNormalizer.from_vecnormalize(venv), obs_shape=tuple(meta["observation_shape"]),
                    meta=meta, **(maps or {}))


CHECKPOINT_STATE = "sb3_state.pt"
"""Checkpoint files (no pickle): ``sb3_state.pt`` (the model's state dicts and tensors, read with
``torch.load(weights_only=True)``), ``vecnormalize.json`` and, for SAC, ``replay_buffer.npz``."""
_BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def save_checkpoint(model, venv, out: Path, steps: int) -> Path:
    import torch
    from stable_baselines3.common.save_util import recursive_getattr

    folder = out / "checkpoints" / f"step_{steps}"
    tmp = runfolder.staging(folder)
    state_dicts, tensors = model._get_torch_save_params()
    state = {"num_timesteps": int(model.num_timesteps), "n_updates": int(getattr(model, "_n_updates", 0)),
             "state_dicts": {name: recursive_getattr(model, name).state_dict() for name in state_dicts},
             "tensors": {name: recursive_getattr(model, name).detach().cpu() for name in tensors}}
    torch.save(state, tmp / CHECKPOINT_STATE)
    (tmp / "vecnormalize.json").write_text(json.dumps(vecnormalize_state(venv)) + "\n")
    buffer = getattr(model, "replay_buffer", None)
    if buffer is not None:
        arrays = {k: getattr(buffer, k) for k in _BUFFER_ARRAYS if getattr(buffer, k, None) is not None}
        np.savez(tmp / "replay_buffer.npz", pos=np.array(buffer.pos), full=np.array(buffer.full), **arrays)
    if getattr(model, "_last_obs", None) is not None:
        np.savez(tmp / ENV_STATE, **env_state(model, venv))
    return runfolder.replace_folder(tmp, folder)  # a checkpoint folder is complete or absent


def load_checkpoint(model, folder: Path) -> None:
    """Restore :func:`save_checkpoint`'s model state into a freshly built ``model`` (no pickle); a
    malformed checkpoint is a :class:`satenv.training.runfolder.RunFolderError` naming the folder."""
    import pickle

    try:
        _load_checkpoint(model, folder)
    except RunFolderError:
        raise
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, IndexError, EOFError, OSError,
            pickle.UnpicklingError) as err:
        raise RunFolderError(f"--resume: the checkpoint {folder} is malformed ({type(err).__name__}: "
                             f"{str(err).splitlines()[0][:120] if str(err) else ''}); expected the files of "
                             f"save_checkpoint ({CHECKPOINT_STATE}, vecnormalize.json) for this config") from None


CHECKPOINT_STATE_SLACK = 2**20
"""Bytes of ``sb3_state.pt`` beyond its tensors (the pickled structure, zip headers)."""
ADAM_COPIES = 3
"""Tensors per parameter in ``sb3_state.pt``: the parameter and Adam's two moment estimates."""


def checkpoint_state_cap(model) -> int:
    """The largest ``sb3_state.pt`` the freshly built ``model`` can have written: every tensor of
    its saved state dicts :data:`ADAM_COPIES` times, plus :data:`CHECKPOINT_STATE_SLACK` (the
    policy folder's rule: the size the architecture allows, known before reading)."""
    from stable_baselines3.common.save_util import recursive_getattr

    names, tensors = model._get_torch_save_params()
    params = sum(t.numel() * t.element_size() for name in names
                 for t in recursive_getattr(model, name).state_dict().values() if hasattr(t, "numel"))
    params += sum(recursive_getattr(model, name).numel() * 8 for name in tensors)
    return ADAM_COPIES * params + CHECKPOINT_STATE_SLACK


def _load_checkpoint(model, folder: Path) -> None:
    import torch
    from stable_baselines3.common.save_util import recursive_getattr

    state = torch.load(stored_zip(folder, CHECKPOINT_STATE, checkpoint_state_cap(model)), map_location="cpu",
                       weights_only=True)  # no link, nothing compressed, at most the model's own size
    model.set_parameters(state["state_dicts"], exact_match=True, device="cpu")
    for name, value in state["tensors"].items():
        recursive_getattr(model, name).data.copy_(value)
    model.num_timesteps = int(state["num_timesteps"])
    model._n_updates = int(state["n_updates"])
    buffer_path = folder / "replay_buffer.npz"
    if buffer_path.is_file() and getattr(model, "replay_buffer", None) is not None:
        buffer = model.replay_buffer
        path = stored_zip(folder, "replay_buffer.npz", MAX_CHECKPOINT_BYTES)
        for k, (shape, dtype) in npz_headers(path).items():   # sizes from the headers first
            want = getattr(buffer, k, None) if k in _BUFFER_ARRAYS else np.empty(())
            if want is None or tuple(shape) != want.shape or np.dtype(dtype).itemsize > want.dtype.itemsize:
                raise RunFolderError(f"--resume: {path}: array {k!r:.40} does not fit the replay buffer "
                                     f"(expected {_BUFFER_ARRAYS} of the buffer's shapes, pos and full scalars)")
        with np.load(path, allow_pickle=False) as d:
            for k in _BUFFER_ARRAYS:
                if k in d:
                    getattr(buffer, k)[...] = d[k]
            buffer.pos, buffer.full = int(d["pos"]), bool(d["full"])


ENV_STATE = "env_state.npz"
"""The checkpoint's record of everything the next rollout reads besides the weights
(:func:`env_state`): with it a resumed run continues the uninterrupted one bit for bit."""


def env_state(model, venv) -> dict[str, np.ndarray]:
    """The episodes in flight (the batched core, its generators and the training reward's memory:
    :meth:`SatVecEnv.get_state`), the wrappers' running sums, the model's last observation and the
    torch / numpy random states, as arrays (saved with ``np.savez``: no pickle)."""
    import torch

    monitor, sat = venv.venv, venv.venv.venv
    state = {f"env.{k}": v for k, v in sat.get_state().items()}
    rng = np.random.get_state()  # noqa: NPY002 - SB3 draws its minibatches from the legacy global state
    state.update({"monitor.episode_returns": monitor.episode_returns,
                  "monitor.episode_lengths": monitor.episode_lengths,
                  "normalize.returns": np.asarray(venv.returns), "last_obs": np.asarray(model._last_obs),
                  "last_episode_starts": np.asarray(model._last_episode_starts),
                  "torch_rng": torch.get_rng_state().numpy(), "numpy_rng.keys": rng[1],
                  "numpy_rng.pos": np.array(rng[2]), "numpy_rng.has_gauss": np.array(rng[3]),
                  "numpy_rng.cached_gaussian": np.array(rng[4])})
    if getattr(model, "_last_original_obs", None) is not None:
        state["last_original_obs"] = np.asarray(model._last_original_obs)
    space_rng = getattr(model.action_space, "np_random", None)
    if isinstance(space_rng, np.random.Generator):       # SAC samples it before learning starts
        state["action_space_rng"] = np.array(json.dumps(space_rng.bit_generator.state))
    return state


def restore_env_state(model, venv, folder: Path) -> bool:
    """Put :func:`env_state` of a checkpoint back (just before ``learn``); ``False`` for a
    checkpoint without it (written before it existed: the env then starts new episodes). A
    malformed one is a :class:`satenv.training.runfolder.RunFolderError`."""
    import torch

    if not (folder / ENV_STATE).is_file():
        return False
    try:
        with np.load(stored_zip(folder, ENV_STATE, MAX_CHECKPOINT_BYTES), allow_pickle=False) as d:
            data = {k: d[k] for k in d.files}
        stats = vecnormalize_state(venv)
        venv.reset()                          # every wrapper's bookkeeping exists, then is overwritten
        restore_vecnormalize(venv, stats)
        monitor, sat = venv.venv, venv.venv.venv
        sat.set_state({k[len("env."):]: v for k, v in data.items() if k.startswith("env.")})
        monitor.episode_returns = data["monitor.episode_returns"].copy()
        monitor.episode_lengths = data["monitor.episode_lengths"].copy()
        venv.returns = data["normalize.returns"].copy()
        model._last_obs = data["last_obs"].copy()
        model._last_episode_starts = data["last_episode_starts"].copy()
        if "last_original_obs" in data:
            model._last_original_obs = data["last_original_obs"].copy()
        if "action_space_rng" in data:
            model.action_space.np_random.bit_generator.state = json.loads(str(data["action_space_rng"]))
        np.random.set_state(("MT19937", data["numpy_rng.keys"], int(data["numpy_rng.pos"]),  # noqa: NPY002
                             int(data["numpy_rng.has_gauss"]), float(data["numpy_rng.cached_gaussian"])))
        torch.set_rng_state(torch.from_numpy(data["torch_rng"].copy()))
    except RunFolderError:
        raise
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError, OSError) as err:
        raise RunFolderError(f"--resume: {folder / ENV_STATE} is malformed ({type(err).__name__}: "
                             f"{str(err).splitlines()[0][:120] if str(err) else ''})") from None
    return True


def vecnormalize_state(venv) -> dict[str, Any]:
    """The running statistics of a ``VecNormalize`` as JSON data."""
    def rms(r):
        return {"mean": np.asarray(r.mean).tolist(), "var": np.asarray(r.var).tolist(), "count": float(r.count)}

    return {"obs_rms": rms(venv.obs_rms), "ret_rms": rms(venv.ret_rms)}


def restore_vecnormalize(venv, data: dict[str, Any]) -> None:
    """Load :func:`vecnormalize_state` data into ``venv`` (shapes checked; a malformed entry is a
    :class:`satenv.training.runfolder.RunFolderError`)."""
    for key in ("obs_rms", "ret_rms"):
        r = getattr(venv, key)
        try:
            mean = np.asarray(data[key]["mean"], dtype=np.float64)
            var = np.asarray(data[key]["var"], dtype=np.float64)
            count = float(data[key]["count"])
        except (KeyError, TypeError, ValueError) as err:
            raise RunFolderError(f"vecnormalize.json: {key} must hold numbers 'mean', 'var' and 'count' "
                                 f"({type(err).__name__}: {str(err)[:80]})") from None
        if mean.shape != np.shape(r.mean) or var.shape != np.shape(r.var):
            raise ValueError(f"vecnormalize.json: {key} has shape {mean.shape}, expected {np.shape(r.mean)}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0) and count > 0):
            raise RunFolderError(f"vecnormalize.json: {key} must be finite with var >= 0 and count > 0")
        r.mean, r.var, r.count = mean, var, count


# --------------------------------------------------------------------------- training
def train(cfg: TrainConfig, resume: bool = False) -> Path:
    """Run (or resume) training; returns the ``final/`` artefact folder."""
    import torch
    from stable_baselines3.common.utils import set_random_seed
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from satenv.training.vec_env import SatVecEnv

    out = Path(cfg.out_dir)
    ckpt = runfolder.resume_checkpoint(out, resume, CHECKPOINT_STATE)
    resume = ckpt is not None
    out.mkdir(parents=True, exist_ok=True)
    for name in ("best", "final"):   # a folder swap a kill interrupted: the old content or the new, whole
        runfolder.recover_folder(out / name)

    # 2. seeding
    torch.set_num_threads(cfg.torch_threads)
    start_steps = ckpt[0] if ckpt else 0
    set_random_seed(cfg.seed + start_steps)

    # 3. environment (training) and evaluation env
    env = make_env(cfg.env_id, **cfg.env_kwargs)
    eval_env = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
    meta = env_meta(cfg, env)
    shaping = RewardShaping.from_dict(cfg.reward_shaping)
    features = features_from_config(cfg.to_json())
    action_map = action_map_from_config(cfg.to_json())
    vec = VecMonitor(SatVecEnv(env, cfg.num_envs, seed=cfg.seed + start_steps,
                               reward_fn=shaping if shaping.active else None, obs_fn=features,
                               action_fn=action_map))
    venv = VecNormalize(vec, norm_obs=cfg.norm_obs, norm_reward=cfg.norm_reward, clip_obs=cfg.clip_obs,
                        gamma=cfg.gamma)
    if ckpt:
        try:
            restore_vecnormalize(venv, read_json(ckpt[1], "vecnormalize.json"))
        except RunFolderError as err:
            raise RunFolderError(f"--resume: {ckpt[1]}/{err}") from None

    # 4. scripted baselines on the evaluation seeds (cached; only when there are periodic evaluations)
    periodic = 0 < cfg.eval_every <= max(cfg.total_timesteps, planned_timesteps(cfg, len(env.possible_agents)))
    baseline_eval = _cached_baselines(out / "baselines_eval.json", eval_env, cfg, cfg.eval_seeds) if periodic else {}

    # 5. model
    seed = init_policy(cfg) if cfg.init_actor else None
    model = build_model(cfg, venv, seed)
    if ckpt:
        load_checkpoint(model, ckpt[1])
    elif seed is not None:
        probe = make_env(cfg.env_id, **cfg.env_kwargs)   # start observations to check the seeding on
        starts = np.concatenate([np.stack(list(probe.reset(seed=cfg.seed + k)[0].values())) for k in range(4)])
        diff = seed_actor(model, venv, seed, starts, {"features": features, "action_map": action_map})
        print(f"actor seeded from {cfg.init_actor} (its actions reproduced to {diff:.1e})", file=sys.stderr)
    model.tensorboard_log = str(out / "tb")
    history_path = out / "eval_history.json"
    history = _read_history(history_path, start_steps) if (resume and history_path.is_file()) else []

    # 6. learn (the budget actually run is the one saved)
    target = planned_timesteps(cfg, len(env.possible_agents))
    if target != cfg.total_timesteps:
        print(f"total_timesteps {cfg.total_timesteps} -> {target}: whole collection rounds of "
              f"{round_timesteps(cfg, len(env.possible_agents))} agent-steps", file=sys.stderr)
        cfg = cfg.replace(total_timesteps=target)
    announce(cfg, f"{cfg.algo.upper()}, {target} agent-steps ({cfg.num_envs} copies x {len(env.possible_agents)} "
             f"agents per env step)" + (f", {model.num_timesteps} already done" if ckpt else ""),
             periodic=(f"an evaluation on {len(cfg.eval_seeds)} seeds every {cfg.eval_every} agent-steps"
                       if cfg.eval_every else "no periodic evaluation"))
    runfolder.write_json(out / "config.json", cfg.to_json(), indent=2)
    remaining = target - model.num_timesteps
    t0 = time.perf_counter()
    if remaining > 0:
        callback = make_callback(cfg, out, venv, eval_env, baseline_eval, meta, history,
                                 {"features": features, "action_map": action_map}, total=target)
        if ckpt:   # last, so that nothing draws from the random states between here and learn
            restore_env_state(model, venv, ckpt[1])
        model.learn(total_timesteps=remaining, callback=callback, reset_num_timesteps=not ckpt,
                    tb_log_name="run", log_interval=1)
        if cfg.checkpoint_every:
            save_checkpoint(model, venv, out, model.num_timesteps)
    wall = time.perf_counter() - t0
    ref = _reference(cfg) if _reference(cfg) in baseline_eval else next(iter(baseline_eval), None)
    if history:
        runfolder.save_with(out / "learning_curve.png", lambda tmp: learning_curve(
            history, baseline_eval.get(ref), ref or "", tmp, x_key="step", x_label="agent-steps"))

    # 7. artefacts with the held-out evaluation
    test_baselines = _cached_baselines(out / "baselines_test.json", eval_env, cfg, cfg.test_seeds)
    final_policy = export_policy(model, venv, meta, {"features": features, "action_map": action_map})
    summary = _summary(cfg, eval_env, final_policy, test_baselines, model.num_timesteps, wall)
    staged = save_artifacts(runfolder.staging(out / "final"), final_policy,
                            env_meta={**meta, "step": model.num_timesteps},
                            config=cfg.to_json(), evaluation=summary, source=f"stable-baselines3 {cfg.algo.upper()}")
    if (out / "learning_curve.png").is_file():
        shutil.copyfile(out / "learning_curve.png", staged / "learning_curve.png")
    final = runfolder.replace_folder(staged, out / "final")
    print(f"final policy ({model.num_timesteps} steps, {wall / 60:.1f} min this session) on "
          f"{len(cfg.test_seeds)} held-out seeds:\n{summary['table']}")
    if (out / "best" / "manifest.json").is_file():
        from satenv.training.policy import load

        best = load(out / "best")
        best_summary = _summary(cfg, eval_env, best, test_baselines, best.meta.get("step"), wall)
        runfolder.write_json(out / "best" / "eval.json", best_summary, indent=2)
        print(f"best-on-eval-seeds policy (step {best.meta.get('step')}):\n{best_summary['table']}")
    venv.close()
    return final


def _read_history(path: Path, upto: int) -> list[dict[str, Any]]:
    """The evaluations of ``eval_history.json`` up to step ``upto`` (the checkpoint resumed from;
    later ones are run again); a malformed file is a :class:`satenv.training.runfolder.RunFolderError`."""
    history = runfolder.read_json(path, "the list of periodic evaluations ({'step': ..., 'aggregate': ...})")
    if not isinstance(history, list) or any(not isinstance(h, dict) or not isinstance(h.get("step"), int)
                                            for h in history):
        raise RunFolderError(f"{path}: expected a list of evaluations with an int 'step', got {str(history)[:80]}")
    return [h for h in history if h["step"] <= upto]


def _summary(cfg: TrainConfig, eval_env, policy, baselines: dict[str, Any], steps, wall: float) -> dict[str, Any]:
    return test_summary(eval_env, policy, baselines, cfg.test_seeds, reference=_reference(cfg), steps=steps,
                        train_wall_s_this_session=round(wall, 1), progress=cfg.progress, workers=cfg.workers)


def _reference(cfg: TrainConfig) -> str:
    """The comparator of the ratios: the env's paper controller (``satenv.tasks.CONTROLLERS``)."""
    from satenv.tasks import CONTROLLERS

    return CONTROLLERS.get(cfg.env_id, "dmpc")


def _cached_baselines(path: Path, eval_env, cfg: TrainConfig, seeds) -> dict[str, Any]:
    return cached_baselines(path, eval_env, cfg.eval_baselines, seeds,
                            {"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs},
                            progress=cfg.progress, workers=cfg.workers)


# --------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> Path:
    try:
        cfg, opts = parse_args(argv, resume=True, prog="satenv train",
                               description=__doc__.split("\n\n")[0])
        return train(cfg, resume=opts.resume)
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None


if __name__ == "__main__":
    warnings.filterwarnings("ignore", category=DeprecationWarning)
    np.set_printoptions(precision=4, suppress=True)
    main()
