"""Demonstration datasets in Minari: the controller's episodes on each paper system's training task.

    satenv datasets write --systems platoon-pereira2023 --episodes 50
    satenv datasets read  --systems platoon-pereira2023
    satenv datasets write --systems all --root /data/minari   # every system
    satenv datasets write --systems cluster-li2022 --workers 2  # episodes in parallel

Each dataset (id ``satenv/<system>/<controller>-v0``, e.g. ``satenv/platoon-pereira2023/dmpc-v0``)
holds the system controller's episodes (:data:`satenv.tasks.CONTROLLERS`) on the first
``--episodes`` **train** seeds of the system's training task (:func:`satenv.tasks.training_task`),
recorded through the centralised Gymnasium view ``satenv/<Env>-v0`` (:class:`satenv.gym_env.CentralisedEnv`)
and written by Minari (``minari.create_dataset_from_buffers``, the storage of its ``DataCollector``).
Datasets live in Minari's folder (``MINARI_DATASETS_PATH``, default ``~/.minari/datasets``; ``--root``
sets it), never in git: this command regenerates them.

**Layout of the multi-agent data** (also in each dataset's description, the dataset card):

* ``observations[t]``: every agent's observation concatenated in ``possible_agents`` order
  (``M x obs_dim``), ``actions[t]``: every agent's normalised action concatenated the same way
  (``M x act_dim``, in ``[-1, 1]``);
* ``rewards[t]``: the team sum of the agents' rewards; ``terminations``/``truncations``: the team's;
* ``infos``: per agent (arrays of length ``M``, agent order) the safety fields ``collision``,
  ``violations``, ``cost``, ``min_separation`` and ``delta_v``; ``tracking_error`` ``(M, d)``;
  and ``state``: the env's full state (``env.state()``), from which an episode replays exactly
  (:func:`replay`).

The episode's seed is Minari's episode ``seed``: ``env.reset(seed=seed)`` and the recorded actions
reproduce the recorded observations and states (:func:`replay`, ``tests/test_datasets.py``).

**A controller that also acts inside the env.** The cluster's tube-RDMPC registers its tube
controller κ (li2022 eq. 13) with ``env.set_inner_loop``: the env applies ``u~ + κ(x)`` at every
physics step (0.25 s), κ computed from the true state. The recorded action is the controller's
decision-rate command ``u~`` (what the env's ``step`` takes); κ is not in it, and the bare env flies
the recorded actions to other states (cluster episode 0: 0.024 apart in the state after the first
step, and the env ends before the actions do). :func:`replay` therefore builds the controller and
resets it after the env, as :func:`record_episode` does, so whatever it installs in the env is there
again (its ``act`` is never called: the actions are the recorded ones); the card says when a
controller has an inner loop. ``infos["state"]`` is the flown trajectory.

Writing is resumable: each recorded episode is kept as plain arrays (``.npz``, loaded without
pickle) in ``--cache`` (default ``~/.cache/satenv/episodes``) until the dataset is written, so an
interrupted ``write`` records only the episodes it has not got; ``--workers`` records episodes in
parallel (the scoreboard's backends). An episode taken from the cache is replayed first (cheap next
to recording) and recorded again when it does not replay exactly: the env may have changed since it
was recorded. (A change of the controller alone, with the env unchanged, is not detected: its
actions still replay.)

A dataset appears whole or not at all: Minari writes it under a hidden staging root beside the
datasets (:data:`STAGING`), and the finished folder is swapped in
(:func:`satenv.training.runfolder.replace_folder`); a kill leaves the previous dataset or the new one.
A dataset folder without a readable ``metadata.json`` (a kill inside an earlier writer) is named on
stderr and removed before writing (:func:`remove_incomplete`).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from satenv import tasks
from satenv.training import runfolder, trust

__all__ = ["CACHE", "INFO_FIELDS", "SafetyInfos", "dataset_id", "drop_stale", "episode_seed", "inner_loop_name",
           "load_episode", "make_controller", "make_env", "read", "record_episode", "replay", "replays_exactly",
           "save_episode", "write"]

INFO_FIELDS = {"collision": bool, "violations": np.int64, "cost": np.float64, "min_separation": np.float64,
               "delta_v": np.float64}
"""Per-agent safety fields kept in ``infos`` (and their dtype)."""
MANIFEST = Path(__file__).resolve().parent / "datasets.json"
"""What was generated (id, task, seeds, size, wall time; committed, the datasets are not): the docs
page's dataset table."""
USER_MANIFEST = Path("results") / "datasets" / "manifest.json"
"""Where ``satenv datasets write`` records what it wrote unless told otherwise (a user folder: the
packaged :data:`MANIFEST` changes only with ``--update-published``)."""
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "satenv" / "episodes"
"""Where recorded episodes wait until their dataset is written (one ``.npz`` per seed)."""
MAX_EPISODE_BYTES = 2**30
"""Cap on one cached episode file (``.npz``): 1 GiB."""
BUFFER_FIELDS = ("observations", "actions", "rewards", "terminations", "truncations")
STAGING = ".satenv-staging"
"""Hidden folder under Minari's root where a dataset is written before it is swapped in (Minari's
listing skips hidden folders)."""
GYM_ID = {"platoon_v0": "satenv/Platoon-v0", "cluster_v0": "satenv/Cluster-v0",
          "servicing_v0": "satenv/Servicing-v0", "formation_v0": "satenv/Formation-v0"}


