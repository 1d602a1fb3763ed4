"""Flying and labelling one episode (:func:`collect_episode`, the one collector of imitation).

Every visited agent-step becomes a row: the agent's observation, the expert's action there
(``act``), the env state, the agent's index and the decision. DAgger (``fly="dagger"``) flies the
expert's action with probability ``beta`` per decision, else the learner's, plus Gaussian noise.
The safe flights fly the learner and record the safety filter at every decision: the expert's
action through the label filter (``label``), the filter's output for the network's action
(``filtered``), the network's action (``flown``), whether the filter intervened, the label
filter's constraint rows (``rows``, ``lower``: :func:`satenv.training.imitation.barrier.agent_constraints`)
and whether the network flew alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from satenv.errors import SatenvError

__all__ = ["EPISODE_FLIGHTS", "collect_episode", "episode_flight"]

EPISODE_FLIGHTS = ("dagger", "filtered", "alone", "handover")
"""How one episode is flown (``"mixed"`` chooses between ``"alone"`` and ``"filtered"`` per episode)."""
BOOL_ROWS = ("intervened", "alone")
FLOAT_ROWS = ("obs", "act", "label", "filtered", "flown", "rows", "lower")


def episode_flight(fly: str, j: int) -> str:
    """Who flies episode ``j`` of a round (``"mixed"``: even ``j`` alone, odd behind the filter)."""
    if fly != "mixed":
        return fly
    return "alone" if j % 2 == 0 else "filtered"


def collect_episode(env: Any, expert: Any, learner: Any, seed: int, *, beta: float = 1.0, noise: float = 0.0,
                    rng: np.random.Generator | None = None, fly: str = "dagger", filter_config: Any = None,
                    label_config: Any = None, max_decisions: int = 0) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """One episode's rows (module docstring) and how it ended (``stats``: decisions, agent-steps,
    final position error, collision, closest approach; safe flights: interventions and agent-steps
    flown alone).

    ``fly="dagger"``: ``expert`` labels, the learner (``None``: the expert alone) flies with
    probability ``1 - beta``, draws from ``rng``. Safe flights (``"filtered"``, ``"alone"``,
    ``"handover"``: alone until the first collision or hard-bound violation, then behind the
    filter): ``learner`` (``predict``) flies, ``expert`` (``None``: the network's own action)
    acts at the state the learner reached and is filtered there; ``filter_config`` is the
    filter's :class:`satenv.safety.SafetyConfig`, ``label_config`` the labels' and rows' filter
    (``None``: the same); ``max_decisions`` > 0 stops the episode after that many decisions."""
    if fly not in EPISODE_FLIGHTS:
        raise SatenvError(f"collect_episode: fly must be one of {list(EPISODE_FLIGHTS)}, got {fly!r:.40}")
    obs, _ = env.reset(seed=seed)
    for actor in (expert, learner):
        if actor is not None:
            actor.reset(seed=seed)
    order = list(env.possible_agents)
    step = _dagger_step(expert, learner, beta, noise, rng) if fly == "dagger" else \
        _SafeStep(env, expert, learner, fly, filter_config, label_config)
    rows: dict[str, list] = {}
    t, collided, min_sep, infos = 0, False, math.inf, {}
    while env.agents:
        if fly != "dagger" and (len(env.agents) != len(order) or (max_decisions and t >= max_decisions)):
            break
        agents = order if fly != "dagger" else list(obs)
        applied, columns = step(obs, agents)
        state = np.asarray(env.state(), dtype=np.float64)
        for key, value in {**columns, "state": np.repeat(state[None], len(agents), 0),
                           "agent": np.array([order.index(a) for a in agents]),
                           "t": np.full(len(agents), t)}.items():
            rows.setdefault(key, []).append(value)
        obs, _, _, _, infos = env.step(applied)
        collided |= any(bool(i.get("collision", False)) for i in infos.values())
        min_sep = min(min_sep, *(float(i.get("min_separation", math.inf)) for i in infos.values()))
        if isinstance(step, _SafeStep):
            step.after(infos)
        t += 1
    errors = [float(np.linalg.norm(np.asarray(i["tracking_error"])[:3])) for i in infos.values()
              if "tracking_error" in i]
    stats = {"seed": seed, "steps": t, "agent_steps": sum(len(c) for c in rows.get("t", [])),
             "final_error_m": round(max(errors), 4) if errors else None, "collision": collided,
             "min_separation_m": round(min_sep, 3) if math.isfinite(min_sep) else None,
             "learner": learner is not None, "noise": noise}
    if isinstance(step, _SafeStep):
        stats.update(interventions=step.interventions, alone_agent_steps=step.alone_steps, fly=fly)
    return {k: _array(k, v) for k, v in rows.items()}, stats


def _array(key: str, parts: list) -> np.ndarray:
    out = np.concatenate(parts)
    if key in BOOL_ROWS:
        return out.astype(bool)
    return out.astype(np.float32) if key in FLOAT_ROWS else out


def _dagger_step(expert: Any, learner: Any, beta: float, noise: float, rng: Any) -> Any:
    """One DAgger decision: the expert's labels; the flown actions (the expert's with probability
    ``beta``, else the learner's) with Gaussian noise of std ``noise``."""
    def step(obs: dict[str, Any], agents: list[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        labels = expert.act(obs)
        flown = labels if learner is None or rng.random() < beta else learner.act(obs)
        if noise > 0:
            flown = {a: np.clip(v + rng.normal(0, noise, np.shape(v)), -1, 1).astype(np.float32)
                     for a, v in flown.items()}
        return flown, {"obs": np.stack([obs[a] for a in agents]), "act": np.stack([labels[a] for a in agents])}
    return step


class _SafeStep:
    """One decision of a safe flight: the network's action, the filter's output for it, the
    expert's action through the label filter, the label filter's rows; the applied action (the
    network's own while alone, else the filtered one)."""

    def __init__(self, env: Any, expert: Any, net: Any, fly: str, filter_config: Any, label_config: Any):
        from satenv.safety import SafetyFilter

        self.expert, self.net, self.fly = expert, net, fly
        self.filt = SafetyFilter(env, filter_config)
        self.lfilt = self.filt if label_config is None else SafetyFilter(env, label_config)
        self.alone = fly != "filtered"
        self.interventions = self.alone_steps = 0

    def __call__(self, obs: dict[str, Any], agents: list[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        from satenv.training.imitation.barrier import agent_constraints

        o = np.stack([obs[a] for a in agents])
        n = self.net.predict(o).astype(float)
        n_f, rec = self.filt.filter(n)
        if self.expert is None:
            e, e_f = n, (n_f if self.lfilt is self.filt else self.lfilt.filter(n)[0])
        else:
            lab = self.expert.act(obs)
            e = np.stack([np.asarray(lab[a], dtype=float) for a in agents])
            e_f, _ = self.lfilt.filter(np.clip(e, -1, 1))
        applied = np.clip(np.nan_to_num(n), -1.0, 1.0) if self.alone else n_f
        rows, lower = agent_constraints(self.lfilt, applied)
        self.alone_steps += len(agents) if self.alone else 0
        self.interventions += int(rec.intervened.sum())
        columns = {"obs": o, "act": e, "label": e_f, "filtered": n_f, "flown": n, "intervened": rec.intervened[0],
                   "rows": rows, "lower": lower, "alone": np.full(len(agents), self.alone)}
        return {a: applied[i].astype(np.float32) for i, a in enumerate(agents)}, columns

    def after(self, infos: dict[str, Any]) -> None:
        """A hand-over flight goes behind the filter after its first collision or violation."""
        if self.fly == "handover" and any(bool(i.get("collision")) or bool(i.get("violations"))
                                          for i in infos.values()):
            self.alone = False
