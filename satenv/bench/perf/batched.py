"""The ``batched`` section: ``RelativeModel.step`` and the platoon core on batches of copies, and the
machine's memory-copy limit."""

from __future__ import annotations

import math

import numpy as np

from satenv.dynamics import RelativeModel

from ._common import AGENTS, _orbit, _rate


def batched_dynamics(model: str, batch: int, dt: float = 0.1, min_time: float = 0.2) -> dict:
    """Agent-steps/s of ``RelativeModel.step`` on ``batch`` copies x 4 agents, and of a memory copy
    of the same state, action and chief bytes (the machine's limit)."""
    prop = RelativeModel(model, _orbit(), dt)
    rng = np.random.default_rng(0)
    state = {"x": rng.normal(size=(batch, AGENTS, 6)) * 100.0,
             "chief": np.broadcast_to(prop.initial_chief(), (batch, 6)).copy()}
    u = rng.normal(size=(batch, AGENTS, 3)) * 1e-3

    def step() -> None:
        state["x"], state["chief"] = prop.step(state["x"], u, state["chief"])

    src = np.concatenate([state["x"].ravel(), u.ravel(), state["chief"].ravel()])
    dst = np.empty_like(src)
    sat = _rate(step, batch * AGENTS, min_time)
    limit = _rate(lambda: np.copyto(dst, src), batch * AGENTS, min_time)
    return {"model": model, "batch": batch, "agents": batch * AGENTS, "bytes": int(src.nbytes),
            "agent_steps_per_s": sat, "memory_limit_agent_steps_per_s": limit,
            "ratio_to_limit": sat / limit}


def batched_core(model: str, batch: int, min_time: float = 0.2) -> dict | None:
    """Agent-steps/s of the platoon training path: ``core.step_observe`` (the step and its
    observations, as ``satenv.make_vec`` calls it) on ``batch`` copies."""
    try:
        from satenv.envs.platoon_v0 import PlatoonCore
        from satenv.scenarios.platoon import resolve_scenario
    except ModuleNotFoundError as exc:
        if not (exc.name or "").startswith("satenv"):
            raise
        return None
    scenario = resolve_scenario("pereira2023", dynamics=model, inclination=math.radians(51.6))
    core = PlatoonCore(scenario, batch=batch)
    rng = np.random.default_rng(0)
    core.reset(core.sample_initial_state(rng, batch), None, rng)
    accel = rng.uniform(-1.0, 1.0, size=(batch, core.n_agents, 3)) * 0.01 * scenario.u_max

    def step() -> None:
        core.step_observe(accel, rng)

    return {"model": model, "batch": batch, "agents": batch * core.n_agents,
            "agent_steps_per_s": _rate(step, batch * core.n_agents, min_time)}