class DatasetError(ValueError):
    """A bad dataset request (names the field, the value and what is expected)."""


class SafetyInfos(gym.Wrapper):
    """The centralised view with fixed-layout infos (module docstring): what Minari stores."""

    def _infos(self, info: dict[str, Any]) -> dict[str, Any]:
        pz = self.env.unwrapped.env
        per = [info["agents"][a] for a in pz.possible_agents]
        out = {k: np.asarray([p[k] for p in per], dtype=t) for k, t in INFO_FIELDS.items()}
        out["tracking_error"] = np.asarray([p["tracking_error"] for p in per], dtype=np.float64)
        out["state"] = np.asarray(pz.state(), dtype=np.float64)
        return out

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        return obs, self._infos(info)

    def step(self, action: Any):
        obs, reward, term, trunc, info = self.env.step(action)
        return obs, reward, term, trunc, self._infos(info)


def dataset_id(system: str) -> str:
    """``satenv/<system>/<controller>-v0``."""
    return f"satenv/{system}/{tasks.system(system).controller.replace('_', '-')}-v0"


def make_env(system: str, **overrides: Any) -> gym.Env:
    """The training task of ``system`` as its centralised Gymnasium view with :class:`SafetyInfos`
    (``overrides`` replace env keywords of the task, e.g. ``max_steps`` for a short episode)."""
    import satenv  # noqa: F401  (registers the gymnasium ids)

    task = tasks.training_task(system)
    return SafetyInfos(gym.make(GYM_ID[task.env_id], **{**dict(task.env_kwargs), **overrides}))


def make_controller(system: str, env: gym.Env) -> Any:
    """The system's controller (:data:`satenv.tasks.CONTROLLERS`) on ``env`` (:func:`make_env`)."""
    from satenv import baselines
    return baselines.make(tasks.system(system).controller, env.unwrapped.env)


def _inner_loop(env: gym.Env) -> Any:
    """The physics-rate hook a controller installed in ``env`` (``None`` for none or an env without hooks)."""
    return getattr(env.unwrapped.env, "inner_loop", None)


def _safety_counts(buffers: list[Any]) -> dict[str, int]:
    """Episodes with any collision / any hard-bound violation of any agent."""
    return {"collision_episodes": int(sum(bool(np.any(b.infos["collision"])) for b in buffers)),
            "violation_episodes": int(sum(bool(np.any(b.infos["violations"])) for b in buffers))}


