"""Matplotlib rendering: a 3-D LVLH scene, trajectory plots and animated GIFs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def _pyplot(show: bool):
    import matplotlib

    if not show:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _draw_sphere(ax, center, radius: float, color: str = "grey", alpha: float = 0.15) -> None:
    u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:10j]
    ax.plot_wireframe(center[0] + radius * np.cos(u) * np.sin(v),
                      center[1] + radius * np.sin(u) * np.sin(v),
                      center[2] + radius * np.cos(v), color=color, alpha=alpha, linewidth=0.5)


def draw_scene(ax, scene: dict[str, Any], trails: np.ndarray | None = None) -> None:
    """Draw one scene on a 3-D axis: positions, trails (T, M, 3), targets, spheres, pointing axes."""
    pos = np.asarray(scene["positions"])
    colors = [f"C{i % 10}" for i in range(len(pos))]
    if trails is not None and len(trails) > 1:
        for i in range(pos.shape[0]):
            ax.plot(trails[:, i, 0], trails[:, i, 1], trails[:, i, 2], color=colors[i], lw=1)
    ax.scatter(pos[:, 0], pos[:, 1], pos[:, 2], c=colors, s=30, depthshade=False)
    labels = scene.get("labels")
    if labels is not None:
        for p, name in zip(pos, labels, strict=False):
            ax.text(p[0], p[1], p[2], f" {name}", fontsize=7)
    if scene.get("targets") is not None:
        tg = np.asarray(scene["targets"])
        ax.scatter(tg[:, 0], tg[:, 1], tg[:, 2], marker="x", c=colors[: len(tg)], s=30)
    for center, radius, label in scene.get("spheres", []):
        _draw_sphere(ax, np.asarray(center), float(radius), color="red" if "keep" in label else "grey")
    if scene.get("axes") is not None:  # pointing axes (M, 3), unit vectors
        ax.quiver(pos[:, 0], pos[:, 1], pos[:, 2], *np.asarray(scene["axes"]).T,
                  length=scene.get("axis_length", 3.0), color="k", linewidth=0.8)
    ax.scatter([0], [0], [0], marker="*", c="k", s=60)
    ax.set_xlabel("x radial [m]")
    ax.set_ylabel("y along-track [m]")
    ax.set_zlabel("z normal [m]")
    ax.set_title(scene.get("title", ""))


def render_frame(scene: dict[str, Any], trails: np.ndarray | None, fig=None, show: bool = False):
    """Render a scene to an RGB array ``(H, W, 3)`` uint8 (and show it when ``show``)."""
    plt = _pyplot(show)
    if fig is None:
        fig = plt.figure(figsize=(6, 5), dpi=80)
    fig.clf()
    ax = fig.add_subplot(projection="3d")
    draw_scene(ax, scene, trails)
    fig.canvas.draw()
    frame = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    if show:
        plt.pause(0.001)
    return frame, fig


def plot_trajectory(traj, path: str | Path, title: str | None = None) -> Path:
    """Save a 3-D plot of a :class:`satenv.rollout.Trajectory`'s positions (PNG)."""
    plt = _pyplot(False)
    pos = traj.states[..., :3]
    fig = plt.figure(figsize=(7, 6), dpi=100)
    ax = fig.add_subplot(projection="3d")
    scene = {"positions": pos[-1], "labels": traj.agents, "title": title or traj.env_id}
    draw_scene(ax, scene, pos)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def save_gif(traj, path: str | Path, every: int = 2, fps: int = 10) -> Path:
    """Save an animated GIF of a trajectory's positions (needs ``imageio``: the render extra)."""
    try:
        import imageio.v2 as imageio
    except ImportError as exc:  # pragma: no cover - depends on the extra
        raise ImportError("save_gif needs imageio: pip install 'satenv[render]'") from exc
    pos = traj.states[..., :3]
    frames, fig = [], None
    for k in range(0, len(pos), max(1, int(every))):
        scene = {"positions": pos[k], "title": f"{traj.env_id}  t = {traj.t[k]:.1f} s"}
        frame, fig = render_frame(scene, pos[: k + 1], fig)
        frames.append(frame)
    if fig is not None:
        _pyplot(False).close(fig)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, duration=1.0 / fps)
    return path
