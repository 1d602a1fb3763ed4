"""Evaluate policies (learned or scripted) on fixed seeds with the PettingZoo env and ``satenv.rollout``.

The same path the scoreboard uses: ``rollout(env, policy, seed=s)`` then the episode record and
aggregate of :mod:`satenv.scoring`. :func:`compare` adds the learned-vs-reference ratios of the
targets (tracking RMSE and total delta-v relative to the reference on the same seeds).

Every evaluation shows a progress bar with an ETA (tqdm, on stderr; ``progress=False`` hides
it) and runs its episodes in ``workers`` forked processes when there are several (each episode
is independent and seeded, so the results do not depend on the worker count). The scripted
baselines' results are cached on disk once per (scenario, seeds, baseline config, code) in
:func:`cache_dir` and shared by every run.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import multiprocessing
import os
import sys
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from satenv import baselines, metrics, scoring
from satenv.rollout import rollout

__all__ = ["AUTO", "evaluate", "make_baseline", "baseline_names", "compare", "format_table",
           "evaluate_baselines", "cached_baselines", "test_summary", "run_summary", "learning_curve",
           "cache_dir", "resolve_workers"]

AUTO = "auto"
"""``eval_baselines`` entry meaning: ``zero`` plus the cheap scripted controllers that support
the env (no per-decision NLP: ``dmpc`` on platoon, ``apf`` on cluster)."""


def make_baseline(name: str, env: Any):
    """``satenv.baselines.make(name, env)`` (a name of ``satenv.baselines.BASELINES``)."""
    return baselines.make(name, env)


def baseline_names(env: Any, names: Iterable[str]) -> list[str]:
    """``names`` with ``"auto"`` expanded to ``zero`` and the other baselines of
    ``satenv.baselines.supporting(env, cheap=True)`` except ``random`` (:data:`AUTO`), duplicates dropped.

    The NLP baselines (nmpc, tube_rdmpc, cgmres: 0.5-16 min per episode) run only when named.
    """
    out: list[str] = []
    for name in names:
        auto = [n for n in baselines.supporting(env, cheap=True) if n != "random"]
        out += auto if name == AUTO else [name]
    return list(dict.fromkeys(out))


def evaluate(env: Any, policy: Any, seeds: Iterable[int], *, desc: str = "evaluation", progress: bool = True,
             workers: int = 1) -> dict[str, Any]:
    """Roll ``policy`` out once per seed; returns per-episode summaries and their aggregate.

    Success is the scenario's rule (``satenv.metrics.summary``: ``success_tol``,
    ``collision_voids_success`` of ``env.scenario``). ``desc`` labels the progress bar;
    ``workers`` > 1 runs the episodes in that many forked processes (:func:`resolve_workers`).

    Aggregate keys: those of :func:`satenv.scoring.aggregate`.
    """
    seeds = [int(s) for s in seeds]
    bar = progress_bar(len(seeds), desc, progress)
    episodes = []
    n = min(resolve_workers(workers), len(seeds) - 1)
    parallel = n > 1 and "fork" in multiprocessing.get_all_start_methods()
    for seed in seeds[:1] if parallel else seeds:  # in parallel, the first episode here warms up the
        episodes.append(_episode(env, policy, seed))  # compiled kernels and solver caches the workers inherit
        bar.update(1)
    if parallel:
        global _WORK
        _WORK = (env, policy)  # inherited by the forked workers, never pickled
        try:
            with multiprocessing.get_context("fork").Pool(n, initializer=_init_worker) as pool:
                for s in pool.imap(_episode_in_worker, seeds[1:]):
                    episodes.append(s)
                    bar.update(1)
        finally:
            _WORK = None
    bar.close()
    return {"aggregate": aggregate(episodes), "episodes": episodes}


def _episode(env: Any, policy: Any, seed: int) -> dict[str, Any]:
    return scoring.episode_record(rollout(env, policy, seed=seed), seed, len(env.possible_agents))


_WORK: tuple[Any, Any] | None = None
"""The (env, policy) of the running :func:`evaluate`, for its forked workers."""


def _init_worker() -> None:
    torch = sys.modules.get("torch")  # one thread per worker where a torch policy runs (never imported here)
    if torch is not None:
        torch.set_num_threads(1)


def _episode_in_worker(seed: int) -> dict[str, Any]:
    env, policy = _WORK
    return _episode(env, policy, seed)


def resolve_workers(workers: int) -> int:
    """``workers`` processes for evaluation episodes; 0 (auto): one per idle core, at most 2 (on a
    machine whose cores are busy, extra processes only add their start-up: measured 9.6 s vs 13 s
    wall for six DMPC episodes at load 7 on 2 cores)."""
    if workers > 0:
        return workers
    idle = (os.cpu_count() or 1) - int(os.getloadavg()[0]) if hasattr(os, "getloadavg") else 1
    return max(1, min(2, idle))


def progress_bar(total: int, desc: str, enabled: bool = True):
    """A tqdm bar with an ETA on stderr (a no-op when ``enabled`` is false)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="episode", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True, leave=False)