def _card(system: str, seeds: list[int], steps: int, inner_loop: str | None = None,
          counts: dict[str, int] | None = None) -> str:
    sysdef, task = tasks.system(system), tasks.training_task(system)
    env = task.make_env()
    m = len(env.possible_agents)
    o, a = env.observation_space(env.possible_agents[0]).shape[0], env.action_space(env.possible_agents[0]).shape[0]
    hook = ("" if inner_loop is None else
            f"The controller also acts inside the env: it registers {inner_loop} with env.set_inner_loop, "
            f"which adds its correction to the action at every physics step from the true state; the "
            f"recorded actions are the controller's decision-rate commands without it, so a replay needs the "
            f"controller's inner loop attached (satenv.bench.learning.datasets.replay does), and infos state is "
            f"the flown trajectory. ")
    safety = ("" if counts is None else
              f"Safety: {counts['collision_episodes']} of the {len(seeds)} episodes hold a collision and "
              f"{counts['violation_episodes']} a hard-bound violation (infos collision, violations): "
              + ("the data is not collision-free; filter those episodes for safe demonstrations. "
                 if counts["collision_episodes"] else "the data is collision-free. "))
    return (f"satenv {sysdef.label}: the controller {sysdef.controller!r} (satenv.baselines.make) flying the training "
            f"task {task.name!r} ({task.description}) on train seeds {tasks.show_seeds(seeds)} "
            f"({len(seeds)} episodes, {steps} steps, {steps * m} agent-steps). Env: {GYM_ID[task.env_id]} with "
            f"kwargs {dict(task.env_kwargs)} (satenv.gym_env.CentralisedEnv). Layout: {m} agents in "
            f"possible_agents order {list(env.possible_agents)}; observation = the {m} agents' observations "
            f"concatenated ({m} x {o}); action = their normalised actions concatenated ({m} x {a}, in [-1, 1]); "
            f"reward = team sum; infos: per agent {sorted(INFO_FIELDS)} (length {m}), tracking_error ({m}, d), "
            f"state = env.state() (replay: reset(seed=episode seed) then the actions). {safety}{hook}"
            f"Written by python -m satenv.bench.learning.datasets.")


def record_episode(env: gym.Env, controller: Any, seed: int) -> Any:
    """One controller episode on ``env`` (:func:`make_env`) as a Minari ``EpisodeBuffer``."""
    from minari.data_collector.episode_buffer import EpisodeBuffer

    pz = env.unwrapped.env
    m, act_dim = len(pz.possible_agents), env.action_space.shape[0] // len(pz.possible_agents)
    obs, info = env.reset(seed=int(seed))
    controller.reset(seed=int(seed))
    data: dict[str, list] = {"observations": [obs], "actions": [], "rewards": [], "terminations": [], "truncations": []}
    infos = {k: [v] for k, v in info.items()}
    done = False
    while not done:
        split = obs.reshape(m, -1)
        acts = controller.act({a: split[i] for i, a in enumerate(pz.possible_agents)})
        action = np.clip(np.concatenate([np.asarray(acts[a], dtype=np.float32).reshape(act_dim)
                                         for a in pz.possible_agents]), -1, 1)
        obs, reward, term, trunc, info = env.step(action)
        for key, value in (("observations", obs), ("actions", action), ("rewards", reward),
                           ("terminations", term), ("truncations", trunc)):
            data[key].append(value)
        for k, v in info.items():
            infos[k].append(v)
        done = term or trunc
    return EpisodeBuffer(seed=int(seed), infos=infos, **data)


def save_episode(buffer: Any, path: Path) -> Path:
    """An ``EpisodeBuffer`` as plain arrays in ``path`` (``.npz``; :func:`satenv.training.runfolder.save_with`)."""
    arrays = {k: np.asarray(getattr(buffer, k)) for k in BUFFER_FIELDS}
    arrays.update({f"info.{k}": np.asarray(v) for k, v in buffer.infos.items()})
    arrays["seed"] = np.asarray(buffer.seed)
    return runfolder.save_with(path, lambda tmp: np.savez(tmp, **arrays))


