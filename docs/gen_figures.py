"""Regenerate the site's env pictures and dynamics error tables (committed under docs/assets/).

Usage:  python docs/gen_figures.py [--only platoon_v0,formation_v0] [--skip-dynamics]

For every env in ``EPISODES``: one episode (seed 0) under its baseline, saved with
``satenv.render.plot_trajectory`` as ``docs/assets/envs/<env_id>.png``; the caption (baseline,
episode length, the ``satenv.metrics.summary`` numbers) goes to ``docs/assets/envs/figures.json``,
which the pages render (``docs/hooks.py``). Then ``tests/report_dynamics_errors.py`` is run and its
markdown tables are saved as ``docs/assets/generated/dynamics_errors.md`` (the dynamics page
includes them). Takes a few minutes on 2 cores (the servicing NMPC dominates).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

EPISODES: dict[str, dict] = {
    "platoon_v0": {"baseline": "dmpc", "env_kwargs": {}},
    "cluster_v0": {"baseline": "apf", "env_kwargs": {}},
    "servicing_v0": {"baseline": "nmpc", "env_kwargs": {"max_steps": 400},
                     "note": "first 40 s of the 120 s episode (max_steps=400, the first waypoint phase)"},
    "formation_v0": {"baseline": "cgmres", "env_kwargs": {}},
}
"""env id -> the baseline that flies its picture, the env kwargs, and a note for the caption."""


def env_figure(env_id: str, spec: dict, out_dir: Path) -> dict:
    """Run one seed-0 episode of ``env_id`` under its baseline; save the PNG; return the caption."""
    import satenv
    from satenv import baselines, metrics
    from satenv.render import plot_trajectory
    from satenv.rollout import rollout

    env = satenv.make(env_id, **spec["env_kwargs"])
    policy = baselines.make(spec["baseline"], env)
    start = time.perf_counter()
    traj = rollout(env, policy, seed=0)
    wall = time.perf_counter() - start
    s = metrics.summary(traj)
    image = plot_trajectory(traj, out_dir / f"{env_id}.png",
                            title=f"{env_id} ({env.scenario.name}) under {spec['baseline']}")
    kwargs = ", ".join(f"{k}={v!r}" for k, v in spec["env_kwargs"].items())
    caption = (f"`satenv.make({env_id!r}{', ' + kwargs if kwargs else ''})` under "
               f"`satenv.baselines.make({spec['baseline']!r}, env)`, seed 0: {len(traj.t) - 1} steps "
               f"({traj.t[-1]:.4g} s); success {s['success']}, final error "
               f"{s['final_error_m']:.3g} m, Δv {s['delta_v']:.4g} m/s, collision flags "
               f"{s['collisions']}. Dots: final positions, lines: trails, in the LVLH frame (star: origin).")
    if spec.get("note"):
        caption += f" Shortened: {spec['note']}."
    print(f"{env_id}: {image.relative_to(ROOT)} ({wall:.1f} s)")
    return {"image": image.name, "caption": caption}


def dynamics_errors(path: Path) -> None:
    """Save the markdown tables printed by ``tests/report_dynamics_errors.py``."""
    out = subprocess.run([sys.executable, str(ROOT / "tests" / "report_dynamics_errors.py")],
                         check=True, capture_output=True, text=True, cwd=ROOT)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(out.stdout)
    print(f"dynamics errors: {path.relative_to(ROOT)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=None, help="comma-separated env ids (default: all)")
    parser.add_argument("--skip-dynamics", action="store_true", help="skip the dynamics error tables")
    args = parser.parse_args(argv)
    only = args.only.split(",") if args.only else list(EPISODES)
    unknown = sorted(set(only) - set(EPISODES))
    if unknown:
        parser.error(f"--only: unknown env ids {unknown}; known: {sorted(EPISODES)}")
    out_dir = DOCS / "assets" / "envs"
    index_path = out_dir / "figures.json"
    index = json.loads(index_path.read_text()) if index_path.exists() else {}
    for env_id in only:
        index[env_id] = env_figure(env_id, EPISODES[env_id], out_dir)
        index_path.write_text(json.dumps(dict(sorted(index.items())), indent=1, ensure_ascii=False) + "\n")
    if not args.skip_dynamics:
        dynamics_errors(DOCS / "assets" / "generated" / "dynamics_errors.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
