"""The learning curve of an imitation run (``learning_curve.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["plot_curve"]


def total_loss(entry: dict[str, Any]) -> float:
    """A round's loss as one number (the safe loss: the sum of its terms)."""
    loss = entry["loss"]
    return float(sum(loss.values())) if isinstance(loss, dict) else float(loss)


def plot_curve(history: list[dict[str, Any]], path: Path) -> None:
    """Validation success and collision episodes (the network alone, and behind the filter when
    scored) and the fit's loss against the number of labels."""
    from satenv.render import new_figure  # own canvas: the caller's backend is left alone

    try:
        fig = new_figure((13, 3.6), 90, layout="constrained")
    except ImportError:  # plotting is optional
        return
    labels = [h["labels"] for h in history]
    ax = fig.subplots(1, 3)
    ax[0].plot(labels, [h["val"]["success_rate"] for h in history], "o-", label="random starts")
    if all("paper" in h for h in history):
        ax[0].plot(labels, [h["paper"]["success_rate"] for h in history], "s--", label="paper start")
    sh = [(h["labels"], h["shield"]["val"]) for h in history if "shield" in h]
    if sh:
        ax[0].plot([a for a, _ in sh], [v["success_rate"] for _, v in sh], "^-", label="random, +filter")
        ax[1].plot([a for a, _ in sh], [v["collision_episodes"] for _, v in sh], "^-", label="+filter")
    ax[0].set_ylabel("success rate")
    ax[0].legend()
    ax[1].plot(labels, [h["val"]["collision_episodes"] for h in history], "o-", label="network")
    ax[1].set_ylabel(f"collision episodes (of {history[-1]['val']['episodes']})")
    ax[1].legend()
    ax[2].semilogy(labels, [max(total_loss(h), 1e-12) for h in history], "o-")
    ax[2].set_ylabel("fit loss")
    for a in ax:
        a.set_xlabel("labels (agent-steps)")
        a.grid(alpha=0.3)
    last = history[-1]
    fig.suptitle(f"imitation, {last.get('system') or last.get('task') or ''} (validation seeds)")
    fig.savefig(path, dpi=90)