def load_episode(path: Path) -> Any:
    """The ``EpisodeBuffer`` :func:`save_episode` wrote (no pickle)."""
    from minari.data_collector.episode_buffer import EpisodeBuffer

    trust.stored_zip(path.parent, path.name, MAX_EPISODE_BYTES)   # no link, capped, nothing inflates
    with np.load(path, allow_pickle=False) as z:
        data = {k: list(z[k]) for k in BUFFER_FIELDS}
        infos = {k[5:]: list(z[k]) for k in z.files if k.startswith("info.")}
        return EpisodeBuffer(seed=int(z["seed"]), infos=infos, **data)


def _episode_path(cache: Path, system: str, seed: int) -> Path:
    return cache / dataset_id(system).replace("/", "__") / f"seed-{int(seed)}.npz"


def _record_one(job: tuple[str, int, str]) -> dict[str, Any]:
    """Record one seed's episode into the cache (a worker's task)."""
    system, seed, cache = job
    env = make_env(system)
    try:
        controller = make_controller(system, env)
        save_episode(record_episode(env, controller, seed), _episode_path(Path(cache), system, seed))
    finally:
        env.close()
    return {"seed": seed}


def _lost(job: tuple[str, int, str], error: str) -> dict[str, Any]:
    return {"seed": job[1], "error": error}


