"""The satenv scoreboard: every policy on every scenario over seeds, ranked on the papers' metrics.

Usage::

    python -m benchmarks.scoreboard --quick            # the README's first command (~1-3 min)
    python -m benchmarks.scoreboard                    # the full, published board
    python -m benchmarks.scoreboard --scenarios 'platoon-*' --policies zero,dmpc --seeds 0-9
    python -m benchmarks.scoreboard --policy runs/my_ppo/final --scenarios platoon-random-cw
    python -m benchmarks.scoreboard --list             # what is registered / available
    satenv-scoreboard ...                              # the same, as a console script

Scenarios and policies come from :mod:`benchmarks.registry`. Every episode is a
``(scenario, policy, seed)`` key: the env is reset with ``seed`` and the policy with
``reset(seed)``; its metrics (``satenv.metrics.summary`` plus ``episode_return`` and ``wall_s``)
go as one JSON line to ``OUT/episodes.jsonl``, appended and flushed (``fsync``) as soon as the
episode finishes. ``--resume`` reads that file back (dropping a torn last line), skips the keys
already done and runs the rest, so an interrupted run loses and duplicates nothing.
Before any episode runs, every (scenario, policy) pair is built (and cheap or learned policies
act once) so bad input fails fast with a :class:`~benchmarks.registry.ScoreboardError`: a name
the user typed must exist and be runnable, and a pair the user named on both sides must work;
entries selected by default or by a glob that are not available (code not landed, optional
dependency missing) or cannot run together are skipped with a note in the outputs.
The boards: ``registry.FULL`` (seeds 0-9, fewer for the costliest scenarios) and
``registry.QUICK``; ``--seeds`` replaces both the seeds and the caps.

Outputs in ``OUT`` (default ``results/scoreboard``, ``results/scoreboard/quick`` with
``--quick``): ``scoreboard.md`` (header + a ranked table per scenario: success rate desc, then
RMSE asc, then delta-v asc; mean +- 95 % CI half-width over seeds: Student t for metrics, Wilson
for the success rate), ``scoreboard.json`` (header, aggregates, ranking, episodes),
``scoreboard.csv`` (one row per scenario x policy), ``episodes.csv``, ``plots/<metric>.png`` (bar
charts with CIs) and ``plots/trajectories/*.png`` (the first seed of every pair).

Episodes are deterministic given their key; ``--workers K`` (a spawn process pool) and
``--backend ray`` only change *where* they run, so the records equal a serial run's except the
measured times (:data:`TIMING_FIELDS`).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one BLAS thread per episode: fair, stable solve timings

import argparse  # noqa: E402
import difflib  # noqa: E402
import fnmatch  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from collections.abc import Callable, Iterable, Iterator  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks.registry import (  # noqa: E402
    FULL,
    POLICIES,
    QUICK,
    SCENARIOS,
    PolicySpec,
    ScenarioSpec,
    ScoreboardError,
    Unavailable,
    discover_trained_policies,
)
from benchmarks.scoreboard_report import (  # noqa: E402
    KEY,
    METRICS,
    TIMING_FIELDS,
    Board,
    aggregate,
    jsonable,
    rank,
    render_markdown,
    write_outputs,
)

__all__ = ["EPISODES_FILE", "METRICS", "TIMING_FIELDS", "Task", "aggregate", "main", "rank",
           "read_episodes", "run_episode", "run_scoreboard"]

EPISODES_FILE = "episodes.jsonl"


# ----------------------------------------------------------------------------------------------
# One episode (runs in the main process, a pool worker or a Ray worker).
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One episode to run: ``rollout(scenario.make(), policy.make(env), seed=seed)``."""

    scenario: ScenarioSpec
    policy: PolicySpec
    seed: int
    trajectory_path: str | None = None  # save the Trajectory (.npz) here (example episodes)

    @property
    def key(self) -> tuple[str, str, int]:
        return (self.scenario.name, self.policy.name, self.seed)


