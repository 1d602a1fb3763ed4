"""The lean learner's networks: MLPs over ``(rows, agents, features)`` with shared or per-agent weights.

:class:`AgentMLP` holds ``K`` copies of one MLP as stacked tensors (``K = 1``: every agent shares the
weights; ``K = M``: each agent has its own) and runs all agents of a batch in one matmul per layer
(``baddbmm`` over the agent axis), never a Python loop over agents. :class:`ActorCritic` is the
PPO pair: a Gaussian actor whose mean is ``tanh`` of the last layer (so the deterministic action
is inside the ``[-1, 1]`` thrust box) with a state-independent ``log_std``, and a critic. The hidden
layers are ``tanh`` (:data:`ACTIVATIONS`: ``relu`` for an actor seeded from a ReLU policy folder).
:func:`export_actor` copies one agent's actor into the folder format's
:class:`satenv.training.actor.MLPActor` (``squash=True``): the saved policy is that mean.

The learner's hot path runs without autograd: every parameter of an :class:`ActorCritic` is a view
of one flat float32 buffer (``net.flat``), :class:`FlatArrays` lays numpy views of the same layout
over it (or over a gradient buffer), and :func:`mlp_forward` / :func:`mlp_backward` are the MLP's
hand-written forward and backward on numpy float32 arrays (the same function as the torch modules;
tests/test_lean_nets.py checks them against autograd): products by numpy's BLAS, or by torch's
oneDNN linear for large batches of shared weights (:data:`LINEAR`). :func:`adam_step` is torch's
Adam over the flat buffers. Measured on the lean learner's minibatches (4,096 agent-steps, 64-64),
autograd and the per-parameter optimizer spent more time in dispatch and small-tensor overhead
than in matmuls.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np
import torch
from torch import nn

from satenv.training.actor import MLPActor

__all__ = ["ACTIVATIONS", "ActorCritic", "AgentMLP", "FlatArrays", "adam_step", "export_actor", "from_copies",
           "mlp_backward", "mlp_forward", "scratch", "tanh", "to_copies"]

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
"""The lean networks' tanh (:class:`_Tanh`): every critic's hidden activation, and the actors' but a
ReLU-seeded one's (:data:`ACTIVATIONS`)."""


def _relu(x: torch.Tensor) -> torch.Tensor:
    return torch.relu(x)


ACTIVATIONS = {"tanh": tanh, "relu": _relu}
"""The hidden activations the lean networks (torch and :func:`mlp_forward`) implement."""