def write(system: str, episodes: int, seed0: int = 0, progress: bool = True, manifest: Path | None = None,
          workers: int = 1, cache: Path = CACHE) -> Any:
    """Record ``episodes`` controller episodes (train seeds ``seed0 ...``) as the system's dataset
    (replacing an existing one) with Minari's writer (``minari.create_dataset_from_buffers``: the
    storage ``DataCollector`` writes, without its ``jax`` dependency) and return the ``MinariDataset``;
    its entry goes to ``manifest`` when given. Episodes already in ``cache`` are not recorded again;
    ``workers`` > 1 records the others in parallel."""
    import minari  # noqa: F401  (the datasets extra: checked before any episode is recorded)

    from satenv.bench.scoreboard.backends import stream

    for name, value in (("episodes", episodes), ("workers", workers)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise DatasetError(f"{name} must be a positive int, got {value!r}")
    task = tasks.training_task(system)
    seeds = list(task.seeds("train"))[seed0:seed0 + episodes]
    t0 = time.perf_counter()
    for s in drop_stale(system, seeds, cache):
        if progress:
            print(f"{system}: the cached episode of seed {s} does not replay with this code: recording it again",
                  flush=True)
    todo = [(system, int(s), str(cache)) for s in seeds if not _episode_path(cache, system, s).is_file()]
    for k, result in enumerate(stream(todo, "local", workers, None, run=_record_one, lost=_lost)):
        if result.get("error"):
            raise RuntimeError(f"{system}: the episode of seed {result['seed']} failed: {result['error']}")
        if progress:
            print(f"{system}: episode {len(seeds) - len(todo) + k + 1}/{len(seeds)} (seed {result['seed']}) at "
                  f"{time.perf_counter() - t0:.0f}s", flush=True)
    buffers = [load_episode(_episode_path(cache, system, s)) for s in seeds]
    steps = sum(len(b.actions) for b in buffers)
    counts = _safety_counts(buffers)
    env = make_env(system)
    try:
        ds = _create_whole(dataset_id(system), buffers, env,
                           algorithm_name=f"scripted controller {tasks.system(system).controller}",
                           author="satenv", code_permalink="satenv/bench/learning/datasets.py",
                           description=_card(system, seeds, steps, inner_loop_name(system), counts))
    finally:
        env.close()
    if manifest is not None:
        _record(manifest, system, seeds, buffers, time.perf_counter() - t0, counts)
    for s in seeds:
        _episode_path(cache, system, s).unlink(missing_ok=True)
    return ds


def _root() -> Path:
    """Minari's dataset folder (``MINARI_DATASETS_PATH``, default ``~/.minari/datasets``)."""
    from minari.storage.datasets_root_dir import get_dataset_path

    return Path(get_dataset_path())


def remove_incomplete(did: str, out: Any = None) -> list[Path]:
    """Remove what a killed write of dataset ``did`` left: a staging copy (:data:`STAGING`), a folder
    swap half done (:func:`satenv.training.runfolder.recover_folder`) and a dataset folder without a
    readable ``metadata.json``; each removal is named on ``out`` (default: stderr). Returns the folders removed."""
    import shutil

    from minari.dataset.minari_storage import MinariStorage

    root, removed = _root(), []
    staged = root / STAGING / did
    if staged.exists():
        shutil.rmtree(staged)
        removed.append(staged)
    folder = root / did
    runfolder.recover_folder(folder)
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise DatasetError(f"{folder}: expected the dataset folder of {did}, found a link or a file; remove it")
    if folder.is_dir():
        try:
            complete = MinariStorage.read_raw_metadata(str(folder / "data"))["dataset_id"] == did
        except Exception:   # noqa: BLE001 - any unreadable metadata is an incomplete folder
            complete = False
        if not complete:
            shutil.rmtree(folder)
            removed.append(folder)
    for path in removed:
        print(f"removed {path}: an incomplete dataset folder left by an interrupted write", file=out or sys.stderr,
              flush=True)
    return removed


def _create_whole(did: str, buffers: list[Any], env: gym.Env, **card: Any) -> Any:
    """``minari.create_dataset_from_buffers`` into the staging root, then the finished folder swapped
    in for ``did`` (module docstring); the ``MinariDataset`` in place."""
    import minari
    from minari.namespace import create_namespace, list_local_namespaces
    from minari.utils import parse_dataset_id

    remove_incomplete(did)
    root = _root()
    saved = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root / STAGING)
    try:
        minari.create_dataset_from_buffers(did, buffers, env=env.unwrapped.spec, eval_env=env.unwrapped.spec,
                                           data_format="arrow", observation_space=env.observation_space,
                                           action_space=env.action_space, **card)
    finally:
        os.environ["MINARI_DATASETS_PATH"] = str(root) if saved is None else saved
    (root / did).parent.mkdir(parents=True, exist_ok=True)
    runfolder.replace_folder(root / STAGING / did, root / did)
    namespace = parse_dataset_id(did)[0]
    if namespace is not None and namespace not in list_local_namespaces():
        create_namespace(namespace)
    return minari.load_dataset(did)


def drop_stale(system: str, seeds: Iterable[int], cache: Path = CACHE) -> list[int]:
    """Replay every cached episode of ``seeds`` and delete those that do not replay exactly (recorded
    by an env that has changed since, or unreadable: a link or a file past the cap is removed
    unread); the seeds deleted."""
    stale = []
    for s in seeds:
        path = _episode_path(cache, system, s)
        if not os.path.lexists(path):
            continue
        try:
            exact = replays_exactly(replay(system, load_episode(path), s))
        except (ValueError, TypeError, KeyError):   # another layout: other shapes, fields or spaces
            exact = False
        if not exact:
            path.unlink()
            stale.append(int(s))
    return stale


def inner_loop_name(system: str) -> str | None:
    """The class of the physics-rate hook the system's controller installs in its env
    (``env.set_inner_loop``; tube-RDMPC: ``TubeController``), ``None`` when it installs none."""
    env = make_env(system)
    try:
        controller = make_controller(system, env)
        env.reset(seed=0)
        controller.reset(seed=0)
        hook = _inner_loop(env)
    finally:
        env.close()
    return None if hook is None else type(hook).__name__