def run_episode(task: Task) -> dict[str, Any]:
    """Run one episode and return its JSON record (an exception in it is recorded, not raised)."""
    from satenv import metrics
    from satenv.rollout import rollout

    start = time.perf_counter()
    record: dict[str, Any] = {"scenario": task.scenario.name, "policy": task.policy.name,
                              "seed": int(task.seed), "scenario_fp": task.scenario.fingerprint(),
                              "policy_fp": task.policy.fingerprint()}
    env = None
    try:
        env = task.scenario.make()
        record["env"] = env.metadata.get("name", type(env).__name__)
        policy = task.policy.make(env)
        traj = rollout(env, policy, seed=int(task.seed))
        record.update(metrics.summary(traj, tol=task.scenario.success_tol))
        if not task.scenario.collision_free_success:   # success = formation reached (see registry)
            record["success"] = bool(record["final_error_m"] <= task.scenario.success_tol)
        record["episode_return"] = float(np.mean(np.sum(traj.rewards, axis=0))) if traj.steps else 0.0
        record["error"] = None
        if task.trajectory_path is not None:
            Path(task.trajectory_path).parent.mkdir(parents=True, exist_ok=True)
            traj.save(task.trajectory_path)
    except Exception as exc:  # a crashing controller is a result of the board, not a crash of it
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc(limit=6)
        record["success"] = False
    finally:
        if env is not None:
            env.close()
    record["wall_s"] = time.perf_counter() - start
    return jsonable(record)


