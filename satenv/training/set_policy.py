"""A permutation-invariant actor for observations with neighbour slots (no pickled code).

The fixed observation layouts of ``cluster_v0`` and ``formation_v0`` (``obs_neighbours = K``) are
``own entries | K slots of slot_dim entries`` with the first entry of every slot its presence flag
(1 or 0); the feature map (:class:`satenv.training.shaping.ObsFeatures`) may append more own entries
after the slots. :class:`SetActor` reads the slots as an unordered set::

    code_k  = encoder(slot_k)                      one MLP shared by every slot
    pooled  = [masked mean_k code_k, masked max_k code_k]   (zeros when no slot is present)
    action  = head([own entries, pooled])          (tanh of it when ``squash``)

so its action does not depend on the order of the slots, nor on how many empty ones there are.
Before encoding, the slots are put in one canonical order (a lexicographic sort of their
entries), so a permutation of the slots gives the bit-identical action, not only the same one up
to rounding. The network is described by ``policy.json`` (``"type": "set"``, read by
:func:`set_actor_from_spec` through ``satenv.training.actor.actor_from_spec``) and its weights by
``weights.safetensors`` like the MLP's; :func:`set_statistics` keeps the slot statistics shared
by every slot (and the presence flag unscaled), so the normalisation is permutation-invariant too.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from satenv.training.actor import ACTIVATIONS, MAX_LAYERS, MAX_PARAMETERS

__all__ = ["PRESENT_ABOVE", "SetActor", "set_actor_from_spec", "set_statistics", "slot_layout"]

PRESENT_ABOVE = 0.5
"""A slot is present when its (normalised) flag entry exceeds this (the env writes 1 or 0 and
:func:`set_statistics` leaves the flag unscaled)."""

SPEC_FIELDS = ("type", "obs_dim", "act_dim", "own_dim", "slot_dim", "n_slots", "encoder", "hidden",
               "activation", "squash")
"""The fields of a ``"set"`` actor spec in ``policy.json``."""


def _positive_ints(name: str, values: Any) -> list[int]:
    if not isinstance(values, list | tuple) or any(isinstance(v, bool) or not isinstance(v, int) or v < 1
                                                   for v in values):
        raise ValueError(f"set actor {name} must be a list of positive ints, got {values!r:.80}")
    return list(values)


def _mlp(widths: list[int], activation: str, last_activation: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(widths, widths[1:], strict=False)):
        layers.append(nn.Linear(a, b))
        if last_activation or i < len(widths) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


class SetActor(nn.Module):
    """``obs (..., obs_dim) -> action (..., act_dim)``: shared slot encoder, masked mean and max
    pooling, MLP head (module docstring).

    Args:
        obs_dim: network inputs (``own_dim + n_slots * slot_dim`` plus any appended own features).
        act_dim: actions.
        own_dim: own entries before the slots.
        slot_dim: entries per slot, the first its presence flag.
        n_slots: slots.
        encoder: hidden sizes of the per-slot MLP (its last is the code width).
        hidden: hidden sizes of the head.
        activation: one of :data:`satenv.training.actor.ACTIVATIONS`.
        squash: ``tanh`` on the output.
    """

    def __init__(self, obs_dim: int, act_dim: int, own_dim: int, slot_dim: int, n_slots: int,
                 encoder: list[int] | tuple[int, ...], hidden: list[int] | tuple[int, ...],
                 activation: str = "relu", squash: bool = True) -> None:
        super().__init__()
        for name, v in (("obs_dim", obs_dim), ("act_dim", act_dim), ("slot_dim", slot_dim), ("n_slots", n_slots)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"set actor {name} must be a positive int, got {v!r:.40}")
        if isinstance(own_dim, bool) or not isinstance(own_dim, int) or own_dim < 0:
            raise ValueError(f"set actor own_dim must be an int >= 0, got {own_dim!r:.40}")
        if own_dim + n_slots * slot_dim > obs_dim:
            raise ValueError(f"set actor: own_dim + n_slots * slot_dim = {own_dim + n_slots * slot_dim} exceeds "
                             f"obs_dim = {obs_dim}")
        encoder, hidden = _positive_ints("encoder", encoder), _positive_ints("hidden", hidden)
        if not encoder:
            raise ValueError("set actor encoder must have at least one layer (its last is the code width)")
        if activation not in ACTIVATIONS:
            raise ValueError(f"set actor activation must be one of {sorted(ACTIVATIONS)}, got {activation!r:.40}")
        if not isinstance(squash, bool):
            raise ValueError(f"set actor squash must be a bool, got {squash!r:.40}")
        own_total = obs_dim - n_slots * slot_dim
        enc_widths = [slot_dim, *encoder]
        head_widths = [own_total + 2 * encoder[-1], *hidden, act_dim]
        n_params = sum((a + 1) * b for w in (enc_widths, head_widths) for a, b in zip(w, w[1:], strict=False))
        if len(encoder) + len(hidden) > MAX_LAYERS or n_params > MAX_PARAMETERS:
            raise ValueError(f"the set actor would have {len(encoder) + len(hidden)} hidden layers and {n_params} "
                             f"parameters; at most {MAX_LAYERS} and {MAX_PARAMETERS} (MAX_LAYERS, MAX_PARAMETERS)")
        self.spec = {"type": "set", "obs_dim": obs_dim, "act_dim": act_dim, "own_dim": own_dim,
                     "slot_dim": slot_dim, "n_slots": n_slots, "encoder": encoder, "hidden": hidden,
                     "activation": activation, "squash": squash}
        self.encoder = _mlp(enc_widths, activation, last_activation=True)
        self.head = _mlp(head_widths, activation, last_activation=False)

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(own (..., own_total), slots (..., n_slots, slot_dim))`` of network inputs ``obs``."""
        s = self.spec
        end = s["own_dim"] + s["n_slots"] * s["slot_dim"]
        own = torch.cat([obs[..., :s["own_dim"]], obs[..., end:]], dim=-1)
        slots = obs[..., s["own_dim"]:end].reshape(*obs.shape[:-1], s["n_slots"], s["slot_dim"])
        return own, slots

    @staticmethod
    def canonical(slots: torch.Tensor) -> torch.Tensor:
        """The slots in lexicographic order of their entries (stable sorts, last entry first): one
        order for every permutation of the same slots."""
        for c in reversed(range(slots.shape[-1])):
            idx = torch.sort(slots[..., c], dim=-1, stable=True).indices
            slots = torch.gather(slots, -2, idx.unsqueeze(-1).expand_as(slots))
        return slots

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        own, slots = self.split(obs)
        slots = self.canonical(slots)
        present = slots[..., :1] > PRESENT_ABOVE                                  # (..., K, 1)
        code = self.encoder(slots)                                                # (..., K, E)
        count = present.sum(dim=-2).clamp(min=1).to(code.dtype)                  # (..., 1)
        mean = torch.where(present, code, torch.zeros_like(code)).sum(dim=-2) / count
        peak = torch.where(present, code, torch.full_like(code, -torch.inf)).amax(dim=-2)
        peak = torch.where(present.any(dim=-2), peak, torch.zeros_like(peak))
        y = self.head(torch.cat([own, mean, peak], dim=-1))
        return torch.tanh(y) if self.spec["squash"] else y