def _record(manifest: Path, system: str, seeds: list[int], buffers: list[Any], wall_s: float,
            counts: dict[str, int]) -> None:
    import minari

    entries = _read_manifest(manifest)
    m = len(buffers[0].infos["collision"][0])
    steps = sum(len(b.actions) for b in buffers)
    entries[system] = {"dataset_id": dataset_id(system), "task": tasks.training_task(system).name,
                       "controller": tasks.system(system).controller, "train_seeds": tasks.show_seeds(seeds),
                       "episodes": len(buffers), "steps": steps, "agent_steps": steps * m,
                       **counts, "wall_s": round(wall_s, 1), "minari": minari.__version__}
    runfolder.write_json(manifest, entries, sort_keys=True)


def _read_manifest(path: Path) -> dict[str, Any]:
    """The manifest's entries (``{}`` when there is none); a link, an oversized or malformed file is a
    :class:`DatasetError` naming it (read through :func:`satenv.training.trust.read_json`)."""
    if not os.path.lexists(path):
        return {}
    try:
        entries = trust.read_json(path.parent, path.name)
    except trust.UntrustedDataError as err:
        raise DatasetError(f"--manifest: {err}") from None
    if not isinstance(entries, dict):
        raise DatasetError(f"--manifest {path}: expected a JSON object of datasets, got {type(entries).__name__}")
    return entries


def read(system: str) -> Any:
    """The system's dataset, loaded by Minari's own loader (``minari.load_dataset``)."""
    import minari

    return minari.load_dataset(dataset_id(system))


def episode_seed(dataset: Any, episode_id: int) -> int:
    """The seed an episode was recorded with (Minari's episode metadata)."""
    return int(next(iter(dataset.storage.get_episode_metadata([int(episode_id)])))["seed"])


def replay(system: str, episode: Any, seed: int, **env_overrides: Any) -> dict[str, float]:
    """Fly a recorded episode's actions from ``seed`` (:func:`episode_seed`) with the controller
    reset after the env as in :func:`record_episode` (what it installs in the env, e.g. the
    tube-RDMPC's inner loop, is there again; it never acts); ``env_overrides`` as given to the
    recording's :func:`make_env`. Returns the largest differences to the recorded observations and
    states and ``flags``, the number of steps whose termination/truncation differ from the recorded
    ones (a step the env could not take because it had ended counts, and its differences are
    ``inf``). An exact replay is ``{"observation": 0.0, "state": 0.0, "flags": 0}``."""
    env = make_env(system, **env_overrides)
    try:
        controller = make_controller(system, env)
        obs, info = env.reset(seed=int(seed))
        controller.reset(seed=int(seed))
        obs_err = float(np.max(np.abs(obs - episode.observations[0])))
        state_err = float(np.max(np.abs(info["state"] - episode.infos["state"][0])))
        flags, done = 0, False
        for t, action in enumerate(episode.actions):
            if done:
                return {"observation": math.inf, "state": math.inf, "flags": flags + len(episode.actions) - t}
            obs, _, term, trunc, info = env.step(action)
            obs_err = max(obs_err, float(np.max(np.abs(obs - episode.observations[t + 1]))))
            state_err = max(state_err, float(np.max(np.abs(info["state"] - episode.infos["state"][t + 1]))))
            flags += (bool(term), bool(trunc)) != (bool(episode.terminations[t]), bool(episode.truncations[t]))
            done = bool(term or trunc)
    finally:
        env.close()
    return {"observation": obs_err, "state": state_err, "flags": flags}


def replays_exactly(error: dict[str, float]) -> bool:
    """Whether a :func:`replay` result is an exact replay."""
    return error == {"observation": 0.0, "state": 0.0, "flags": 0}


