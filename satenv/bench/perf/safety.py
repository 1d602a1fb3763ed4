"""The ``safety`` section: the safety filter's cost, beside the env step in the same run.

``run(options, log)`` -> dict: for each case (env, copies ``B``), the filter's wall time per agent decision
(``ms_per_agent``: one ``filter`` call over ``B`` copies x ``M`` agents, divided by ``B M``) on the
states and proposals of a random-policy episode under the filter (so its QPs run as often as the
random policy makes them), the same for an all-safe proposal (zero thrust: the row check only), the
env step on the same states (``step_ms_per_agent``: PettingZoo dict step for ``B = 1``, the
``make_vec`` batched step otherwise) and their ratio. Targets: at N = 10 (cluster_v0)
<= 0.1 ms per agent decision, and <= 0.02 ms per agent over 64 copies.

    python -m satenv.bench.perf --sections safety --out perf_safety.json
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

CASES: tuple[tuple[str, dict[str, Any], int], ...] = (
    ("cluster_v0", {}, 1), ("cluster_v0", {}, 64), ("platoon_v0", {"preset": "pereira2022"}, 1),
    ("platoon_v0", {"preset": "pereira2022"}, 64), ("servicing_v0", {}, 1), ("servicing_v0", {}, 64),
)
TARGETS = {("cluster_v0", 1): 0.1, ("cluster_v0", 64): 0.02}
"""ms per agent decision."""


def _record(env_id: str, kwargs: dict[str, Any], copies: int, decisions: int, seed: int) -> tuple[list, Any]:
    """(state, time, proposal) of ``decisions`` steps of a random policy under the filter."""
    import satenv

    vec = satenv.make_vec(env_id, copies, seed=seed, safety_filter=True, **kwargs)
    vec.reset()
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(decisions):
        a = rng.uniform(-1.0, 1.0, vec.action_shape)
        out.append((vec.core.x.copy(), vec.core.t * float(vec.scenario.dt), a))
        vec.step(a)
    return out, vec


def _best(fn, items: list, repeats: int) -> float:
    """Best over ``repeats`` of the mean wall time of ``fn(item)`` over ``items`` [s]."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for item in items:
            fn(item)
        best = min(best, (time.perf_counter() - start) / len(items))
    return float(best)


def _env_step_s(env_id: str, kwargs: dict[str, Any], copies: int, decisions: int, repeats: int) -> float:
    """Wall time of one env step [s]: the PettingZoo dict step (``copies == 1``) or the batched
    ``make_vec`` step, random actions."""
    import satenv

    rng = np.random.default_rng(0)
    if copies == 1:
        env = satenv.make(env_id, terminate_on_collision=False, **kwargs)
        acts = [dict(zip(env.possible_agents, rng.uniform(-1, 1, (len(env.possible_agents), env.core.action_dim)),
                         strict=True)) for _ in range(decisions)]
        env.reset(seed=0)

        def step(a):
            if not env.agents:
                env.reset()
            env.step(a)
        return _best(step, acts, repeats)
    vec = satenv.make_vec(env_id, copies, seed=0, terminate_on_collision=False, **kwargs)
    vec.reset()
    acts = [rng.uniform(-1, 1, vec.action_shape) for _ in range(decisions)]
    return _best(vec.step, acts, repeats)


def measure(env_id: str, kwargs: dict[str, Any], copies: int, decisions: int = 60, repeats: int = 3,
            seed: int = 0) -> dict[str, Any]:
    """One case (module docstring)."""
    from satenv.safety import filter_actions

    items, vec = _record(env_id, kwargs, copies, decisions, seed)
    model, cfg = vec.safety.model, vec.safety.config
    agents = copies * vec.n_agents
    interventions = []

    def run(item):
        _, rec = filter_actions(model, cfg, *item)
        interventions.append(int(rec.intervened.sum()))

    random_s = _best(run, items, repeats)
    safe_s = _best(lambda it: filter_actions(model, cfg, it[0], it[1], np.zeros_like(it[2])), items, repeats)
    step_s = _env_step_s(env_id, kwargs, copies, decisions, repeats)
    target = TARGETS.get((env_id, copies))
    ms = random_s * 1e3 / agents
    return {"env_id": env_id, "kwargs": kwargs, "copies": copies, "agents": vec.n_agents,
            "decisions": decisions, "interventions_per_call": float(np.mean(interventions)),
            "ms_per_call": random_s * 1e3, "ms_per_agent": ms, "ms_per_agent_all_safe": safe_s * 1e3 / agents,
            "step_ms_per_agent": step_s * 1e3 / agents, "ratio_to_step": random_s / step_s,
            "target_ms_per_agent": target, "met": None if target is None else bool(ms <= target)}


def run(options: Any = None, log=print, decisions: int = 60, repeats: int = 3, cases=CASES) -> dict[str, Any]:
    """Every case of :data:`CASES` (``options.scale`` shrinks the decisions); ``{"cases": [...],
    "targets": [...]}`` (the perf report's target format)."""
    decisions = max(5, int(decisions * getattr(options, "scale", 1.0)))
    out, targets = [], []
    for env_id, kwargs, copies in cases:
        res = measure(env_id, kwargs, copies, decisions, repeats)
        log(f"safety filter {env_id} {kwargs or ''} B={copies}: {res['ms_per_agent']:.4f} ms/agent "
            f"(all safe {res['ms_per_agent_all_safe']:.4f}; env step {res['step_ms_per_agent']:.4f}; "
            f"ratio {res['ratio_to_step']:.2f}; {res['interventions_per_call']:.2f} QPs/call)")
        out.append(res)
        if res["met"] is not None:
            targets.append({"name": f"safety filter {env_id} x{copies}: ms per agent decision",
                            "value": res["ms_per_agent"], "target": res["target_ms_per_agent"], "op": "<=",
                            "met": res["met"]})
    return {"cases": out, "targets": targets}
