"""The lean learner's networks: MLPs over ``(rows, agents, features)`` with shared or per-agent weights.

:class:`AgentMLP` holds ``K`` copies of one MLP as stacked tensors (``K = 1``: every agent shares the
weights; ``K = M``: each agent has its own) and runs all agents of a batch in one matmul per layer
(``baddbmm`` over the agent axis), never a Python loop over agents. :class:`ActorCritic` is the
PPO pair: a Gaussian actor whose mean is ``tanh`` of the last layer (so the deterministic action
is inside the ``[-1, 1]`` thrust box) with a state-independent ``log_std``, and a critic.
:func:`export_actor` copies one agent's actor into the folder format's
:class:`satenv.training.actor.MLPActor` (``squash=True``): the saved policy is that mean.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from satenv.training.actor import MLPActor

__all__ = ["ActorCritic", "AgentMLP", "export_actor", "tanh"]

HIDDEN_GAIN = math.sqrt(2.0)
"""Orthogonal initialisation gain of the hidden layers (CleanRL's PPO)."""
ACTOR_HEAD_GAIN = 0.01
"""Gain of the actor's last layer: the untrained mean is close to zero thrust."""
CRITIC_HEAD_GAIN = 1.0


class _Tanh(torch.autograd.Function):
    """``tanh`` with numpy's forward and torch's ``tanh_backward`` from the saved output: the same
    function (to float32 rounding), measured 4x faster forward and backward than ``torch.tanh`` on
    one thread here (torch's CPU kernel took as long as the layer's matmul)."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor) -> torch.Tensor:
        y = torch.from_numpy(np.tanh(x.detach().numpy()))
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


tanh = _Tanh.apply
"""The activation of every lean network (:class:`_Tanh`)."""


class AgentMLP(nn.Module):
    """``x (n, M, in) -> (n, M, out)``: a tanh MLP of hidden sizes ``hidden``, ``copies`` weight sets
    (1: shared by every agent; ``M``: one per agent)."""

    def __init__(self, n_in: int, hidden: tuple[int, ...], n_out: int, copies: int, head_gain: float) -> None:
        super().__init__()
        widths = [n_in, *hidden, n_out]
        self.copies = copies
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for i, (a, b) in enumerate(zip(widths, widths[1:], strict=False)):
            w = torch.empty(copies, b, a)
            for k in range(copies):
                nn.init.orthogonal_(w[k], HIDDEN_GAIN if i < len(widths) - 2 else head_gain)
            self.weights.append(nn.Parameter(w.transpose(1, 2).contiguous()))   # (K, in, out)
            self.biases.append(nn.Parameter(torch.zeros(copies, 1, b)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last = len(self.weights) - 1
        if self.copies == 1:
            for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
                x = torch.addmm(b[0], x.reshape(-1, x.shape[-1]), w[0]).reshape(*x.shape[:-1], -1)
                x = tanh(x) if i < last else x
            return x
        x = x.transpose(0, 1)                          # (M, n, in): one batched matmul per layer
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = torch.baddbmm(b, x, w)
            x = tanh(x) if i < last else x
        return x.transpose(0, 1)


class ActorCritic(nn.Module):
    """The PPO actor (Gaussian, mean ``tanh(mlp(obs))``, ``log_std`` per copy) and critic.

    ``copies``: 1 (parameters shared by every agent) or ``M`` (per-agent parameters);
    ``critic_in``: the critic's input width (the observation's, or state + observation for a
    centralised critic).
    """

    def __init__(self, obs_dim: int, act_dim: int, critic_in: int, hidden: tuple[int, ...], copies: int,
                 init_std: float) -> None:
        super().__init__()
        self.hidden = tuple(hidden)
        self.actor = AgentMLP(obs_dim, self.hidden, act_dim, copies, ACTOR_HEAD_GAIN)
        self.critic = AgentMLP(critic_in, self.hidden, 1, copies, CRITIC_HEAD_GAIN)
        self.log_std = nn.Parameter(torch.full((copies, act_dim), math.log(init_std)))

    def mean(self, obs: torch.Tensor) -> torch.Tensor:
        """The deterministic action ``(n, M, act_dim)`` in ``[-1, 1]``."""
        return tanh(self.actor(obs))

    def value(self, critic_obs: torch.Tensor) -> torch.Tensor:
        """``V (n, M)``."""
        return self.critic(critic_obs)[..., 0]


def export_actor(net: ActorCritic, agent: int = 0) -> MLPActor:
    """Agent ``agent``'s actor (its weight copy; the shared one when the weights are shared) as an
    :class:`MLPActor` with ``squash=True`` (a copy of the weights)."""
    k = agent if net.actor.copies > 1 else 0
    obs_dim, act_dim = net.actor.weights[0].shape[1], net.actor.weights[-1].shape[2]
    actor = MLPActor(int(obs_dim), int(act_dim), list(net.hidden), "tanh", squash=True)
    pairs = [(w[k].detach().T, b[k, 0].detach()) for w, b in zip(net.actor.weights, net.actor.biases, strict=True)]
    return actor.copy_linear_weights(pairs)