def _systems(text: str) -> list[str]:
    """An argparse ``type``: ``all`` or comma-separated systems of :data:`satenv.tasks.SYSTEMS`."""
    if text == "all":
        return list(tasks.SYSTEMS)
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names or any(n not in tasks.SYSTEMS for n in names):
        raise argparse.ArgumentTypeError(f"expected 'all' or comma-separated systems among {sorted(tasks.SYSTEMS)}, "
                                         f"got {text!r}")
    return names


def _estimate(systems: list[str], episodes: int, workers: int) -> str:
    """The expected wall time of writing ``systems`` from the manifest's timed runs."""
    try:
        timed = _read_manifest(MANIFEST)
    except DatasetError:
        timed = {}
    per_episode = [timed[s]["wall_s"] / timed[s]["episodes"] for s in systems
                   if isinstance(timed.get(s), dict) and timed[s].get("wall_s") and timed[s].get("episodes")]
    if not per_episode:
        return "no timed run of these systems in the manifest"
    return (f"about {sum(per_episode) * episodes / workers / 60:.0f} min on {workers} worker(s) at the measured "
            f"rate of {len(per_episode)} of them (episodes already in the cache are replayed, not recorded)")


def main(argv: Iterable[str] | None = None) -> int:
    from satenv.cliargs import int_at_least, new_parser, out_file, out_folder, published_or_user

    p = new_parser("satenv datasets", __doc__.split("**Layout")[0])
    p.add_argument("command", choices=("write", "read"), help="record and write the datasets, or read them back")
    p.add_argument("--systems", type=_systems, default="all", help="comma-separated systems or 'all' (default)")
    p.add_argument("--episodes", type=int_at_least(1), default=50, help="episodes per dataset (default 50)")
    p.add_argument("--root", type=out_folder, default=None, help="Minari's dataset folder (MINARI_DATASETS_PATH)")
    p.add_argument("--manifest", default=None,
                   help=f"JSON file of what was written ('' for none; default: {USER_MANIFEST})")
    p.add_argument("--update-published", action="store_true",
                   help="write the entries into the packaged manifest (satenv/bench/learning/datasets.json, "
                        "the committed record of the published datasets) instead")
    p.add_argument("--workers", type=int_at_least(1), default=1, help="episodes recorded in parallel")
    p.add_argument("--cache", type=out_folder, default=CACHE,
                   help="recorded episodes kept until the dataset is written (default: ~/.cache/satenv/episodes)")
    ns = p.parse_args(None if argv is None else list(argv))
    ns.manifest = str(published_or_user(p, "--manifest", ns.manifest, ns.update_published, MANIFEST, USER_MANIFEST))
    if ns.manifest:
        try:
            out_file(ns.manifest)
            _read_manifest(Path(ns.manifest))   # before any episode is recorded
        except (argparse.ArgumentTypeError, DatasetError) as err:
            p.error(f"argument --manifest: {err}")
    if ns.root:
        os.environ["MINARI_DATASETS_PATH"] = str(ns.root)
    if ns.command == "write":
        print(f"writing {len(ns.systems)} dataset(s) of {ns.episodes} episodes: "
              f"{_estimate(ns.systems, ns.episodes, ns.workers)}; "
              f"to {ns.root or 'MINARI_DATASETS_PATH (~/.minari/datasets)'}",
              file=sys.stderr, flush=True)
    for system in ns.systems:
        ds = (write(system, ns.episodes, manifest=Path(ns.manifest) if ns.manifest else None, workers=ns.workers,
                    cache=Path(ns.cache))
              if ns.command == "write" else read(system))
        ep = next(ds.iterate_episodes())
        err = replay(system, ep, episode_seed(ds, ep.id))
        print(f"{dataset_id(system)}: {ds.total_episodes} episodes, {ds.total_steps} steps; episode 0: "
              f"{len(ep.actions)} steps, replay max |obs diff| {err['observation']:.3g}, max |state diff| "
              f"{err['state']:.3g}, steps ending otherwise {err['flags']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
