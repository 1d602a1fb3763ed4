"""The saved actor network: a plain torch MLP described by JSON (no pickled code).

Every training stack (SB3, BenchMARL, RLlib) exports its trained actor to :class:`MLPActor`:
``actions = head(body(obs))`` (``tanh`` of it when ``squash``), the deterministic action in
``[-1, 1]`` of the policy for the normalised, featurised per-agent observation.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

__all__ = ["ACTIVATIONS", "MLPActor", "actor_from_spec"]

ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "silu": nn.SiLU}


MAX_PARAMETERS = 50_000_000
"""Cap on an actor's parameter count (200 MB of float32): a ``policy.json`` asking for more would
allocate before any weight is read."""
MAX_LAYERS = 64
"""Cap on the number of hidden layers."""


class MLPActor(nn.Module):
    """``obs (..., obs_dim) -> action (..., act_dim)``: hidden ``Linear`` + activation layers, a
    linear head, and ``tanh`` when ``squash``."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...] | list[int],
                 activation: str = "tanh", squash: bool = False) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}")
        for name, v in (("obs_dim", obs_dim), ("act_dim", act_dim), *(("hidden", h) for h in hidden)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be positive ints, got {v!r}")
        if not isinstance(squash, bool):
            raise ValueError(f"squash must be a bool, got {squash!r}")
        widths = [obs_dim, *hidden, act_dim]
        n_params = sum((a + 1) * b for a, b in zip(widths, widths[1:], strict=False))
        if len(hidden) > MAX_LAYERS or n_params > MAX_PARAMETERS:
            raise ValueError(f"the actor would have {len(hidden)} hidden layers and {n_params} parameters; "
                             f"at most {MAX_LAYERS} and {MAX_PARAMETERS} (MAX_LAYERS, MAX_PARAMETERS) are "
                             "allowed (a bigger one is a corrupt or hostile policy.json)")
        self.spec = {"type": "mlp", "obs_dim": obs_dim, "act_dim": act_dim, "hidden": list(hidden),
                     "activation": activation, "squash": squash}
        layers: list[nn.Module] = []
        width = obs_dim
        for h in hidden:
            layers += [nn.Linear(width, h), ACTIVATIONS[activation]()]
            width = h
        self.body = nn.Sequential(*layers)
        self.head = nn.Linear(width, act_dim)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        y = self.head(self.body(obs))
        return torch.tanh(y) if self.spec["squash"] else y

    def linear_layers(self) -> list[nn.Linear]:
        """The linear layers in order (hidden ones, then the head): what exporters fill."""
        return [m for m in self.body if isinstance(m, nn.Linear)] + [self.head]

    def copy_linear_weights(self, layers: list[nn.Linear] | list[tuple[Any, Any]]) -> MLPActor:
        """Copy ``(weight, bias)`` of each source layer (modules or tensor pairs) into this actor."""
        mine = self.linear_layers()
        if len(layers) != len(mine):
            raise ValueError(f"expected {len(mine)} linear layers, got {len(layers)}")
        with torch.no_grad():
            for dst, src in zip(mine, layers, strict=True):
                w, b = (src.weight, src.bias) if isinstance(src, nn.Module) else src
                w, b = torch.as_tensor(w, dtype=torch.float32), torch.as_tensor(b, dtype=torch.float32)
                if w.shape != dst.weight.shape or b.shape != dst.bias.shape:
                    raise ValueError(f"layer shape {tuple(w.shape)} does not fit {tuple(dst.weight.shape)}")
                dst.weight.copy_(w)
                dst.bias.copy_(b)
        return self


def actor_from_spec(spec: dict[str, Any]) -> nn.Module:
    """Build the (untrained) :class:`MLPActor` a ``policy.json`` ``actor`` entry of ``"type": "mlp"``
    describes (``satenv.training.policy`` reads the other type, ``"set"``, with ``satenv.training.set_policy``)."""
    if not isinstance(spec, dict) or spec.get("type") != "mlp":
        raise ValueError(f"actor spec must be a JSON object with type 'mlp' or 'set', got {spec!r}")
    unknown = set(spec) - {"type", "obs_dim", "act_dim", "hidden", "activation", "squash"}
    if unknown:
        raise ValueError(f"unknown actor spec field(s) {sorted(unknown)}")
    hidden = spec.get("hidden")
    if not isinstance(hidden, list):
        raise ValueError(f"actor spec 'hidden' must be a list of ints, got {hidden!r}")
    return MLPActor(spec.get("obs_dim"), spec.get("act_dim"), hidden, spec.get("activation", "tanh"),
                    spec.get("squash", False))
