"""The ``envs`` section: the envs that learning needs, each beside its peer in the same run.

* PettingZoo dict API of ``cluster_v0`` (li2022 case 1, 10 satellites, J2 + drag truth: one DOP853
  step per 5 s decision, the 0.25 s physics steps' positions interpolated) and ``servicing_v0``
  (pereira2022, 6-DOF) against mpe2 ``simple_spread`` (3 agents, continuous), timed in interleaved
  repeats, per agent-step;
* ``make_vec("cluster_v0", 1024)`` against VMAS ``navigation`` at 1024 envs, interleaved;
* the ring swarm core (``platoon_v0`` ``swarm(N, "ring", "RING")``, cw, 64 copies, ``step`` +
  ``observe``) at N = 1024 against N = 4, per agent-step.

Each comparison is a ratio of two rates measured in the same run (the machine's load affects
both alike); :data:`TARGETS` are the goals, reported with ``met`` flags; ``make_vec_profile``
gives the shares of the ``make_vec`` step (the truth kernel, the separations, the rest).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import scaling
from ._common import PettingZooLoop, _rate
from .vmas import vmas_navigation

TARGETS: dict[str, float] = {
    "cluster_v0 PettingZoo / mpe2 simple_spread, per agent-step": 5.0,
    "servicing_v0 PettingZoo / mpe2 simple_spread, per agent-step": 1.0,
    "make_vec(cluster_v0) / VMAS navigation at 1024 copies, per agent-step": 5.0,
    "ring swarm core x64: per-agent rate N=1024 / N=4": 1 / 3,
}
"""The targets (ratios, ``>=``): the J2 + drag engine's (cluster PettingZoo 5x mpe2, servicing 1x,
``make_vec("cluster_v0")`` 5x VMAS at 1024 copies: about 0.5 M agent-steps/s per core); the ring
swarm's per-agent rate at N = 1024 at least a third of N = 4's."""

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


PROFILE_PARTS = {"truth kernel": ("_span_kernel.py", "_truth_kernel.py"),
                 "separations": ("_cluster_kernel.py:separations",),
                 "graph and observation": ("_cluster_kernel.py:neighbours", "_cluster_kernel.py:observe")}
"""The compiled parts of the ``make_vec("cluster_v0")`` step whose shares :func:`make_vec_profile`
reports (file, or file:function, of the profile's rows); everything else is ``rest`` (numpy glue,
rewards, infos, resets)."""


def make_vec_profile(batch: int, steps: int = 10) -> dict[str, Any]:
    """Shares of the ``make_vec("cluster_v0", batch)`` step's wall time (cProfile's own times of
    :data:`PROFILE_PARTS`, ``rest`` the remainder) over ``steps`` steps after a warm-up."""
    import cProfile
    import pstats

    import satenv

    vec = satenv.make_vec("cluster_v0", batch, seed=0)
    vec.reset()
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, vec.action_shape)
    for _ in range(2):
        vec.step(actions)
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(steps):
        vec.step(actions)
    prof.disable()
    stats = pstats.Stats(prof).stats      # (file, line, name) -> (cc, nc, tottime, cumtime, callers)
    total = sum(row[2] for row in stats.values())
    shares = dict.fromkeys(PROFILE_PARTS, 0.0)
    for (file, _, name), row in stats.items():
        for part, keys in PROFILE_PARTS.items():
            if any(file.endswith(k) or f"{file}:{name}".endswith(k) for k in keys):
                shares[part] += row[2] / total
                break
    shares["rest"] = max(0.0, 1.0 - sum(shares.values()))
    return {"batch": batch, "steps": steps, "wall_s": total, "shares": shares}


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
    out["make_vec_profile"] = make_vec_profile(batch, steps=max(2, round(10 * min(1.0, min_time / 0.2))))
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
    out["targets"] = [{"name": f"(envs) {name}", "value": value, "target": TARGETS.get(name, 1 / 3), "op": ">=",
                       "met": bool(value >= TARGETS.get(name, 1 / 3))} for name, value in ratios.items()]
    for t in out["targets"]:
        log(f"{t['name']}: {t['value']:.3g} (target >= {t['target']:.3g})")
    log("make_vec(cluster_v0) step shares: " + ", ".join(
        f"{k} {100 * v:.0f} %" for k, v in out["make_vec_profile"]["shares"].items()))
    return out
