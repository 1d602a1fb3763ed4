"""The segments of a fine-tune run (``run.sh``): each kept final/'s evaluation of the network alone on
the validation seeds, as ``logs/<name>/segments.json`` and a markdown table; its training log
thinned to every 10th row as ``logs/<name>/progress.jsonl``, and its config. ``<name>`` is the
system (the PPO-Lagrangian runs) or ``<system>_reward`` (``METHOD=reward``).

    .venv/bin/python studies/runs/imitation_rl_finetune/summarize.py servicing runs/lag_ft_servicing
    .venv/bin/python studies/runs/imitation_rl_finetune/summarize.py cluster_reward runs/reward_ft_cluster
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

FIELDS = ("episodes", "successes", "collision_episodes", "violation_episodes", "final_error_m", "steps")


def main(name: str, run: Path) -> None:
    out = Path(__file__).parent / "logs" / name
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for kept in sorted((run / "kept").iterdir(), key=lambda p: int(p.name)):
        ev = json.loads((kept / "eval.json").read_text())
        agg = ev["aggregate"].get("learned", ev["aggregate"])
        rows.append({"agent_steps": ev["steps"], "train_wall_s": ev.get("train_wall_s_this_session"),
                     **{k: agg.get(k) for k in FIELDS}, "seeds": ev["test_seeds"]})
    (out / "segments.json").write_text(json.dumps(rows, indent=1) + "\n")
    lines = (run / "progress.jsonl").read_text().splitlines()
    (out / "progress.jsonl").write_text("".join(ln + "\n" for ln in lines[::10]))
    (out / "config.json").write_text((run / "config.json").read_text())
    print("| agent-steps | success | collision episodes | violation episodes | final error [m] | "
          "mean episode length [decisions] | train wall [s] |")
    print("|--:|--:|--:|--:|--:|--:|--:|")
    for r in rows:
        n = r["episodes"]
        print(f"| {r['agent_steps']:,} | {r['successes']}/{n} | {r['collision_episodes']}/{n} | "
              f"{r['violation_episodes']}/{n} | {r['final_error_m']:.1f} | {r['steps']:.1f} | "
              f"{r['train_wall_s']:.0f} |")


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]))