def set_actor_from_spec(spec: dict[str, Any]) -> SetActor:
    """Build the (untrained) set actor a ``policy.json`` ``actor`` entry describes."""
    if not isinstance(spec, dict) or spec.get("type") != "set":
        raise ValueError("set actor spec must be a JSON object with type 'set'")
    unknown = set(spec) - set(SPEC_FIELDS)
    if unknown:
        raise ValueError(f"unknown set actor spec field(s) {sorted(unknown)}")
    missing = [k for k in SPEC_FIELDS if k not in spec and k not in ("activation", "squash")]
    if missing:
        raise ValueError(f"set actor spec misses field(s) {missing}")
    return SetActor(spec["obs_dim"], spec["act_dim"], spec["own_dim"], spec["slot_dim"], spec["n_slots"],
                    spec["encoder"], spec["hidden"], spec.get("activation", "relu"), spec.get("squash", True))


def slot_layout(env: Any) -> tuple[int, int, int]:
    """``(own_dim, slot_dim, n_slots)`` of an env with the fixed observation layout
    (``obs_neighbours = K`` on ``cluster_v0`` / ``formation_v0``); a ``ValueError`` otherwise."""
    base = getattr(env, "unwrapped", env)
    scenario, core = getattr(base, "scenario", None), getattr(base, "core", None)
    k = getattr(scenario, "obs_neighbours", None)
    if k is None or core is None:
        raise ValueError(f"a set actor needs an env with the fixed observation layout (cluster_v0 or "
                         f"formation_v0 with obs_neighbours=K), got {type(base).__name__} with obs_neighbours={k!r}")
    slot_dim = 7
    return int(core.obs_dim) - slot_dim * k, slot_dim, int(k)


def set_statistics(spec: dict[str, Any], features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean and variance of a set actor's :class:`satenv.training.policy.ObsNormalizer` from network
    inputs ``features`` ``(n, obs_dim)``: own entries by their own mean and variance; every slot
    entry by the mean and variance of that entry over all present slots (one statistic shared by
    every slot, so the normalisation commutes with permuting them); the presence flag unscaled
    (mean 0, variance 1)."""
    fx = np.asarray(features, dtype=np.float64)
    mean, var = fx.mean(0), fx.var(0)
    o, d, k = spec["own_dim"], spec["slot_dim"], spec["n_slots"]
    slots = fx[:, o:o + k * d].reshape(-1, d)
    slots = slots[slots[:, 0] > PRESENT_ABOVE]
    slot_mean = slots.mean(0) if len(slots) else np.zeros(d)
    slot_var = slots.var(0) if len(slots) else np.ones(d)
    slot_mean[0], slot_var[0] = 0.0, 1.0
    mean[o:o + k * d], var[o:o + k * d] = np.tile(slot_mean, k), np.tile(slot_var, k)
    return mean, var
