"""Evaluate policies (learned or scripted) on fixed seeds with the PettingZoo env and ``satenv.rollout``.

The same path the scoreboard uses: ``rollout(env, policy, seed=s)`` then
``satenv.metrics.summary``. :func:`compare` adds the learned-vs-reference ratios of the issue's
targets (tracking RMSE and total delta-v relative to the DMPC on the same seeds).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

import baselines
from satenv import metrics
from satenv.rollout import rollout

__all__ = ["AUTO", "evaluate", "make_baseline", "baseline_names", "compare", "format_table",
           "evaluate_baselines", "cached_baselines", "test_summary", "run_summary", "learning_curve"]

AUTO = "auto"
"""``eval_baselines`` entry meaning: ``zero`` plus the cheap scripted controllers that support
the env (no per-decision NLP: ``dmpc`` on platoon, ``apf`` on cluster)."""


def make_baseline(name: str, env: Any):
    """``baselines.make(name, env)`` (a name of ``baselines.BASELINES``)."""
    return baselines.make(name, env)


def baseline_names(env: Any, names: Iterable[str]) -> list[str]:
    """``names`` with ``"auto"`` expanded to ``zero`` and the other baselines of
    ``baselines.supporting(env, cheap=True)`` except ``random`` (:data:`AUTO`), duplicates dropped.

    The NLP baselines (nmpc, tube_rdmpc, cgmres: 0.5-16 min per episode) run only when named.
    """
    out: list[str] = []
    for name in names:
        auto = [n for n in baselines.supporting(env, cheap=True) if n != "random"]
        out += auto if name == AUTO else [name]
    return list(dict.fromkeys(out))


def evaluate(env: Any, policy: Any, seeds: Iterable[int]) -> dict[str, Any]:
    """Roll ``policy`` out once per seed; returns per-episode summaries and their aggregate.

    Success is the scenario's rule (``satenv.metrics.summary``: ``success_tol``,
    ``collision_voids_success`` of ``env.scenario``).

    Aggregate keys: ``success_rate``, ``collision_episodes`` (episodes with >= 1 collision
    flag), ``rmse``/``delta_v``/``final_error_m``/``violations``/``min_separation_m``/
    ``compute_ms_per_decision`` (means over episodes; ``min_separation_m`` is the minimum),
    ``terminated_rate``, ``episodes``.
    """
    episodes = []
    for seed in seeds:
        traj = rollout(env, policy, seed=int(seed))
        s = metrics.summary(traj)
        s["seed"] = int(seed)
        episodes.append(s)
    return {"aggregate": aggregate(episodes), "episodes": episodes}


def aggregate(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    def mean(key):
        return float(np.mean([e[key] for e in episodes])) if episodes else float("nan")

    return {
        "episodes": len(episodes),
        "success_rate": mean("success"),
        "collision_episodes": int(sum(e["collisions"] > 0 for e in episodes)),
        "terminated_rate": mean("terminated"),
        "rmse": mean("rmse"),
        "delta_v": mean("delta_v"),
        "final_error_m": mean("final_error_m"),
        "violations": mean("violations"),
        "min_separation_m": float(min(e["min_separation_m"] for e in episodes)) if episodes else float("nan"),
        "steps": mean("steps"),
        "compute_ms_per_decision": mean("compute_ms_per_decision"),
    }


def compare(results: dict[str, dict[str, Any]], learned: str = "learned",
            reference: str = "dmpc") -> dict[str, Any]:
    """Ratios learned/reference of mean RMSE and mean delta-v on the seeds both were evaluated on.

    ``all``: over every common seed; ``reference_ok``: over the common seeds where the reference
    episode ran to truncation without a collision (a terminated reference episode has a shorter
    window). A reference evaluated on a subset of the learned policy's seeds (an expensive
    controller) is compared on that subset (``seeds`` says how many).
    """
    if learned not in results or reference not in results:
        return {}
    by_seed = {e["seed"]: e for e in results[learned]["episodes"]}
    pairs = [(by_seed[e["seed"]], e) for e in results[reference]["episodes"] if e["seed"] in by_seed]
    if not pairs:
        raise ValueError(f"compare() needs {learned!r} and {reference!r} evaluated on common seeds")
    out: dict[str, Any] = {"reference": reference}
    ok = [(le, re) for le, re in pairs if re["collisions"] == 0 and not re["terminated"]]
    for label, sel in (("all", pairs), ("reference_ok", ok)):
        if not sel:
            out[label] = {"seeds": 0}
            continue
        le, re = [p[0] for p in sel], [p[1] for p in sel]
        out[label] = {
            "seeds": len(sel),
            "rmse_ratio": float(np.mean([e["rmse"] for e in le]) / np.mean([e["rmse"] for e in re])),
            "delta_v_ratio": float(np.mean([e["delta_v"] for e in le]) / np.mean([e["delta_v"] for e in re])),
            "learned_success_rate": float(np.mean([e["success"] for e in le])),
            "reference_success_rate": float(np.mean([e["success"] for e in re])),
        }
    return out


def format_table(results: dict[str, dict[str, Any]]) -> str:
    """A Markdown table of the aggregates, one row per policy."""
    cols = ["episodes", "success_rate", "collision_episodes", "terminated_rate", "rmse", "delta_v",
            "final_error_m", "violations", "min_separation_m", "compute_ms_per_decision"]
    head = "| policy | " + " | ".join(cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    for name, res in results.items():
        agg = res["aggregate"]
        cells = [f"{agg[c]:.3g}" if isinstance(agg[c], float) else str(agg[c]) for c in cols]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def evaluate_baselines(env: Any, names: Iterable[str], seeds: Iterable[int]) -> dict[str, Any]:
    """Evaluate the named registered baselines (``"auto"``: :func:`baseline_names`).

    A named baseline that cannot control ``env`` (``supports(env)`` False) is skipped with a
    warning; an unknown name raises :class:`baselines.BaselineError`.
    """
    seeds = list(seeds)
    out = {}
    for name in baseline_names(env, names):
        cls = baselines.get(name)
        if not cls.supports(env):
            warnings.warn(f"baseline {name!r} cannot control this env (it supports "
                          f"{cls.supported()}); skipped", stacklevel=2)
            continue
        out[name] = evaluate(env, baselines.make(name, env), seeds)
    return out


def cached_baselines(path: Path, eval_env: Any, names: Iterable[str], seeds: Iterable[int],
                     key: dict[str, Any]) -> dict[str, Any]:
    """:func:`evaluate_baselines`, cached in the JSON file ``path`` under ``key`` (plus the
    names, seeds and the scenario's success rule): a run that resumes does not re-run them."""
    names, seeds = list(names), [int(s) for s in seeds]
    full_key = {**key, "seeds": seeds, "baselines": names, "tol": eval_env.scenario.success_tol,
                "collision_voids_success": eval_env.scenario.collision_voids_success}
    if path.is_file():
        cached = json.loads(path.read_text())
        if cached.get("key") == full_key:
            return cached["results"]
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        results = evaluate_baselines(eval_env, names, seeds)
    path.write_text(json.dumps({"key": full_key, "results": results}, indent=1, default=float) + "\n")
    return results


def test_summary(eval_env: Any, policy: Any, baselines: dict[str, Any], seeds: Iterable[int], *,
                 reference: str = "dmpc", **extra: Any) -> dict[str, Any]:
    """The ``eval.json`` of a policy folder: ``policy`` evaluated on the held-out ``seeds`` beside
    the ``baselines`` results on the same seeds, the ratios against ``reference``
    (:func:`compare`; saved as ``vs_<REFERENCE>``), a Markdown table and ``extra`` fields."""
    seeds = [int(s) for s in seeds]
    learned = evaluate(eval_env, policy, seeds)
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
    """The ``eval.json`` of a run config ``cfg`` (a :class:`training.config.RunConfig`):
    :func:`test_summary` of ``policy`` on ``cfg.test_seeds`` with the evaluation env, beside
    ``cfg.eval_baselines`` (cached, :func:`cached_baselines`) — the same for every stack."""
    from training.envs import make_env

    eval_env = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
    key = {"env_id": cfg.env_id, "eval_env_kwargs": cfg.resolved_eval_env_kwargs}
    found = cached_baselines(Path(cfg.out_dir) / "baselines_test.json", eval_env, cfg.eval_baselines,
                             cfg.test_seeds, key)
    return test_summary(eval_env, policy, found, cfg.test_seeds, reference=reference, **extra)


def learning_curve(history: list[dict[str, Any]], expert: dict[str, Any] | None, expert_name: str,
                   path: Path, x_key: str = "labels", x_label: str = "expert labels (agent-steps)") -> None:
    """Success rate, RMSE and total Δv on the evaluation seeds at each entry of ``history``
    (``x_key``: ``"labels"`` for DAgger rounds, ``"step"`` for RL), a scripted reference's as
    dashed lines; skipped without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # plotting is optional (the render extra)
        return
    labels = [h[x_key] for h in history]
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.2))
    for ax, key, title in zip(axes, ("success_rate", "rmse", "delta_v"), ("success rate", "RMSE", "total Δv"),
                              strict=True):
        ax.plot(labels, [h["aggregate"][key] for h in history], "o-", label="learned")
        if expert:
            ax.axhline(expert["aggregate"][key], color="k", ls="--", label=expert_name)
        ax.set_xlabel(x_label)
        ax.set_title(title)
    axes[0].set_ylim(-0.05, 1.05)
    axes[0].legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