aggregate = scoring.aggregate
"""The one aggregate (:func:`satenv.scoring.aggregate`)."""


def compare(results: dict[str, dict[str, Any]], learned: str = "learned",
            reference: str = "dmpc") -> dict[str, Any]:
    """Ratios learned/reference of mean RMSE and mean delta-v.

    ``matched``: the one ratio rule (:func:`satenv.metrics.matched_ratios`: seeds where both
    episodes ran to the end without a collision), what the card reads; ``all_seeds``: over every
    common seed (an early-terminated episode can lower a ratio), for information. A reference
    evaluated on a subset of the learned policy's seeds (an expensive controller) is compared on
    that subset.
    """
    if learned not in results or reference not in results:
        return {}
    mine, ref = results[learned]["episodes"], results[reference]["episodes"]
    by_seed = {e["seed"]: e for e in mine}
    pairs = [(by_seed[e["seed"]], e) for e in ref if e["seed"] in by_seed]
    if not pairs:
        raise ValueError(f"compare() needs {learned!r} and {reference!r} evaluated on common seeds")
    le, re = [p[0] for p in pairs], [p[1] for p in pairs]
    return {"reference": reference, "matched": metrics.matched_ratios(mine, ref),
            "all_seeds": {"seeds": len(pairs),
                          "rmse_ratio": float(np.mean([e["rmse"] for e in le]) / np.mean([e["rmse"] for e in re])),
                          "delta_v_ratio": float(np.mean([e["delta_v"] for e in le])
                                                 / np.mean([e["delta_v"] for e in re]))}}


