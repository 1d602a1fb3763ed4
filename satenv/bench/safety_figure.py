"""The docs figure of one filtered episode (``docs/assets/safety_episode.png``).

A shipped learned policy on a held-out seed of its scenario, with and without the safety filter
(``satenv.make(..., safety_filter=True)``): the nearest-body distances of both runs against the
safety distances, and where the filter intervened (agent, time, binding constraint, ``|du|``).

    nice -n 10 python -m satenv.bench.safety_figure --out docs/assets/safety_episode.png
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from satenv.tasks import SEED_SPLITS

POLICY = "cluster_li2022_dagger"
SEED = SEED_SPLITS["test"].start
"""The episode's seed: the first of the test split."""


def episode(policy: Any, env_kwargs: dict[str, Any], filtered: bool, seed: int) -> dict[str, np.ndarray]:
    """Per-step arrays of one cluster_v0 episode: pair / obstacle distances ``(T, M)`` and, when
    filtered, the record (``intervened``, ``delta``, ``active``)."""
    import satenv

    env = satenv.make("cluster_v0", safety_filter=filtered, **env_kwargs)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    rows: dict[str, list] = {k: [] for k in ("pair", "obstacle", "target", "intervened", "delta", "active")}
    while env.agents:
        obs, _, _, _, infos = env.step(policy.act(obs))
        per = [infos[a] for a in env.possible_agents]
        rows["pair"].append([i["pair_distance"] for i in per])
        rows["obstacle"].append([i["obstacle_distance"] for i in per])
        rows["target"].append([i["target_distance"] for i in per])
        if filtered:
            rows["intervened"].append([i["safety_intervened"] for i in per])
            rows["delta"].append([i["safety_delta"] for i in per])
            rows["active"].append([i["safety_active"] for i in per])
    out = {k: np.array(v) for k, v in rows.items() if v}
    out["dt"] = float(env.scenario.dt)
    out["limits"] = (env.scenario.pair_distance, env.scenario.obstacle_distance, env.scenario.target_distance)
    return out


def plot(out: str | Path, name: str = POLICY, seed: int = SEED) -> dict[str, Any]:
    from satenv import training
    from satenv.bench.scoreboard.registry import SHIPPED_POLICY_DIR
    from satenv.render import new_figure
    from satenv.training.trust import read_json

    folder = SHIPPED_POLICY_DIR / name
    kwargs = dict(read_json(folder, "env.json")["eval_env_kwargs"])
    policy = training.load(folder, shielded=False)
    raw, safe = episode(policy, kwargs, False, seed), episode(policy, kwargs, True, seed)
    fig = new_figure(figsize=(8.0, 6.4), layout="constrained")
    (ax1, ax2) = fig.subplots(2, 1, sharex=True)
    colors = {"pair": "tab:blue", "obstacle": "tab:red"}
    for key, limit in zip(("pair", "obstacle"), safe["limits"][:2], strict=True):
        for run, style, label in ((raw, ":", "unfiltered"), (safe, "-", "filtered")):
            t = np.arange(1, len(run[key]) + 1) * run["dt"]
            ax1.plot(t, run[key].min(axis=1), style, color=colors[key], label=f"nearest {key}, {label}")
        ax1.axhline(limit, color=colors[key], lw=0.8, ls="--")
    ax1.set_ylabel("distance [m]")
    ax1.set_ylim(0, 1500)
    ax1.legend(fontsize=8, ncol=2, loc="upper right")
    ax1.set_title(f"trained:{name}, cluster_v0 (li2022 case 1, randomised), seed {seed}; "
                  "dashed: safety distances", fontsize=9)
    t = np.arange(1, len(safe["delta"]) + 1) * safe["dt"]
    names = sorted({a for a in safe["active"].ravel() if a})
    for k, kind in enumerate(names):
        b, i = np.nonzero(safe["active"] == kind)
        ax2.scatter(t[b], i + 1, s=10 + 60 * safe["delta"][b, i], label=kind, color=f"C{k + 2}", alpha=0.7)
    ax2.set_ylabel("satellite (marker size ~ |du|)")
    ax2.set_xlabel("time [s]")
    ax2.set_yticks(range(1, safe["delta"].shape[1] + 1))
    ax2.legend(fontsize=8, title="binding constraint", title_fontsize=8, loc="upper right")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return {"steps": [len(raw["pair"]), len(safe["pair"])],
            "collision_unfiltered": bool((raw["pair"] < raw["limits"][0]).any()
                                         | (raw["obstacle"] < raw["limits"][1]).any()
                                         | (raw["target"] < raw["limits"][2]).any()),
            "collision_filtered": bool((safe["pair"] < safe["limits"][0]).any()
                                       | (safe["obstacle"] < safe["limits"][1]).any()
                                       | (safe["target"] < safe["limits"][2]).any()),
            "interventions": int(safe["intervened"].sum())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m satenv.bench.safety_figure", description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs/assets/safety_episode.png")
    p.add_argument("--seed", type=int, default=SEED)
    args = p.parse_args(argv)
    print(plot(args.out, seed=args.seed))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