# ----------------------------------------------------------------------------------------------
# The episode log: one JSON line per finished episode.
# ----------------------------------------------------------------------------------------------
def read_episodes(path: str | Path, repair: bool = False) -> list[dict[str, Any]]:
    """Records of ``episodes.jsonl`` (first occurrence per key); a torn last line is ignored.

    With ``repair`` the torn tail (a line an interrupted run did not finish) is cut off the file.
    """
    path = Path(path)
    if not path.exists():
        return []
    data = path.read_bytes()
    good_end = data.rfind(b"\n") + 1          # everything after the last newline is torn
    records, seen = [], set()
    for lineno, line in enumerate(data[:good_end].splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            key = tuple(rec[k] for k in KEY)
        except (ValueError, KeyError, TypeError) as exc:
            raise ScoreboardError(f"{path}:{lineno} is not an episode record ({exc}); the file is "
                                  f"corrupt: pass --overwrite to start over or fix the line") from None
        if key not in seen:
            seen.add(key)
            records.append(rec)
    if repair and good_end < len(data):
        with open(path, "r+b") as fh:
            fh.truncate(good_end)
    return records


class EpisodeLog:
    """Append-only JSONL writer: every record is one ``write`` of a full line, then ``fsync``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def append(self, record: dict[str, Any]) -> None:
        line = (json.dumps(record, sort_keys=True, allow_nan=False) + "\n").encode()
        os.write(self._fd, line)
        os.fsync(self._fd)

    def close(self) -> None:
        os.close(self._fd)


# ----------------------------------------------------------------------------------------------
# Selection and preflight.
# ----------------------------------------------------------------------------------------------
def _split(value: str | Iterable[str] | None) -> list[str] | None:
    if value is None:
        return None
    items = value.split(",") if isinstance(value, str) else list(value)
    return [s.strip() for s in items if s.strip()]


def parse_seeds(text: str) -> list[int]:
    """``"0-9"``, ``"0,3,7"`` or ``"0-4,10"`` -> sorted unique non-negative ints."""
    seeds: set[int] = set()
    try:
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            if "-" in part:
                lo, hi = (int(p) for p in part.split("-", 1))
                if hi < lo:
                    raise ValueError
                seeds.update(range(lo, hi + 1))
            else:
                seeds.add(int(part))
    except ValueError:
        raise ScoreboardError(f"--seeds must be non-negative integers or ranges like '0-9' or "
                              f"'0,3,7', got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ScoreboardError(f"--seeds must name at least one non-negative seed, got {text!r}")
    return sorted(seeds)


def _select(requested: list[str] | None, registry: dict, kind: str, notes: list[str],
            strict: bool) -> tuple[list[str], set[str]]:
    """Available registry names matching ``requested`` (names or globs; all when ``None``), and
    the ones the user named exactly (``strict``: the user typed the selection).

    With ``strict`` an unknown name, or an unavailable one named exactly, is an error; otherwise
    (embedded defaults, globs) it is skipped with a note.
    """
    patterns = requested if requested is not None else ["*"]
    chosen: list[str] = []
    explicit: set[str] = set()
    for pat in patterns:
        matches = [n for n in registry if fnmatch.fnmatchcase(n, pat)]
        if not matches:
            if not strict:
                notes.append(f"{kind} {pat!r}: not registered (skipped)")
                continue
            close = difflib.get_close_matches(pat, list(registry), n=3)
            hint = f"; did you mean {close}?" if close else ""
            raise ScoreboardError(f"unknown {kind} {pat!r}{hint} Registered {kind}s: {sorted(registry)} "
                                  f"(see python -m benchmarks.scoreboard --list)")
        for name in matches:
            if name in chosen:
                continue
            try:
                registry[name].factory()
            except Unavailable as why:
                if strict and pat == name:
                    raise ScoreboardError(f"{kind} {name!r} is registered but not available here: {why}. "
                                          "Install what it needs or leave it out.") from None
                notes.append(f"{kind} {name}: skipped ({why})")
                continue
            chosen.append(name)
            if strict and pat == name:
                explicit.add(name)
    return chosen, explicit


def _check_actions(actions: Any, env) -> None:
    if not isinstance(actions, dict):
        raise ValueError(f"act() returned {type(actions).__name__}, expected a dict keyed by agent")
    if set(actions) != set(env.agents):
        raise ValueError(f"act() returned actions for {sorted(actions)}, expected {sorted(env.agents)}")
    for agent, a in actions.items():
        shape = env.action_space(agent).shape
        arr = np.asarray(a, dtype=float)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            raise ValueError(f"act() returned {arr.tolist()} for {agent}; expected finite shape {shape}")


def _observation_mismatch(policy, env) -> str | None:
    shape = getattr(policy, "obs_shape", None)
    if shape is None:
        shape = getattr(getattr(policy, "observation_space", None), "shape", None)
    if shape is None:
        return None
    want = env.observation_space(env.possible_agents[0]).shape
    if tuple(shape) != tuple(want):
        return f"the policy expects observations of shape {tuple(shape)}, the env gives {tuple(want)}"
    return None


def preflight(scenarios: list[ScenarioSpec], policies: list[PolicySpec], seed: int,
              strict: Callable[[str, str], bool], notes: list[str]
              ) -> tuple[list[tuple[str, str]], dict[str, str]]:
    """Build every applicable (scenario, policy) pair once, before any episode runs.

    Learned policies' observation spaces are compared with the env's, and policies with
    ``dry_run`` act once on a reset env. A failing pair raises :class:`ScoreboardError` when
    ``strict(scenario, policy)`` (the user named both), else it is skipped with a note.
    Returns the runnable pairs and each scenario's env id.
    """
    pairs, env_ids = [], {}
    for scen in scenarios:
        try:
            env = scen.make()
        except Exception as exc:
            raise ScoreboardError(f"scenario {scen.name}: building the env {scen.targets[0]}"
                                  f"(**{dict(scen.kwargs)}) failed: {type(exc).__name__}: {exc}") from exc
        env_ids[scen.name] = env.metadata.get("name", type(env).__name__)
        for pol in policies:
            if not pol.applies_to(scen.name, env):
                continue
            try:
                policy = pol.make(env)
                why = _observation_mismatch(policy, env) if pol.learned else None
                if why is None and pol.dry_run:
                    obs, _ = env.reset(seed=seed)
                    policy.reset(seed=seed)
                    _check_actions(policy.act(obs), env)
            except ScoreboardError:
                raise
            except Exception as exc:
                why = f"{type(exc).__name__}: {exc}"
            if why is not None:
                if not strict(scen.name, pol.name):
                    notes.append(f"policy {pol.name} on {scen.name}: skipped ({why})")
                    continue
                raise ScoreboardError(f"policy {pol.name} cannot run on scenario {scen.name}: {why}. "
                                      "Choose compatible scenarios with --scenarios.")
            pairs.append((scen.name, pol.name))
        env.close()
    return pairs, env_ids


def _user_policy(path: str) -> PolicySpec:
    p = Path(path)
    if not p.exists():
        raise ScoreboardError(f"--policy {path}: no such file or directory; pass the path of a "
                              "checkpoint saved by training (e.g. runs/<run>/final)")
    if not os.access(p, os.R_OK):
        raise ScoreboardError(f"--policy {path}: not readable (check its permissions)")
    try:
        import training
    except ModuleNotFoundError as exc:
        raise ScoreboardError(f"--policy needs the training package ({exc})") from None
    if not callable(getattr(training, "load", None)):
        raise ScoreboardError("--policy needs training.load(path), which this installation does not "
                              "provide yet; update satenv or drop --policy")
    try:
        training.load(str(p))
    except Exception as exc:
        raise ScoreboardError(f"--policy {path}: cannot load this checkpoint: {type(exc).__name__}: "
                              f"{exc}") from None
    return PolicySpec(f"user:{p.resolve().name}", ("training:load",), checkpoint=str(p),
                      requires=("stable_baselines3",), learned=True, description=f"user checkpoint {path}")


# ----------------------------------------------------------------------------------------------
# Running.
# ----------------------------------------------------------------------------------------------
def _machine() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"platform": platform.platform(), "cpu": cpu, "cpus": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__}


def _git() -> str | None:
    root = Path(__file__).resolve().parent.parent
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def _iter_serial(tasks: list[Task]) -> Iterator[dict[str, Any]]:
    for task in tasks:
        yield run_episode(task)


def _iter_pool(tasks: list[Task], workers: int) -> Iterator[dict[str, Any]]:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        futures = [pool.submit(run_episode, t) for t in tasks]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _iter_ray(tasks: list[Task], workers: int, address: str | None) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ModuleNotFoundError as exc:
        if exc.name != "ray":
            raise
        raise ScoreboardError("--backend ray needs Ray: pip install 'satenv[rllib]' (or ray)") from None
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(run_episode)
    pending = [remote.remote(t) for t in tasks]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        for ref in pending:
            ray.cancel(ref)


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def _trajectory_path(out: Path, scen: str, pol: str, seed: int) -> Path:
    return out / "trajectories" / f"{_safe(scen)}__{_safe(pol)}__seed{seed}.npz"


def run_scoreboard(out: str | Path = "results/scoreboard", *, scenarios: str | list[str] | None = None,
                   policies: str | list[str] | None = None, seeds: list[int] | str | None = None,
                   checkpoints: list[str] = (), quick: bool = False,
                   scenario_seeds: dict[str, list[int]] | None = None, workers: int = 1,
                   backend: str = "process", ray_address: str | None = None, resume: bool = False,
                   overwrite: bool = False, plots: bool = True, progress: bool = True,
                   scenario_registry: dict[str, ScenarioSpec] | None = None,
                   policy_registry: dict[str, PolicySpec] | None = None,
                   on_record: Callable[[dict[str, Any]], None] | None = None,
                   argv: list[str] | None = None) -> Board:
    """Run the board and write its files; see the module docstring. Returns the :class:`Board`.

    ``seeds`` default to the board's (``FULL`` or ``QUICK`` in the registry); ``scenario_seeds``
    caps the seeds of expensive scenarios (``{name: seeds}``, intersected with ``seeds``), by
    default the board's caps unless ``seeds`` were given;
    ``scenario_registry`` / ``policy_registry`` replace the registry's dicts (tests, plugins);
    ``on_record`` is called after each record is written (progress hooks, tests).
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ScoreboardError(f"--workers must be a positive integer, got {workers!r}")
    if backend not in ("process", "ray"):
        raise ScoreboardError(f"--backend must be 'process' or 'ray', got {backend!r}")
    if resume and overwrite:
        raise ScoreboardError("--resume and --overwrite contradict each other: pick one")
    board_preset = QUICK if quick else FULL
    user_seeds = seeds is not None
    if seeds is None:
        seeds = board_preset["seeds"]
    seeds = parse_seeds(seeds) if isinstance(seeds, str) else sorted(set(seeds))
    if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
        raise ScoreboardError(f"seeds must be non-negative integers, got {seeds!r}")
    seeds = [int(s) for s in seeds]
    if scenario_seeds is None:
        scenario_seeds = {} if user_seeds else dict(board_preset.get("scenario_seeds", {}))
    scen_seeds = {name: [s for s in seeds if s in set(lst)] or seeds[:1] for name, lst in scenario_seeds.items()}

    scen_reg = dict(SCENARIOS if scenario_registry is None else scenario_registry)
    pol_reg = dict(POLICIES if policy_registry is None else policy_registry)
    for reg in (scen_reg, pol_reg):
        for key, spec in reg.items():
            if key != spec.name:
                raise ScoreboardError(f"registry entry {key!r} holds a spec named {spec.name!r}: "
                                      "the key must be the spec's name")
    if policy_registry is None:
        for name, spec in discover_trained_policies().items():
            pol_reg.setdefault(name, spec)
    user_specs = [_user_policy(p) for p in checkpoints]
    for spec in user_specs:
        if spec.name in pol_reg:
            raise ScoreboardError(f"two policies named {spec.name!r}: rename the checkpoint folder")
        pol_reg[spec.name] = spec

    notes: list[str] = []
    req_scen, req_pol = _split(scenarios), _split(policies)
    if quick:
        req_scen = req_scen if req_scen is not None else list(QUICK["scenarios"])
        req_pol = req_pol if req_pol is not None else list(QUICK["policies"])
    if req_pol is not None and user_specs:
        req_pol = req_pol + [s.name for s in user_specs if s.name not in req_pol]
    scen_names, scen_explicit = _select(req_scen, scen_reg, "scenario", notes,
                                        strict=not quick or scenarios is not None)
    pol_names, pol_explicit = _select(req_pol, pol_reg, "policy", notes,
                                      strict=not quick or policies is not None)
    pol_explicit |= {spec.name for spec in user_specs}
    if not scen_names:
        raise ScoreboardError("no scenario to run: none of the selected scenarios is available "
                              f"({'; '.join(notes) or 'empty selection'})")
    if not pol_names:
        raise ScoreboardError("no policy to run: none of the selected policies is available "
                              f"({'; '.join(notes) or 'empty selection'})")

    out = Path(out)
    log_path = out / EPISODES_FILE
    if log_path.exists() and not resume and not overwrite and log_path.stat().st_size > 0:
        raise ScoreboardError(f"{log_path} already holds episodes of an earlier run: pass --resume to "
                              "continue it, --overwrite to discard it, or choose another --out")

    pairs, env_ids = preflight([scen_reg[n] for n in scen_names], [pol_reg[n] for n in pol_names],
                               seeds[0], lambda s, p: s in scen_explicit and p in pol_explicit, notes)
    if not pairs:
        raise ScoreboardError("no (scenario, policy) pair applies: " + "; ".join(notes))
    for name in pol_names:
        if not any(p == name for _, p in pairs) and not any(f"policy {name} on" in n for n in notes):
            notes.append(f"policy {name}: applies to none of the selected scenarios "
                         f"(it applies to {pol_reg[name].where()})")
    for kind, names, idx in (("policy", pol_explicit, 1), ("scenario", scen_explicit, 0)):
        for name in sorted(names):
            if not any(pair[idx] == name for pair in pairs):
                raise ScoreboardError(f"{kind} {name} has nothing to run with the selected "
                                      f"{'scenarios' if idx else 'policies'}: "
                                      + "; ".join(n for n in notes if name in n)
                                      + " (see --list for which policy applies where)")
    plan = [(s, p, seed) for s, p in pairs for seed in scen_seeds.get(s, seeds)]

    if overwrite:
        log_path.unlink(missing_ok=True)
        for f in (out / "trajectories").glob("*.npz"):
            f.unlink()
    out.mkdir(parents=True, exist_ok=True)
    previous = read_episodes(log_path, repair=True)
    fps = {n: scen_reg[n].fingerprint() for n in scen_names}
    fps.update({n: pol_reg[n].fingerprint() for n in pol_names})
    planned = set(plan)
    done = {}
    for rec in previous:
        key = (rec["scenario"], rec["policy"], rec["seed"])
        if key not in planned:
            continue
        for kind, fp in (("scenario", "scenario_fp"), ("policy", "policy_fp")):
            if rec.get(fp) != fps[rec[kind]]:
                raise ScoreboardError(f"{log_path} holds episodes of a different definition of {kind} "
                                      f"{rec[kind]!r} (fingerprint {rec.get(fp)} != {fps[rec[kind]]}): "
                                      "pass --overwrite or choose another --out")
        done[key] = rec
    todo = [k for k in plan if k not in done]
    examples = {(s, p): scen_seeds.get(s, seeds)[0] for s, p in pairs}
    tasks = [Task(scen_reg[s], pol_reg[p], seed,
                  str(_trajectory_path(out, s, p, seed)) if plots and examples[(s, p)] == seed else None)
             for s, p, seed in todo]

    header = {
        "title": "satenv scoreboard" + (" (quick)" if quick else ""),
        "satenv_version": _version(), "git": _git(),
        "generated": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": "python -m benchmarks.scoreboard " + " ".join(argv if argv is not None else []),
        "machine": _machine(), "backend": backend, "workers": workers, "seeds": seeds,
        "scenario_seeds": {n: v for n, v in scen_seeds.items() if n in scen_names},
        "env_versions": sorted(set(env_ids.values())),
        "scenarios": {n: {"env": env_ids[n], "kwargs": dict(scen_reg[n].kwargs),
                          "description": scen_reg[n].description,
                          "success_tol_m": scen_reg[n].success_tol,
                          "collision_free_success": scen_reg[n].collision_free_success}
                      for n in scen_names if n in env_ids},
        "policies": {n: {"description": pol_reg[n].description,
                         **({"checkpoint": pol_reg[n].checkpoint} if pol_reg[n].checkpoint else {})}
                     for n in pol_names},
        "episodes_planned": len(plan), "episodes_resumed": len(done),
        "ranking": "success rate (desc), then RMSE (asc), then delta-v (asc)",
        "notes": notes,
    }
    for note in notes:
        print(f"note: {note}", file=sys.stderr)

    from tqdm import tqdm

    bar = tqdm(total=len(plan), initial=len(done), desc="scoreboard", unit="ep", disable=not progress,
               file=sys.stderr, dynamic_ncols=True)
    if backend == "ray":
        stream = _iter_ray(tasks, workers, ray_address)
    elif workers > 1 and len(tasks) > 1:
        stream = _iter_pool(tasks, workers)
    else:
        stream = _iter_serial(tasks)
    log = EpisodeLog(log_path)
    try:
        for rec in stream:
            log.append(rec)
            done[(rec["scenario"], rec["policy"], rec["seed"])] = rec
            bar.update(1)
            bar.set_postfix_str(f"{rec['scenario']} / {rec['policy']}", refresh=False)
            if on_record is not None:
                on_record(rec)
    finally:
        close = getattr(stream, "close", None)
        if close is not None:
            close()
        log.close()
        bar.close()

    records = [done[k] for k in plan if k in done]       # plan order: registry order, then seed
    agg = aggregate(records)
    agg = {s: agg[s] for s in dict.fromkeys(s for s, _ in pairs) if s in agg}
    ranking = {s: rank(agg[s]) for s in agg}
    board = Board(out, header, records, agg, ranking, notes)
    board.markdown = render_markdown(board)
    write_outputs(board, plots=plots)
    return board


def _version() -> str:
    try:
        import satenv

        return satenv.__version__
    except (ImportError, AttributeError):
        return "unknown"


# ----------------------------------------------------------------------------------------------
# CLI.
# ----------------------------------------------------------------------------------------------
def _list_registry() -> str:
    lines = ["scenarios:"]
    for name, spec in SCENARIOS.items():
        try:
            spec.factory()
            status = "available"
        except Unavailable as why:
            status = f"not available ({why})"
        lines.append(f"  {name:<32} {status:<12}  {spec.description}")
    lines.append("policies:")
    for name, spec in {**POLICIES, **discover_trained_policies()}.items():
        try:
            spec.factory()
            status = "available"
        except Unavailable as why:
            status = f"not available ({why})"
        lines.append(f"  {name:<32} {status:<12}  {spec.where()}  {spec.description}")
    lines.append(f"quick: {QUICK}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scoreboard",
                                description="Rank every policy on every scenario (satenv scoreboard).",
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help=f"the small embedded board: {QUICK['scenarios']} x {QUICK['policies']} x seeds "
                        f"{QUICK['seeds']} (a few minutes on 2 cores)")
    p.add_argument("--scenarios", help="comma-separated scenario names or globs (default: all available)")
    p.add_argument("--policies", help="comma-separated policy names or globs (default: all available)")
    p.add_argument("--seeds", help=f"seeds: '0-9', '0,3,7' (default: {FULL['seeds']} with fewer for "
                                   f"{sorted(FULL['scenario_seeds'])}; quick: {QUICK['seeds']})")
    p.add_argument("--policy", action="append", default=[], metavar="PATH",
                   help="also run a trained checkpoint (training.load(PATH)); repeatable")
    p.add_argument("--out", help="output directory (default: results/scoreboard, "
                                 "results/scoreboard/quick with --quick)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out")
    p.add_argument("--overwrite", action="store_true", help="discard the episodes already in --out")
    p.add_argument("--workers", type=int, default=1, help="parallel worker processes")
    p.add_argument("--backend", choices=("process", "ray"), default="process",
                   help="where episodes run: local processes or Ray")
    p.add_argument("--ray-address", default=None,
                   help="address of an existing Ray cluster (default: start a local one)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots and trajectories")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--list", action="store_true", help="list scenarios and policies, then exit")
    return p


def main(argv: list[str] | None = None) -> int:
    args_list = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(args_list)
    if args.list:
        print(_list_registry())
        return 0
    out = args.out or ("results/scoreboard/quick" if args.quick else "results/scoreboard")
    try:
        board = run_scoreboard(out, scenarios=args.scenarios, policies=args.policies, seeds=args.seeds,
                               checkpoints=args.policy, quick=args.quick, workers=args.workers,
                               backend=args.backend, ray_address=args.ray_address, resume=args.resume,
                               overwrite=args.overwrite, plots=not args.no_plots,
                               progress=not args.no_progress, argv=args_list)
    except ScoreboardError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished episodes are in {out}/{EPISODES_FILE}; "
              "rerun with --resume to continue", file=sys.stderr)
        return 130
    print(board.markdown)
    print(f"wrote {board.out}/scoreboard.md, scoreboard.json, scoreboard.csv, episodes.csv"
          + (", plots/" if not args.no_plots else ""))
    errors = sum(1 for r in board.records if r.get("error"))
    if errors:
        print(f"warning: {errors} episode(s) raised an error (see the 'error' field in "
              f"{board.out}/{EPISODES_FILE})", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
