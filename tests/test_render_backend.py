"""Rendering and the scoreboard's plots leave the user's matplotlib backend and pyplot alone.

Each check runs in a fresh interpreter whose backend the "user" chose (``svg``): env frames,
``plot_trajectory``, the scoreboard's plots, a reproduction's figures; ``render_mode="human"`` without an interactive
backend warns instead of silently showing nothing.
"""

import subprocess
import sys

_CHECK = """
import warnings, matplotlib
matplotlib.use("svg")
import matplotlib.pyplot as plt
import satenv
from satenv.render import plot_trajectory
from satenv.rollout import rollout
from satenv import baselines
env = satenv.make("platoon_v0", render_mode="rgb_array", max_steps=5)
env.reset(seed=0)
frame = env.render()
assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0, frame.shape
env.close()
traj = rollout(satenv.make("platoon_v0", max_steps=5), satenv.baselines.make("zero", satenv.make("platoon_v0")), seed=0)
plot_trajectory(traj, {out!r} + "/traj.png")
human = satenv.make("platoon_v0", render_mode="human", max_steps=5)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    human.reset(seed=0)
    assert human.render() is None
human.close()
assert any("interactive matplotlib backend" in str(w.message) for w in caught), [str(w.message) for w in caught]
from satenv.bench.scoreboard import main as scoreboard
scoreboard(["--scenarios", "platoon-PLF-cw", "--policies", "zero", "--seeds", "0", "--workers", "1",
            "--out", {out!r} + "/board"])
import pathlib
assert list(pathlib.Path({out!r}, "board", "plots").glob("*.png")), "no plots written"
from satenv.bench.reproductions.kannan2022 import plot_scenario
fenv = satenv.make("formation_v0", preset="kannan2022-position", max_steps=5)
assert plot_scenario(rollout(fenv, satenv.baselines.make("zero", fenv), seed=0), "kannan2022-position",
                     pathlib.Path({out!r}, "repro"))
print(matplotlib.get_backend(), plt.get_fignums())
"""


def test_rendering_and_scoreboard_plots_keep_the_backend(tmp_path):
    out = subprocess.run([sys.executable, "-c", _CHECK.format(out=str(tmp_path))], capture_output=True,
                         text=True, env={**__import__("os").environ, "MPLBACKEND": ""}, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "svg []"