def format_table(results: dict[str, dict[str, Any]]) -> str:
    """A Markdown table of the aggregates, one row per policy."""
    cols = ["episodes", "success_rate", "collision_episodes", "violation_episodes", "terminated", "rmse",
            "delta_v", "final_error_m", "min_separation_m", "compute_ms_per_decision"]
    head = "| policy | " + " | ".join(cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    for name, res in results.items():
        agg = res["aggregate"]
        cells = [f"{agg[c]:.3g}" if isinstance(agg[c], float) else str(agg[c]) for c in cols]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def evaluate_baselines(env: Any, names: Iterable[str], seeds: Iterable[int], *, progress: bool = True,
                       workers: int = 1) -> dict[str, Any]:
    """Evaluate the named registered baselines (``"auto"``: :func:`baseline_names`), each from the
    shared on-disk cache when it holds the same (scenario, seeds, baseline config, code).

    A named baseline that cannot control ``env`` (``supports(env)`` False) is skipped with a
    warning; an unknown name raises :class:`satenv.baselines.BaselineError`.
    """
    seeds = [int(s) for s in seeds]
    out = {}
    for name in baseline_names(env, names):
        cls = baselines.get(name)
        if not cls.supports(env):
            warnings.warn(f"baseline {name!r} cannot control this env (it supports "
                          f"{cls.supported()}); skipped", stacklevel=2)
            continue
        policy = baselines.make(name, env)
        path = cache_dir() / f"{_baseline_key(env, name, policy, seeds)}.json"
        try:
            out[name] = json.loads(path.read_text())
            continue
        except (OSError, json.JSONDecodeError):
            pass
        out[name] = evaluate(env, policy, seeds, desc=f"baseline {name}", progress=progress, workers=workers)
        _write_atomic(path, json.dumps(out[name], default=float))
    return out


def cache_dir() -> Path:
    """Where the baselines' results are cached: ``$SATENV_CACHE_DIR/baselines``, else
    ``$XDG_CACHE_HOME/satenv/baselines`` (``~/.cache/satenv/baselines``). Delete it to re-run them."""
    root = os.environ.get("SATENV_CACHE_DIR")
    base = Path(root) if root else Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "satenv"
    return base / "baselines"


def _baseline_key(env: Any, name: str, policy: Any, seeds: list[int]) -> str:
    """A hash of everything a baseline's evaluation depends on: the env's class and scenario, the
    baseline's name and config, the seeds, and the source of the env, baseline, rollout and metrics."""
    files = {inspect.getfile(type(env)), inspect.getfile(type(policy)), inspect.getfile(rollout),
             inspect.getfile(metrics.summary), inspect.getfile(type(env.scenario))}
    h = hashlib.sha256()
    for part in (type(env).__qualname__, repr(env.scenario), name, repr(getattr(policy, "config", None)),
                 json.dumps(seeds), *(Path(f).read_bytes() for f in sorted(files))):
        h.update(part if isinstance(part, bytes) else part.encode())
    return f"{env.metadata.get('name', type(env).__name__)}-{name}-{h.hexdigest()[:20]}"


def _write_atomic(path: Path, text: str) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(text)
        tmp.replace(path)
    except OSError as err:  # a read-only cache only costs time
        warnings.warn(f"cannot write the baseline cache {path} ({err})", stacklevel=3)


def cached_baselines(path: Path, eval_env: Any, names: Iterable[str], seeds: Iterable[int],
                     key: dict[str, Any], *, progress: bool = True, workers: int = 1) -> dict[str, Any]:
    """:func:`evaluate_baselines` (from the shared cache where it can), recorded in the run's JSON
    file ``path`` under ``key`` (plus the names, seeds and the scenario's success rule)."""
    names, seeds = list(names), [int(s) for s in seeds]
    full_key = {**key, "seeds": seeds, "baselines": names, "tol": eval_env.scenario.success_tol,
                "collision_voids_success": eval_env.scenario.collision_voids_success}
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        results = evaluate_baselines(eval_env, names, seeds, progress=progress, workers=workers)
    path.write_text(json.dumps({"key": full_key, "results": results}, indent=1, default=float) + "\n")
    return results


def test_summary(eval_env: Any, policy: Any, baselines: dict[str, Any], seeds: Iterable[int], *,
                 reference: str = "dmpc", progress: bool = True, workers: int = 1, **extra: Any) -> dict[str, Any]:
    """The ``eval.json`` of a policy folder: ``policy`` evaluated on the held-out ``seeds`` beside
    the ``baselines`` results on the same seeds, the ratios against ``reference``
    (:func:`compare`; saved as ``vs_<REFERENCE>``), a Markdown table and ``extra`` fields."""
    seeds = [int(s) for s in seeds]
    learned = evaluate(eval_env, policy, seeds, desc="learned policy, test seeds", progress=progress,
                       workers=workers)
    results = {"learned": learned, **baselines}
    return {
        "test_seeds": seeds,
        "success_tol_m": eval_env.scenario.success_tol,
        "collision_voids_success": eval_env.scenario.collision_voids_success,
        **extra,
        "aggregate": {k: v["aggregate"] for k, v in results.items()},
        f"vs_{reference.upper()}": compare(results, reference=reference),
        "table": format_table(results),
        "learned_episodes": learned["episodes"],
    }


def run_summary(cfg: Any, policy: Any, *, reference: str = "dmpc", **extra: Any) -> dict[str, Any]:
    """The ``eval.json`` of a run config ``cfg`` (a :class:`satenv.training.config.RunConfig`):
    :func:`test_summary` of ``policy`` on ``cfg.test_seeds`` with the evaluation env, beside
    ``cfg.eval_baselines`` (cached, :func:`cached_baselines`) — the same for every stack."""
    from satenv.training.envs import make_env

    eval_env = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
    key = {"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs}
    found = cached_baselines(Path(cfg.out_dir) / "baselines_test.json", eval_env, cfg.eval_baselines,
                             cfg.test_seeds, key, progress=cfg.progress, workers=cfg.workers)
    return test_summary(eval_env, policy, found, cfg.test_seeds, reference=reference, progress=cfg.progress,
                        workers=cfg.workers, **extra)


def learning_curve(history: list[dict[str, Any]], expert: dict[str, Any] | None, expert_name: str,
                   path: Path, x_key: str = "labels", x_label: str = "expert labels (agent-steps)") -> None:
    """Success rate, RMSE and total Δv on the evaluation seeds at each entry of ``history``
    (``x_key``: ``"labels"`` for DAgger rounds, ``"step"`` for RL), a scripted reference's as
    dashed lines; skipped without matplotlib."""
    from satenv.render import new_figure  # own canvas: the caller's backend is left alone

    try:
        fig = new_figure((11, 3.2), 100, layout="constrained")
    except ImportError:  # plotting is optional
        return
    labels = [h[x_key] for h in history]
    axes = fig.subplots(1, 3)
    for ax, key, title in zip(axes, ("success_rate", "rmse", "delta_v"),
                              ("success rate", "RMSE [m]", "total Δv [m/s]"), strict=True):
        ax.plot(labels, [h["aggregate"][key] for h in history], "o-", label="learned")
        if expert:
            ax.axhline(expert["aggregate"][key], color="k", ls="--", label=expert_name)
        ax.set_xlabel(x_label)
        ax.set_title(title)
    axes[0].set_ylim(-0.05, 1.05)
    axes[0].legend(loc="lower right")
    fig.savefig(path, dpi=100)
