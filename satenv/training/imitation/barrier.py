"""The safety filter's constraint rows as a differentiable barrier on the network's action.

The filter's rows are the discrete barrier condition on the next state (``h(x+) >= (1 - gamma)
h(x)``, linear in the action): :func:`agent_constraints` reads them at the filter's state through
the filter's own :func:`satenv.safety.core.action_rows` (its margins and thrust-loss tightening),
:func:`barrier_hinge` is zero exactly where the filter would pass an action (a margin inside), and
:func:`terminal_affine` writes the policy's terminal feedback as an affine map of the network's
action, so the loss acts on what is flown.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["ROW_LOWER_FLOOR", "agent_constraints", "barrier_hinge", "env_action", "terminal_affine"]

ROW_LOWER_FLOOR = -10.0
"""Normalised row bounds below this never bind an action in the unit box (stored clipped here)."""


def agent_constraints(filt: Any, applied: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each agent's filter constraints at the filter's current state, ``rows (M, K, d)`` and
    ``lower (M, K)``, in normalised action space and scaled to unit rows: an action ``a`` of
    agent ``i`` passes the filter untouched iff ``rows[i] @ eff(a) >= lower[i]`` for every ``k``
    (``eff``: the env's clipping). ``applied (M, d)`` are the actions the filter let through this
    step: down a chain, a chaser's rows hold its target's applied acceleration, as in the filter.
    Unused slots get ``lower = ROW_LOWER_FLOOR``."""
    from satenv.safety.core import _effective, action_rows, chain_slots

    m = filt.model
    x = np.asarray(filt.core.x, dtype=float)[:1]
    t = np.asarray(filt.core.t, dtype=float).reshape(-1)[:1] * float(filt.core.scenario.dt)
    found = action_rows(m, filt.config, x, t)                 # the filter's own rows, thrust loss included
    rows, lo = found.rows[0], found.lower[0].copy()
    if m.n_chain:
        idx = chain_slots(m)
        acc = _effective(m, np.asarray(applied, dtype=float)) @ m.S.T     # chains are never body-frame
        for f in range(1, len(lo)):
            lo[f, idx] += found.w[0, f, idx] @ acc[f - 1]
    scale = np.linalg.norm(rows, axis=-1)
    tiny = scale < 1e-12
    rows = np.where(tiny[..., None], 0.0, rows / np.where(tiny, 1.0, scale)[..., None])
    lower = np.where(tiny, ROW_LOWER_FLOOR, lo / np.where(tiny, 1.0, scale))
    return rows.astype(np.float32), np.clip(lower, ROW_LOWER_FLOOR, 10.0).astype(np.float32)


def barrier_hinge(actions: Any, rows: Any, lower: Any, margin: float = 0.0, norm_mode: bool = False) -> Any:
    """``sum_k relu(lower_k + margin - rows_k . eff(a))^2`` per row of a torch batch: zero where the
    filter (tightened by ``margin``) would pass the action, growing with the distance outside.
    A bound no action can reach (an infeasible row, common where the network alone has flown too
    close) is lowered to the row's attainable maximum (``1`` on the unit ball, ``|rows_k|_1`` on
    the box): the hinge then asks for the best the action can do along the row, no more, and the
    term stays of the order of the others."""
    import torch

    eff = torch.clamp(actions, -1.0, 1.0)
    if norm_mode:
        eff = eff / torch.clamp(torch.linalg.norm(eff, dim=-1, keepdim=True), min=1.0)
    attainable = torch.ones_like(lower) if norm_mode else rows.abs().sum(-1)
    slack = torch.einsum("nkd,nd->nk", rows, eff) - torch.minimum(lower + margin, attainable)
    return (torch.relu(-slack) ** 2).sum(-1)


def terminal_affine(policy: Any, obs: np.ndarray, act_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The policy's terminal feedback (:class:`satenv.training.shaping.TerminalFeedback`, a blend affine in
    the network's action) as ``(offset, slope)`` per row: the policy's action is
    ``offset + slope * a_net`` (``(0, 1)`` without feedback), so the loss acts on what is flown."""
    n = len(obs)
    term = getattr(policy, "terminal", None)
    if term is None or not getattr(term, "active", True):
        return np.zeros((n, act_dim)), np.ones((n, act_dim))
    raw = obs.astype(np.float64)
    c0 = term(raw, np.zeros((n, act_dim)))
    c1 = term(raw, np.ones((n, act_dim)))
    return c0, c1 - c0


def env_action(out: Any, power: float) -> Any:
    """The actor's output as the env action (clipped, then the action map ``sign(y)|y|^power``)."""
    import torch

    y = torch.clamp(out, -1.0, 1.0)
    return y if power == 1.0 else torch.sign(y) * torch.abs(y).clamp_min(1e-12) ** power