class AgentMLP(nn.Module):
    """``x (n, M, in) -> (n, M, out)``: an MLP of hidden sizes ``hidden`` and hidden activation
    ``activation`` (:data:`ACTIVATIONS`), ``copies`` weight sets (1: shared by every agent; ``M``: one
    per agent)."""

    def __init__(self, n_in: int, hidden: tuple[int, ...], n_out: int, copies: int, head_gain: float,
                 activation: str = "tanh") -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}")
        widths = [n_in, *hidden, n_out]
        self.copies, self.activation = copies, activation
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for i, (a, b) in enumerate(zip(widths, widths[1:], strict=False)):
            w = torch.empty(copies, b, a)
            for k in range(copies):
                nn.init.orthogonal_(w[k], HIDDEN_GAIN if i < len(widths) - 2 else head_gain)
            self.weights.append(nn.Parameter(w.transpose(1, 2).contiguous()))   # (K, in, out)
            self.biases.append(nn.Parameter(torch.zeros(copies, 1, b)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last, act = len(self.weights) - 1, ACTIVATIONS[self.activation]
        if self.copies == 1:
            for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
                x = torch.addmm(b[0], x.reshape(-1, x.shape[-1]), w[0]).reshape(*x.shape[:-1], -1)
                x = act(x) if i < last else x
            return x
        x = x.transpose(0, 1)                          # (M, n, in): one batched matmul per layer
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = torch.baddbmm(b, x, w)
            x = act(x) if i < last else x
        return x.transpose(0, 1)


class ActorCritic(nn.Module):
    """The PPO actor (Gaussian, mean ``tanh(mlp(obs))``, ``log_std`` per copy) and critic.

    ``copies``: 1 (parameters shared by every agent) or ``M`` (per-agent parameters);
    ``critic_in``: the critic's input width (the observation's, or state + observation for a
    centralised critic); ``actor_hidden`` / ``actor_activation``: the actor's own layout (default:
    the critic's ``hidden``, ``tanh``).
    """

    def __init__(self, obs_dim: int, act_dim: int, critic_in: int, hidden: tuple[int, ...], copies: int,
                 init_std: float, actor_hidden: tuple[int, ...] | None = None,
                 actor_activation: str = "tanh") -> None:
        super().__init__()
        self.hidden = tuple(hidden)
        self.actor_hidden = self.hidden if actor_hidden is None else tuple(actor_hidden)
        self.actor = AgentMLP(obs_dim, self.actor_hidden, act_dim, copies, ACTOR_HEAD_GAIN, actor_activation)
        self.critic = AgentMLP(critic_in, self.hidden, 1, copies, CRITIC_HEAD_GAIN)
        self.log_std = nn.Parameter(torch.full((copies, act_dim), math.log(init_std)))
        self.flat = _flatten(self)
        """One float32 buffer behind every parameter (each a view of it; not in the state dict)."""

    def mean(self, obs: torch.Tensor) -> torch.Tensor:
        """The deterministic action ``(n, M, act_dim)`` in ``[-1, 1]``."""
        return tanh(self.actor(obs))

    def value(self, critic_obs: torch.Tensor) -> torch.Tensor:
        """``V (n, M)``."""
        return self.critic(critic_obs)[..., 0]


def _flatten(module: nn.Module) -> torch.Tensor:
    """Move every parameter of ``module`` into one flat float32 buffer (values kept, order of
    ``module.parameters()`` kept); returns the buffer."""
    params = list(module.parameters())
    flat = torch.empty(sum(p.numel() for p in params))
    offset = 0
    for mod in module.modules():
        for name, p in list(mod._parameters.items()):
            view = flat[offset:offset + p.numel()].view(p.shape)
            view.copy_(p.detach())
            mod._parameters[name] = nn.Parameter(view)
            offset += p.numel()
    return flat


class FlatArrays:
    """numpy views of an :class:`ActorCritic`'s parameters laid over ``buf``: the parameters
    themselves (``buf = net.flat.numpy()``) or a gradient buffer of the same layout. Weights are
    ``(K, in, out)``, biases ``(K, 1, out)``, ``log_std`` ``(K, A)``."""

    def __init__(self, net: ActorCritic, buf: np.ndarray) -> None:
        if buf.shape != tuple(net.flat.shape) or buf.dtype != np.float32:
            raise ValueError(f"buf must be float32 of shape {tuple(net.flat.shape)}, got {buf.dtype} {buf.shape}")
        self.buf = buf
        base = net.flat.data_ptr()

        def view(p: torch.Tensor) -> np.ndarray:
            start = (p.data_ptr() - base) // 4
            return buf[start:start + p.numel()].reshape(p.shape)

        self.actor_w, self.actor_b = [view(w) for w in net.actor.weights], [view(b) for b in net.actor.biases]
        self.critic_w, self.critic_b = [view(w) for w in net.critic.weights], [view(b) for b in net.critic.biases]
        self.log_std = view(net.log_std)


def to_copies(x: np.ndarray, copies: int) -> np.ndarray:
    """``(n, M, d) -> (K, R, d)``, the layout of :func:`mlp_forward`: one weight copy's rows
    together (``K = 1``: all ``n * M`` rows; ``K = M``: agent ``k``'s ``n`` rows, a view)."""
    return x.reshape(1, -1, x.shape[-1]) if copies == 1 else x.transpose(1, 0, 2)


def from_copies(y: np.ndarray, n: int) -> np.ndarray:
    """The inverse of :func:`to_copies`: ``(K, R, d) -> (n, M, d)``."""
    return y.reshape(n, -1, y.shape[-1]) if y.shape[0] == 1 else y.transpose(1, 0, 2)


def scratch(buffers: dict[str, np.ndarray] | None, key: str, shape: tuple[int, ...]) -> np.ndarray:
    """A float32 work array of ``shape``: ``buffers[key]`` reused while its shape holds (``None``: a
    new one). Measured: a fresh 1 MB array page-faults on its first write (glibc hands it out by
    ``mmap``) and that cost the lean update's matmul-sized arrays more than the matmuls."""
    if buffers is None:
        return np.empty(shape, dtype=np.float32)
    buf = buffers.get(key)
    if buf is None or buf.shape != shape:
        buf = buffers[key] = np.empty(shape, dtype=np.float32)
    return buf


BIAS_TILE = 16
"""Rows per bias add in :func:`_add_bias`."""


def _add_bias(z: np.ndarray, b: np.ndarray) -> None:
    """``z (K, R, out) += b (K, 1, out)`` in place, ``BIAS_TILE`` rows at a time (numpy's broadcast
    over rows of 64 floats ran at half the speed of a same-shape add on 4,096 rows; measured; small
    arrays add directly)."""
    k, r, n = z.shape
    if r % BIAS_TILE or z.size < 65536:
        z += b
        return
    rows = z.reshape(k, r // BIAS_TILE, BIAS_TILE * n)
    np.add(rows, np.tile(b, (1, 1, BIAS_TILE)), out=rows)


def _onednn_linear() -> Any:
    """torch's oneDNN linear layer ``x @ w.T + b`` (``torch.ops.mkldnn._linear_pointwise``, the op
    Inductor's CPU code calls) when this torch build has it and it answers right on a tiny input;
    ``None`` otherwise (numpy's matmul then does every product)."""
    try:
        op = torch.ops.mkldnn._linear_pointwise
        probe = op(torch.ones(2, 3), torch.ones(4, 3), torch.ones(4), "none", [], "")
    except (AttributeError, RuntimeError):
        return None
    return op if torch.backends.mkldnn.is_available() and torch.equal(probe, torch.full((2, 4), 4.0)) else None


LINEAR = _onednn_linear()
"""The products of one weight copy (``K = 1``) by rows, forward and backward by the input: measured
at 4,096 rows by 64, twice the rate of numpy's OpenBLAS here (which ran its AVX2 kernels on an
AVX-512 machine where oneDNN ran its AVX-512 ones). The weights' gradients, a sum over the rows,
stay numpy's (no faster by oneDNN: its operands would be transposed copies)."""
LINEAR_MIN_ROWS = 1024
"""Fewer rows go to numpy: oneDNN's per-call cost made the rollout's 256-row policy slower."""


def _times_transposed(x: np.ndarray, w_t: np.ndarray, b: np.ndarray | None = None,
                      out: np.ndarray | None = None) -> np.ndarray:
    """``x (K, R, a) @ w_t (K, c, a)^T (+ b (K, 1, c))``: by :data:`LINEAR` (a new array) for one
    weight copy and at least :data:`LINEAR_MIN_ROWS` rows, else by numpy (into ``out`` when given)."""
    if LINEAR is not None and x.shape[0] == 1 and x.shape[1] >= LINEAR_MIN_ROWS:
        bias = None if b is None else torch.from_numpy(b[0, 0])
        y = LINEAR(torch.from_numpy(np.ascontiguousarray(x[0])), torch.from_numpy(w_t[0]), bias, "none", [], "")
        return y.numpy()[None]
    z = np.matmul(x, w_t.transpose(0, 2, 1), out=out)
    if b is not None:
        _add_bias(z, b)
    return z


def mlp_forward(ws: list[np.ndarray], bs: list[np.ndarray], x: np.ndarray,
                buffers: dict[str, np.ndarray] | None = None, tag: str = "",
                activation: str = "tanh") -> list[np.ndarray]:
    """The activations ``[x, h1, ..., out]`` of :class:`AgentMLP` on ``x (K, R, in)`` (numpy float32;
    ``out`` before any squashing, a new array; hidden ``activation`` of :data:`ACTIVATIONS`). Hidden
    ones made by numpy live in ``buffers`` (:func:`scratch`, keys ``tag``...) until the next call with
    the same ``buffers`` and ``tag``."""
    acts = [x]
    last = len(ws) - 1
    for i, (w, b) in enumerate(zip(ws, bs, strict=True)):
        shape = (*x.shape[:-1], w.shape[-1])
        z = _times_transposed(acts[-1], w.transpose(0, 2, 1), b,
                              scratch(buffers if i < last else None, f"{tag}h{i}", shape))
        if i < last:
            if activation == "tanh":
                np.tanh(z, out=z)
            else:
                np.maximum(z, np.float32(0.0), out=z)
        acts.append(z)
    return acts


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _times_tanh_slope(grad: np.ndarray, y: np.ndarray) -> None:
    """``grad *= 1 - y * y`` (tanh's derivative from its output ``y``) in one pass over flat float32
    arrays (numpy took three)."""
    one = np.float32(1.0)
    for i in range(grad.size):
        grad[i] *= one - y[i] * y[i]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _times_relu_slope(grad: np.ndarray, y: np.ndarray) -> None:
    """``grad *= y > 0`` (ReLU's derivative from its output ``y``) in place over flat float32 arrays."""
    for i in range(grad.size):
        if y[i] <= 0:
            grad[i] = 0


def mlp_backward(ws: list[np.ndarray], acts: list[np.ndarray], grad: np.ndarray, gws: list[np.ndarray],
                 gbs: list[np.ndarray], buffers: dict[str, np.ndarray] | None = None, tag: str = "",
                 activation: str = "tanh") -> None:
    """Write into ``gws`` / ``gbs`` the gradients of the weights and biases given ``grad``, the
    loss's gradient by the last layer's output ``(K, R, out)`` (``acts`` from :func:`mlp_forward`
    with the same ``activation``; work arrays from ``buffers`` as there)."""
    slope = _times_tanh_slope if activation == "tanh" else _times_relu_slope
    k, r = grad.shape[:2]
    ones = np.ones((k, 1, r), dtype=np.float32)
    for i in range(len(ws) - 1, -1, -1):
        np.matmul(acts[i].transpose(0, 2, 1), grad, out=gws[i])
        np.matmul(ones, grad, out=gbs[i])                 # the sum over rows, by BLAS
        if i:
            h = acts[i]
            work = scratch(buffers, f"{tag}g{i}", h.shape)
            if grad.shape[-1] == 1:                       # an outer product: 8x faster multiplied than matmul'd
                grad = np.multiply(grad, ws[i].transpose(0, 2, 1), out=work)
            else:
                grad = _times_transposed(grad, ws[i], out=work)
            assert grad.flags.c_contiguous and h.flags.c_contiguous    # the flat views below alias them
            slope(grad.reshape(-1), h.reshape(-1))


def adam_step(param: np.ndarray, grad: np.ndarray, exp_avg: np.ndarray, exp_avg_sq: np.ndarray, step: int,
              lr: float | np.ndarray, betas: tuple[float, float], eps: float) -> None:
    """One step of ``torch.optim.Adam`` (no weight decay, no amsgrad) on flat float32 arrays, in
    place; ``step`` counts this one (1 on the first); ``lr``: one rate, or one per entry of ``param``."""
    b1, b2 = betas
    exp_avg += (1.0 - b1) * (grad - exp_avg)              # torch's lerp_
    exp_avg_sq *= b2
    exp_avg_sq += (1.0 - b2) * grad * grad
    denom = np.sqrt(exp_avg_sq) / math.sqrt(1.0 - b2**step)
    denom += eps
    param -= (lr / (1.0 - b1**step)) * exp_avg / denom


def export_actor(net: ActorCritic, agent: int = 0) -> MLPActor:
    """Agent ``agent``'s actor (its weight copy; the shared one when the weights are shared) as an
    :class:`MLPActor` with ``squash=True`` (a copy of the weights)."""
    k = agent if net.actor.copies > 1 else 0
    obs_dim, act_dim = net.actor.weights[0].shape[1], net.actor.weights[-1].shape[2]
    actor = MLPActor(int(obs_dim), int(act_dim), list(net.actor_hidden), net.actor.activation, squash=True)
    pairs = [(w[k].detach().T, b[k, 0].detach()) for w, b in zip(net.actor.weights, net.actor.biases, strict=True)]
    return actor.copy_linear_weights(pairs)
