"""Matplotlib rendering: a 3-D LVLH scene, trajectory plots and animated GIFs.

Every figure that is saved or returned as pixels is a :class:`matplotlib.figure.Figure` with its
own Agg canvas (:func:`new_figure`): the user's matplotlib backend is never changed and no figure
is left registered in pyplot. Only ``render_mode="human"`` opens a pyplot window, and only under an
interactive backend; without one (a headless machine, ``Agg``, a notebook's inline backend) it
warns once and draws off-screen.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["close_figure", "draw_scene", "new_figure", "plot_trajectory", "render_frame", "save_gif"]


def new_figure(figsize: tuple[float, float] = (6.4, 4.8), dpi: float = 100, **kwargs: Any):
    """A :class:`matplotlib.figure.Figure` on its own Agg canvas: draw, ``savefig`` or read its
    pixels without pyplot (the backend stays what the user chose, nothing is registered in pyplot).
    ``kwargs`` go to ``Figure`` (e.g. ``layout="constrained"``)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def close_figure(fig) -> None:
    """Release ``fig``: closes its window when pyplot manages it (``render_mode="human"``)."""
    if fig is not None and getattr(fig.canvas, "manager", None) is not None:
        import matplotlib.pyplot as plt

        plt.close(fig)


def _interactive_backend() -> str | None:
    """The current backend's name when it can show a window, else ``None``."""
    import matplotlib

    name = matplotlib.get_backend()
    try:
        from matplotlib.backends import BackendFilter, backend_registry

        interactive = backend_registry.list_builtin(BackendFilter.INTERACTIVE)
    except ImportError:  # matplotlib < 3.9
        from matplotlib import rcsetup

        interactive = rcsetup.interactive_bk
    return name if name.lower() in {b.lower() for b in interactive} else None


def _window_figure(figsize: tuple[float, float], dpi: float):
    """A pyplot figure (a window) under an interactive backend; else a warning and an off-screen one."""
    if _interactive_backend() is None:
        import matplotlib

        warnings.warn(f"render_mode='human' needs an interactive matplotlib backend to open a window; "
                      f"the backend is {matplotlib.get_backend()!r} (headless?), so nothing is shown. "
                      f"Use render_mode='rgb_array' for frames, or select a GUI backend "
                      f"(e.g. MPLBACKEND=TkAgg) on a machine with a display.", UserWarning, stacklevel=4)
        return new_figure(figsize, dpi)
    import matplotlib.pyplot as plt

    return plt.figure(figsize=figsize, dpi=dpi)


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
    """Render a scene to an RGB array ``(H, W, 3)`` uint8 and the figure to pass back next time.

    ``show`` (``render_mode="human"``) draws in a window under an interactive backend; without
    one it warns (on the first frame) and draws off-screen."""
    if fig is None:
        fig = _window_figure((6, 5), 80) if show else new_figure((6, 5), 80)
    fig.clf()
    ax = fig.add_subplot(projection="3d")
    draw_scene(ax, scene, trails)
    fig.canvas.draw()
    frame = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    if show and getattr(fig.canvas, "manager", None) is not None:
        import matplotlib.pyplot as plt

        plt.pause(0.001)
    return frame, fig


def plot_trajectory(traj, path: str | Path, title: str | None = None) -> Path:
    """Save a 3-D plot of a :class:`satenv.rollout.Trajectory`'s positions (PNG)."""
    pos = traj.states[..., :3]
    fig = new_figure((7, 6), 100)
    ax = fig.add_subplot(projection="3d")
    scene = {"positions": pos[-1], "labels": traj.agents, "title": title or traj.env_id}
    draw_scene(ax, scene, pos)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, bbox_inches="tight")
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
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, duration=1.0 / fps)
    return path
