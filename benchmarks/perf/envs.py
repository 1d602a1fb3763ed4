"""The ``envs`` section (issue 25): the envs that learning needs, each beside its peer in the same run.

* PettingZoo dict API of ``cluster_v0`` (li2022 case 1, 10 satellites, J2 + drag truth at 0.25 s
  inside each 5 s decision) and ``servicing_v0`` (pereira2022, 6-DOF) against mpe2
  ``simple_spread`` (3 agents, continuous), timed in interleaved repeats, per agent-step;
* ``make_vec("cluster_v0", 1024)`` against VMAS ``navigation`` at 1024 envs, interleaved;
* the ring swarm core (``platoon_v0`` ``swarm(N, "ring", "RING")``, cw, 64 copies, ``step`` +
  ``observe``) at N = 1024 against N = 4, per agent-step.

Each comparison is a ratio of two rates measured in the same run (the machine's load affects
both alike); :data:`TARGETS` are issue 25's goals, reported with ``met`` flags.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import scaling
from ._common import PettingZooLoop, _rate
from .vmas import vmas_navigation

TARGETS: dict[str, float] = {
    "cluster_v0 PettingZoo / mpe2 simple_spread, per agent-step": 1.0,
    "servicing_v0 PettingZoo / mpe2 simple_spread, per agent-step": 0.5,
    "make_vec(cluster_v0) / VMAS navigation at 1024 copies, per agent-step": 1.0,
    "ring swarm core x64: per-agent rate N=1024 / N=4": 1 / 3,
}
"""Issue 25's targets (ratios, ``>=``)."""

SWARM_SIZES = (4, 1024)
SWARM_COPIES = 64


def pettingzoo_vs_mpe2(api_time: float, repeats: int = 3) -> dict[str, Any]:
    """Agent-steps/s of the cluster and servicing PettingZoo envs and of mpe2, interleaved."""
    import satenv

    try:
        from mpe2 import simple_spread_v3
    except ModuleNotFoundError as exc:
        return {"skipped": f"mpe2 not installed ({exc}); pip install 'satenv[peers]'"}
    loops = {"mpe2": PettingZooLoop(simple_spread_v3.parallel_env(continuous_actions=True, max_cycles=180),
                                    0.0, 1.0),
             "cluster_v0": PettingZooLoop(satenv.make("cluster_v0"), -1.0, 1.0),
             "servicing_v0": PettingZooLoop(satenv.make("servicing_v0"), -1.0, 1.0)}
    for _ in range(repeats):
        for loop in loops.values():
            loop.measure(api_time)
    return {name: loop.result() for name, loop in loops.items()}


def make_vec_vs_vmas(batch: int, min_time: float, repeats: int = 2) -> dict[str, Any]:
    """Agent-steps/s of ``make_vec("cluster_v0", batch)`` (uniform random actions, auto-reset) and of
    VMAS ``navigation`` at the same batch, in alternating repeats (best of each)."""
    import satenv

    vec = satenv.make_vec("cluster_v0", batch, seed=0)
    vec.reset()
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, vec.action_shape)
    sat = peer = 0.0
    note = None
    for _ in range(repeats):
        sat = max(sat, _rate(lambda: vec.step(actions), batch * vec.n_agents, min_time, repeats=1))
        v = vmas_navigation(batch, min_time)
        if "skipped" in v:
            note = v["skipped"]
            break
        peer = max(peer, v["agent_steps_per_s"])
    out: dict[str, Any] = {"batch": batch, "agents": vec.n_agents, "satenv_agent_steps_per_s": sat}
    if note is None:
        out["vmas_agent_steps_per_s"] = peer
    else:
        out["vmas_skipped"] = note
    return out


def ring_swarm(min_time: float, sizes: tuple[int, ...] = SWARM_SIZES, copies: int = SWARM_COPIES,
               repeats: int = 2) -> dict[str, Any]:
    """Per-agent rate of the ring swarm core at each size (interleaved repeats, best of each)."""
    family = scaling.FAMILIES["platoon"]
    best = dict.fromkeys(sizes, 0.0)
    for _ in range(repeats):
        for n in sizes:
            best[n] = max(best[n], scaling.core_rate(family, n, copies, min_time, repeats=1))
    return {"copies": copies, "env": family.label,
            "agent_steps_per_s": {str(n): rate for n, rate in best.items()}}


def env_speed(min_time: float = 0.2, api_time: float = 0.5, batch: int = 1024,
              swarm_sizes: tuple[int, ...] = SWARM_SIZES, log: Callable[[str], None] = print) -> dict:
    """The section's figures, ratios and ``targets`` (rows ``name, value, target, op, met``)."""
    out: dict[str, Any] = {"pettingzoo": pettingzoo_vs_mpe2(api_time)}
    out["make_vec"] = make_vec_vs_vmas(batch, min_time)
    out["ring_swarm"] = ring_swarm(min_time, swarm_sizes)
    ratios: dict[str, float] = {}
    pz = out["pettingzoo"]
    if "skipped" not in pz:
        for env in ("cluster_v0", "servicing_v0"):
            ratios[f"{env} PettingZoo / mpe2 simple_spread, per agent-step"] = (
                pz[env]["agent_steps_per_s"] / pz["mpe2"]["agent_steps_per_s"])
    vec = out["make_vec"]
    if "vmas_agent_steps_per_s" in vec:
        ratios[f"make_vec(cluster_v0) / VMAS navigation at {batch} copies, per agent-step"] = (
            vec["satenv_agent_steps_per_s"] / vec["vmas_agent_steps_per_s"])
    rates = out["ring_swarm"]["agent_steps_per_s"]
    lo, hi = min(swarm_sizes), max(swarm_sizes)
    ratios[f"ring swarm core x{SWARM_COPIES}: per-agent rate N={hi} / N={lo}"] = rates[str(hi)] / rates[str(lo)]
    out["ratios"] = ratios
    out["targets"] = [{"name": f"(25) {name}", "value": value, "target": TARGETS.get(name, 1 / 3), "op": ">=",
                       "met": bool(value >= TARGETS.get(name, 1 / 3))} for name, value in ratios.items()]
    for t in out["targets"]:
        log(f"{t['name']}: {t['value']:.3g} (target >= {t['target']:.3g})")
    return out
