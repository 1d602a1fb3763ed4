"""Fitting the network on the labels: the DAgger regression (:func:`regress`) and the safe loss
(:func:`fit_safe`), both Adam on shuffled minibatches from the caller's generator.

The safe loss of a row (weights of :class:`SafeLoss`)::

    L = a * |pi(o) - y|^2 + w_int * |pi(o) - F(pi_flown(o))|^2 [intervened rows]
        + w_bar * a * sum_k relu(l_k + m - r_k . pi(o))^2 + w_prior * |pi(o_p) - y_p|^2

``a`` is ``alone_weight`` on rows the network flew alone (1 otherwise); the barrier term is zero
exactly where the filter (tightened by the margin ``m``) would pass the action; the prior term
imitates a batch of an earlier run's labels beside every batch.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["LABEL_COLUMNS", "SafeLoss", "fit_safe", "inputs", "regress"]

LABEL_COLUMNS = {"expert": "act", "filtered": "label", "self": "filtered", "teacher": "label"}
"""The row column each ``label`` option imitates."""


class SafeLoss(NamedTuple):
    """The terms and weights of the safe loss (module docstring)."""

    label: str = "filtered"
    w_int: float = 1.0
    w_bar: float = 10.0
    bar_margin: float = 0.02
    alone_weight: float = 1.0
    prior_weight: float = 1.0
    imitation_space: str = "flown"
    prior_space: str = ""


def regress(actor: Any, x: np.ndarray, y: np.ndarray, *, lr: float, epochs: int, batch_size: int,
            generator: Any, weight_decay: float = 0.0) -> float:
    """Adam on the mean squared error of ``actor(x)`` against ``y`` (``x`` already normalised),
    shuffled minibatches from ``generator``; returns the last epoch's mean loss."""
    import torch

    xt, yt = torch.as_tensor(x), torch.as_tensor(y, dtype=torch.float32)
    opt = torch.optim.Adam(actor.parameters(), lr=lr, weight_decay=weight_decay)
    actor.train()
    loss_sum = 0.0
    for _ in range(epochs):
        loss_sum = 0.0
        for idx in torch.randperm(len(xt), generator=generator).split(batch_size):
            loss = torch.mean((actor(xt[idx]) - yt[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            loss_sum += loss.item() * len(idx)
    actor.eval()
    return loss_sum / len(xt)


def inputs(policy: Any, obs: np.ndarray) -> Any:
    """The actor's input for raw observations (the policy's features, then its normaliser)."""
    import torch

    return torch.as_tensor(policy.network_input(obs.astype(np.float64)), dtype=torch.float32)


def fit_safe(policy: Any, data: dict[str, np.ndarray], loss: SafeLoss, *, lr: float, epochs: int,
             batch_size: int, norm_mode: bool, generator: Any,
             prior: dict[str, np.ndarray] | None = None) -> dict[str, float]:
    """Adam on the safe loss (module docstring; ``policy.actor`` in place); the last epoch's
    mean terms. ``data``: rows of :func:`satenv.training.imitation.collect.collect_episode`'s safe
    flights; ``prior`` (``obs``, ``act``): an earlier run's labels."""
    import torch

    from satenv.training.imitation.barrier import barrier_hinge, env_action, terminal_affine

    x = inputs(policy, data["obs"])
    y = torch.as_tensor(data[LABEL_COLUMNS[loss.label]], dtype=torch.float32).clamp(-1, 1)
    power = float(policy.action_map.power) if policy.action_map is not None else 1.0
    offset, slope = (torch.as_tensor(v, dtype=torch.float32) for v in terminal_affine(policy, data["obs"], y.shape[-1]))
    f = torch.as_tensor(data["filtered"], dtype=torch.float32)
    mask = torch.as_tensor(data["intervened"], dtype=torch.float32)
    rows, lower = torch.as_tensor(data["rows"]), torch.as_tensor(data["lower"])
    alone = data.get("alone", np.zeros(len(data["obs"]), dtype=bool))
    w = 1.0 + (loss.alone_weight - 1.0) * torch.as_tensor(alone, dtype=torch.float32)
    if prior is not None:
        px = inputs(policy, prior["obs"])
        py = torch.as_tensor(prior["act"], dtype=torch.float32).clamp(-1, 1)
        p_off, p_slope = (torch.as_tensor(v, dtype=torch.float32)
                          for v in terminal_affine(policy, prior["obs"], py.shape[-1]))
    on_flown = loss.imitation_space == "flown"
    prior_on_flown = (loss.prior_space or loss.imitation_space) == "flown"
    actor = policy.actor
    opt = torch.optim.Adam(actor.parameters(), lr=lr)
    actor.train()
    terms: dict[str, float] = {}
    for _ in range(epochs):
        sums = np.zeros(4)
        for idx in torch.randperm(len(x), generator=generator).split(batch_size):
            out = env_action(actor(x[idx]), power)
            a = offset[idx] + slope[idx] * out
            imit = (w[idx] * (((a if on_flown else out) - y[idx]) ** 2).sum(-1)).mean()
            inter = (mask[idx] * ((a - f[idx]) ** 2).sum(-1)).mean()
            bar = (w[idx] * barrier_hinge(a, rows[idx], lower[idx], loss.bar_margin, norm_mode)).mean()
            total = imit + loss.w_int * inter + loss.w_bar * bar
            pri = torch.zeros(())
            if prior is not None:
                j = torch.randint(len(px), (len(idx),), generator=generator)
                pout = env_action(actor(px[j]), power)
                pa = p_off[j] + p_slope[j] * pout if prior_on_flown else pout
                pri = ((pa - py[j]) ** 2).sum(-1).mean()
                total = total + loss.prior_weight * pri
            opt.zero_grad()
            total.backward()
            opt.step()
            sums += np.array([imit.item(), inter.item(), bar.item(), pri.item()]) * len(idx)
        terms = dict(zip(("imitation", "intervention", "barrier", "prior"), (sums / len(x)).tolist(), strict=True))
    actor.eval()
    return terms
