"""Intervention-aware DAgger: fine-tune an imitation network so that it needs the safety filter less.

    nice -n 10 env OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m satenv.training.safe_imitation \\
        --system platoon-pereira2022 --warm-start satenv/training/policies/platoon_pereira2022_dagger_shield \\
        --run-dir studies/runs/platoon_pereira2022_safe_dagger

The same command resumes the run after its last finished round (``config.json`` of the run; flags
given again override it). Every round:

1. **collect** — the current network flies the system's training task (train seeds, collisions do
   not end the episode) *behind the safety filter* (:class:`satenv.safety.SafetyFilter`), so the
   labelled states are those the filtered policy reaches; at every agent-step the row stores the
   observation, the system's expert action, the expert action after the filter (the label:
   ``label="filtered"``; ``"teacher"``: the warm-start network's action after the filter, the
   shipped composite as the expert), the filter's output for the network's action, whether the filter
   intervened, and the filter's constraint rows at that state (:func:`agent_constraints`).
   ``fly="alone"``: the network flies without the filter (its own action applied, the filter's
   output and rows still recorded), so the expert labels the states where the network alone goes
   (``"mixed"``: alone and behind the filter in alternate episodes; ``"handover"``: alone until the
   first collision or hard-bound violation, then behind the filter). The expert (or teacher) acts
   at the state the flown network reached and is filtered there; the filter everywhere (labels,
   rows, flights, validation) is the warm start's shipped one (:func:`warm_start_filter`), except
   that ``label_filter`` (options of :class:`satenv.safety.SafetyConfig`) tightens the filter of the
   labels and the barrier rows only (:func:`label_filter_config`): the network then copies an
   expert held inside a smaller set, a slack for its imitation error against the shipped bounds;
2. **fit** (warm start, all rows of every round) on

   ``L = |pi(o) - y|^2 + w_int * |pi(o) - F(pi_flown(o))|^2 [intervened rows] + w_bar * sum_k relu(l_k + m - r_k . pi(o))^2``

   (the imitation and barrier terms of a row flown by the network alone weighted ``alone_weight``)
   — imitation of the (filtered) expert, the **intervention term** (distance to the filter's output
   for the flown action, where it intervened) and the **barrier term**: the filter's rows are the
   discrete barrier condition on the next state (``h(x+) >= (1 - gamma) h(x)``, linear in the
   action), so the hinge is zero exactly when the filter would leave the action alone (with the
   margin ``m`` inside), and differentiable in the network's output. ``prior_labels``: the labels
   folder of an earlier DAgger run (``obs``, ``act``), a batch of it imitated beside every batch
   with weight ``prior_weight`` (``+ w_prior |pi(o_p) - y_p|^2``), a task term that the other
   terms cannot trade away on the states the expert already labelled (compared in ``prior_space``,
   by default the imitation terms' space). ``imitation_space="network"``:
   the imitation terms compare the network's own output with the label (as the DAgger engine
   trained a warm start whose terminal feedback blends in near the target), not the flown action
   (for the expert's labels; the teacher's label is a flown action, compared in ``"flown"`` space:
   :func:`check_label_space`);
3. **validate** on validation seeds only: the network alone (collision and violation episodes,
   success) and behind the filter (interventions per agent-step); the round is chosen on these.

``--ship satenv/training/policies/<name>`` copies the round :func:`choose` picks on validation (or
``--ship-round k``) to a new policy folder; ``--validate-round k`` validates round ``k`` (``-1``: the warm
start) on ``--val-seeds`` / ``--val-shield-seeds`` seeds into ``<run>/validation/``. Rows, labels and history go to ``<run>/labels/round_NNNN.npz``, ``<run>/rounds/NNNN/`` (policy
folder format) and ``<run>/history.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from satenv.errors import SatenvError

__all__ = ["SafeDaggerConfig", "EXPERTS", "agent_constraints", "barrier_hinge", "terminal_affine", "run", "main"]

ROW_LOWER_FLOOR = -10.0
"""Normalised row bounds below this never bind an action in the unit box (stored clipped here)."""


def _joint_platoon(env: Any) -> Any:
    from satenv.baselines.experts import JointPlatoonMPC

    return JointPlatoonMPC(env, coupling="sequential")


def _replanning_tube(env: Any) -> Any:
    from satenv.baselines.experts import ReplanningTubeRDMPC

    return ReplanningTubeRDMPC(env)


EXPERTS: dict[str, Any] = {"platoon-pereira2022": _joint_platoon, "platoon-pereira2023": None,
                           "cluster-li2022": _replanning_tube, "servicing-pereira2022": None}
"""The expert that labels each system's states (a stateless re-planner where there is one;
``None``: the system has none better than the filtered network, whose own filtered action is the
label, ``label="self"``)."""


LABELS = ("filtered", "expert", "self", "teacher")
IMITATION_SPACES = ("flown", "network")
"""Where the imitation terms compare with the label: the flown action (the policy's terminal
feedback blended in, as the filter sees it) or the network's own output (as the DAgger engine,
:func:`satenv.training.imitate.regress`, trained a warm start with terminal feedback). The barrier and
intervention terms are always on the flown action."""

FLIGHTS = ("filtered", "alone", "mixed", "handover")
"""Who flies the collection episodes: the network behind the filter (the labelled states are those
the shipped composite reaches), the network alone (the states where it needs the filter; the
filter's output and rows are still recorded, the network's own action is applied), or both
(``"mixed"``: a round's even-numbered episodes alone, the odd ones behind the filter;
``"handover"``: each episode alone until its first collision or hard-bound violation, then behind
the filter, so the labelled states are the network's own up to its failure and the composite's
recovery from it, not the network's flight on after a collision)."""
EPISODE_FLIGHTS = ("filtered", "alone", "handover")
"""How one collection episode is flown (``"mixed"`` chooses between the first two per episode)."""
"""What the network imitates: the system's expert after the filter or as it is, the filter's output
for the network's own action (self-distillation of the filtered network), or the filter's output
for the *warm-start* network's action (the shipped composite, network + filter, as a frozen expert)."""


@dataclass(frozen=True)
class SafeDaggerConfig:
    """One run (every field is a ``--flag`` taking a JSON value)."""

    system: str = "platoon-pereira2022"
    warm_start: str = "satenv/training/policies/platoon_pereira2022_dagger_shield"
    rounds: int = 8
    episodes_per_round: int = 12
    train_seed: int = 610_000
    val_seeds: int = 100                 # network alone: validation seeds 700000.. (this many)
    val_shield_seeds: int = 20           # behind the filter (interventions)
    label: str = "filtered"              # "filtered": F(expert), "expert": raw expert, "self": F(network),
    #                                      "teacher": F(warm-start network), the shipped composite as expert
    w_int: float = 1.0
    w_bar: float = 10.0
    bar_margin: float = 0.02
    epochs: int = 4
    batch_size: int = 512
    learning_rate: float = 1e-4
    seed: int = 0
    fly: str = "filtered"                # FLIGHTS
    prior_labels: str = ""               # a DAgger run's labels folder (round_*.npz with obs, act): rows
    #                                      imitated in every batch beside the run's own (anchors the task)
    prior_weight: float = 1.0
    imitation_space: str = "flown"       # IMITATION_SPACES
    prior_space: str = ""                # IMITATION_SPACES for the prior term ("": imitation_space); a DAgger
    #                                      run's labels are the expert's action, "network" with terminal feedback
    label_filter: dict = field(default_factory=dict)   # SafetyConfig options over the shipped filter, for the
    #                                      labels and barrier rows only ({}: the shipped filter)
    collect_decisions: int = 0           # a collection episode stops after this many decisions (0: at its end)
    alone_weight: float = 1.0            # weight of the rows flown by the network alone in the imitation and
    #                                      barrier terms (rows of label files without the flag count as 1)

    def __post_init__(self) -> None:
        if self.system not in EXPERTS:
            raise SatenvError(f"system must be one of {sorted(EXPERTS)}, got {self.system!r}")
        if self.label not in LABELS:
            raise SatenvError(f"label must be one of {list(LABELS)}, got {self.label!r}")
        if self.imitation_space not in IMITATION_SPACES:
            raise SatenvError(f"imitation_space must be one of {list(IMITATION_SPACES)}, got {self.imitation_space!r}")
        if self.prior_space not in ("", *IMITATION_SPACES):
            raise SatenvError(f"prior_space must be '' or one of {list(IMITATION_SPACES)}, got {self.prior_space!r}")
        if self.fly not in FLIGHTS:
            raise SatenvError(f"fly must be one of {list(FLIGHTS)}, got {self.fly!r}")
        if not isinstance(self.label_filter, dict):
            raise SatenvError(f"label_filter must be a dict of SafetyConfig options, got {self.label_filter!r:.60}")
        if self.label_filter:
            from satenv.safety import SafetyConfig
            SafetyConfig.from_options(**self.label_filter)     # unknown or out-of-range options raise here
        if self.prior_labels and not Path(self.prior_labels).is_dir():
            raise SatenvError(f"prior_labels must be a folder of round_*.npz label files, got {self.prior_labels!r}")
        if EXPERTS[self.system] is None and self.label in ("filtered", "expert"):
            raise SatenvError(f"system {self.system!r} has no expert here: label must be 'self' or 'teacher', "
                              f"got {self.label!r}")
        if isinstance(self.collect_decisions, bool) or not isinstance(self.collect_decisions, int) \
                or self.collect_decisions < 0:
            raise SatenvError(f"collect_decisions must be an int >= 0 (0: whole episodes), got {self.collect_decisions!r}")
        for name in ("w_int", "w_bar", "bar_margin", "learning_rate", "prior_weight", "alone_weight"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise SatenvError(f"{name} must be a finite number >= 0, got {v!r}")

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


# --------------------------------------------------------------------------- the filter's rows
def agent_constraints(filt: Any, applied: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each agent's filter constraints at the filter's current state, ``rows (M, K, d)`` and
    ``lower (M, K)``, in normalised action space and scaled to unit rows: an action ``a`` of
    agent ``i`` passes the filter untouched iff ``rows[i] @ eff(a) >= lower[i]`` for every ``k``
    (``eff``: the env's clipping). ``applied (M, d)`` are the actions the filter let through this
    step: down a chain, a chaser's rows hold its target's applied acceleration, as in the filter.
    Unused slots get ``lower = ROW_LOWER_FLOOR``."""
    from satenv.safety import _effective, _omega_rows, constraint_rows, quat_to_matrix

    m, cfg = filt.model, filt.config
    x = np.asarray(filt.core.x, dtype=float)[:1]
    t = np.asarray(filt.core.t, dtype=float).reshape(-1)[:1] * float(filt.core.scenario.dt)
    w, lo = constraint_rows(m, cfg, x, t)
    s = m.S if not m.body_frame else np.einsum("bmij,jk->bmik", quat_to_matrix(x[..., 6:10]), m.S)
    rows = (np.einsum("bmki,ij->bmkj", w, s) if s.ndim == 2 else np.einsum("bmki,bmij->bmkj", w, s))[0]
    lo = lo[0].copy()
    if m.attitude is not None:
        w_om, lo_om = _omega_rows(m, cfg, x)
        rows, lo = np.concatenate([rows, w_om[0]], axis=1), np.concatenate([lo, lo_om[0]], axis=1)
    if m.n_chain:
        slots = m.budget[0].shape[1]
        idx = np.r_[slots - m.n_chain:slots, 2 * slots - m.n_chain:2 * slots]
        acc = _effective(m, np.asarray(applied, dtype=float)) @ m.S.T     # chains are never body-frame
        for f in range(1, len(lo)):
            lo[f, idx] += w[0, f, idx] @ acc[f - 1]
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


# --------------------------------------------------------------------------- collection
def collect_episode(env: Any, expert: Any, net: Any, seed: int, fly: str = "filtered",
                    filter_config: Any = None, label_config: Any = None,
                    max_decisions: int = 0) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The network flies ``env`` behind the filter (``fly="alone"``: without it, the filter's output
    only recorded; ``"handover"``: alone until the first collision or hard-bound violation, then
    behind the filter); every agent-step labelled (module docstring). Without an expert (``None``) the
    expert columns hold the network's own action. The expert (a re-planner, or the frozen teacher
    network) acts on the observation of the state the flown network reached, and its action is
    filtered at that state. ``filter_config``: the :class:`satenv.safety.SafetyConfig` of the filter
    (the warm start's shipped one, :func:`warm_start_filter`; ``None``: the default); ``label_config``
    the filter of the labels and the barrier rows (``None``: ``filter_config``); ``max_decisions`` > 0
    stops the episode after that many decisions (the early states of many starts)."""
    from satenv.safety import SafetyFilter

    if fly not in EPISODE_FLIGHTS:
        raise SatenvError(f"collect_episode: fly must be one of {list(EPISODE_FLIGHTS)}, got {fly!r}")
    obs, _ = env.reset(seed=seed)
    if expert is not None:
        expert.reset(seed=seed)
    net.reset(seed=seed)
    filt = SafetyFilter(env, filter_config)
    lfilt = filt if label_config is None else SafetyFilter(env, label_config)
    agents = list(env.possible_agents)
    rows: dict[str, list] = {k: [] for k in ("obs", "expert", "label", "filtered", "flown", "intervened",
                                             "rows", "lower", "alone")}
    collided, interventions, steps, infos = False, 0, 0, {}
    alone, alone_steps = fly != "filtered", 0
    while env.agents:
        if len(env.agents) != len(agents) or (max_decisions and steps >= max_decisions * len(agents)):
            break
        o = np.stack([obs[a] for a in agents])
        n = net.predict(o).astype(float)
        n_f, rec = filt.filter(n)
        if expert is None:
            e, e_f = n, (n_f if lfilt is filt else lfilt.filter(n)[0])
        else:
            lab = expert.act(obs)
            e = np.stack([np.asarray(lab[a], dtype=float) for a in agents])
            e_f, _ = lfilt.filter(np.clip(e, -1, 1))
        applied = _box(n) if alone else n_f
        alone_steps += len(agents) if alone else 0
        r, lo = agent_constraints(lfilt, applied)
        rows["obs"].append(o)
        rows["expert"].append(e)
        rows["label"].append(e_f)
        rows["filtered"].append(n_f)
        rows["flown"].append(n)
        rows["intervened"].append(rec.intervened[0])
        rows["rows"].append(r)
        rows["lower"].append(lo)
        rows["alone"].append(np.full(len(agents), alone))
        interventions += int(rec.intervened.sum())
        steps += len(agents)
        obs, _, _, _, infos = env.step({a: applied[i].astype(np.float32) for i, a in enumerate(agents)})
        collided |= any(bool(i.get("collision")) for i in infos.values())
        if fly == "handover" and any(bool(i.get("collision")) or bool(i.get("violations")) for i in infos.values()):
            alone = False
    out = {k: np.concatenate(v).astype(bool if k in ("intervened", "alone") else np.float32) for k, v in rows.items()}
    return out, {"seed": seed, "agent_steps": steps, "interventions": interventions, "collision": collided,
                 "alone_agent_steps": alone_steps}


def _box(a: np.ndarray) -> np.ndarray:
    return np.clip(np.nan_to_num(np.asarray(a, dtype=float)), -1.0, 1.0)


# --------------------------------------------------------------------------- fit
def _inputs(policy: Any, obs: np.ndarray) -> Any:
    """The actor's input for raw observations (the policy's features, then its normaliser)."""
    import torch

    return torch.as_tensor(policy.normalizer(policy.features(obs.astype(np.float64))
                                             if policy.features is not None else obs), dtype=torch.float32)


def fit(policy: Any, data: dict[str, np.ndarray], cfg: SafeDaggerConfig, norm_mode: bool,
        generator: Any, prior: dict[str, np.ndarray] | None = None) -> dict[str, float]:
    """Adam on the loss of the module docstring (``policy.actor`` in place); the epoch-mean terms.
    ``prior`` (``obs``, ``act``): rows of an earlier DAgger run, a batch of the same size drawn from
    them at every step and imitated with weight ``cfg.prior_weight`` (the ``prior`` term)."""
    import torch

    x = _inputs(policy, data["obs"])
    key = {"filtered": "label", "expert": "expert", "self": "filtered", "teacher": "label"}[cfg.label]
    y = torch.as_tensor(data[key], dtype=torch.float32).clamp(-1, 1)
    power = float(policy.action_map.power) if policy.action_map is not None else 1.0
    offset, slope = (torch.as_tensor(v, dtype=torch.float32) for v in terminal_affine(policy, data["obs"], y.shape[-1]))
    f = torch.as_tensor(data["filtered"], dtype=torch.float32)
    mask = torch.as_tensor(data["intervened"], dtype=torch.float32)
    rows, lower = torch.as_tensor(data["rows"]), torch.as_tensor(data["lower"])
    alone = data.get("alone", np.zeros(len(data["obs"]), dtype=bool))
    w = 1.0 + (cfg.alone_weight - 1.0) * torch.as_tensor(alone, dtype=torch.float32)   # per-row weight
    if prior is not None:
        px = _inputs(policy, prior["obs"])
        py = torch.as_tensor(prior["act"], dtype=torch.float32).clamp(-1, 1)
        p_off, p_slope = (torch.as_tensor(v, dtype=torch.float32)
                          for v in terminal_affine(policy, prior["obs"], py.shape[-1]))
    on_flown = cfg.imitation_space == "flown"
    prior_on_flown = (cfg.prior_space or cfg.imitation_space) == "flown"
    actor = policy.actor
    opt = torch.optim.Adam(actor.parameters(), lr=cfg.learning_rate)
    actor.train()
    terms = {}
    for _ in range(cfg.epochs):
        sums = np.zeros(4)
        for idx in torch.randperm(len(x), generator=generator).split(cfg.batch_size):
            out = _env_action(actor(x[idx]), power)
            a = offset[idx] + slope[idx] * out
            imit = (w[idx] * (((a if on_flown else out) - y[idx]) ** 2).sum(-1)).mean()
            inter = (mask[idx] * ((a - f[idx]) ** 2).sum(-1)).mean()
            bar = (w[idx] * barrier_hinge(a, rows[idx], lower[idx], cfg.bar_margin, norm_mode)).mean()
            loss = imit + cfg.w_int * inter + cfg.w_bar * bar
            pri = torch.zeros(())
            if prior is not None:
                j = torch.randint(len(px), (len(idx),), generator=generator)
                pout = _env_action(actor(px[j]), power)
                pa = p_off[j] + p_slope[j] * pout if prior_on_flown else pout
                pri = ((pa - py[j]) ** 2).sum(-1).mean()
                loss = loss + cfg.prior_weight * pri
            opt.zero_grad()
            loss.backward()
            opt.step()
            sums += np.array([imit.item(), inter.item(), bar.item(), pri.item()]) * len(idx)
        terms = dict(zip(("imitation", "intervention", "barrier", "prior"), (sums / len(x)).tolist(), strict=True))
    actor.eval()
    return terms


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


def _env_action(out: Any, power: float) -> Any:
    """The actor's output as the env action (clipped, then the action map ``sign(y)|y|^power``)."""
    import torch

    y = torch.clamp(out, -1.0, 1.0)
    return y if power == 1.0 else torch.sign(y) * torch.abs(y).clamp_min(1e-12) ** power


# --------------------------------------------------------------------------- validation
def validate(task: Any, policy: Any, cfg: SafeDaggerConfig, filter_config: Any = None) -> dict[str, Any]:
    """The network alone on ``cfg.val_seeds`` validation seeds and behind the filter (its
    ``filter_config``, the warm start's shipped one) on the first ``cfg.val_shield_seeds``
    (:func:`satenv.scoring.aggregate` of each)."""
    from satenv.safety import shield
    from satenv.scoring import aggregate, run_episodes

    env = task.make_env()
    alone = aggregate(run_episodes(env, policy, task.seeds("validation", cfg.val_seeds)))
    shipped = aggregate(run_episodes(env, shield(policy, env, filter_config),
                                     task.seeds("validation", cfg.val_shield_seeds)))
    return {"alone": alone, "shield": shipped}


def selection_key(v: dict[str, Any]) -> tuple[float, ...]:
    """How rounds are ranked on validation (ascending): collision episodes, violation episodes of
    the network alone, then its failures, then the filter's interventions per agent-step."""
    a, s = v["alone"], v["shield"]
    return (a["collision_episodes"], a["violation_episodes"], -a["success_rate"],
            s.get("interventions_per_agent_step") or 0.0)


# --------------------------------------------------------------------------- run
def warm_start_filter(folder: Path) -> Any:
    """The :class:`satenv.safety.SafetyConfig` the warm start ships with (``env.json``
    ``"safety_filter"``; the default filter when it ships none): the labels, the rows, the flights
    behind the filter and the validation use the filter of the shipped composite (servicing ships
    with a 0.005 margin, against the default 0.02 that would hold its servicers off their final
    waypoints)."""
    from satenv.safety import SafetyConfig
    from satenv.training.policy import shipped_filter

    meta = json.loads((Path(folder) / "env.json").read_text())
    return shipped_filter(Path(folder), meta) or SafetyConfig()


def label_filter_config(cfg: SafeDaggerConfig, shipped: Any) -> Any:
    """The filter of the labels and the barrier rows: the ``shipped`` one with ``cfg.label_filter``'s
    options replaced (``None`` when there are none: the shipped filter itself)."""
    from satenv.safety import SafetyConfig

    return SafetyConfig.from_options(shipped, **cfg.label_filter) if cfg.label_filter else None


def check_label_space(cfg: SafeDaggerConfig, policy: Any) -> None:
    """Refuse teacher labels compared with the network's own output when the warm start blends in
    terminal feedback: the teacher's label is a *flown* action (its feedback blended in, then
    filtered), so ``imitation_space="network"`` would pull the network's raw output towards the
    flown action, away from the warm start even where the filter passes it; ``"flown"`` has the
    warm start as its minimiser wherever the filter leaves the teacher's action alone."""
    term = getattr(policy, "terminal", None)
    if cfg.label == "teacher" and cfg.imitation_space == "network" and term is not None \
            and getattr(term, "active", True):
        raise SatenvError("imitation_space must be 'flown' with label 'teacher' when the warm start has terminal "
                          "feedback (the teacher's label is a flown action), got 'network'")


def episode_flight(cfg: SafeDaggerConfig, j: int) -> str:
    """Who flies episode ``j`` of a round (:data:`FLIGHTS`; ``"mixed"``: even ``j`` alone, odd behind the filter)."""
    if cfg.fly != "mixed":
        return cfg.fly
    return "alone" if j % 2 == 0 else "filtered"


def run(cfg: SafeDaggerConfig, run_dir: Path) -> None:
    import torch

    from satenv import tasks
    from satenv.safety import safety_model
    from satenv.training.policy import load, save_artifacts

    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "labels").mkdir(exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps(cfg.to_json(), indent=2) + "\n")
    task = tasks.training_task(cfg.system)
    collect_env = task.make_env(terminate_on_collision=False)
    if cfg.label == "teacher":   # the warm-start network; collect_episode filters its action
        expert = load(Path(cfg.warm_start), shielded=False)
    elif cfg.label in ("filtered", "expert"):
        expert = EXPERTS[cfg.system](collect_env)
    else:
        expert = None
    norm_mode = safety_model(collect_env).norm_mode if hasattr(collect_env, "core") else False
    filter_config = warm_start_filter(Path(cfg.warm_start))
    label_config = label_filter_config(cfg, filter_config)
    history_path = run_dir / "history.json"
    history = json.loads(history_path.read_text()) if history_path.is_file() else []
    done = len(history)
    last = history[-1]["round"] if history else -1     # round -1: the warm start's validation only
    start = run_dir / "rounds" / f"{last:04d}" if last >= 1 else Path(cfg.warm_start)
    policy = load(start, shielded=False)
    check_label_space(cfg, policy)
    warm_meta = json.loads((Path(cfg.warm_start) / "env.json").read_text())
    warm_cfg = json.loads((Path(cfg.warm_start) / "config.json").read_text())
    if not history:   # round -1: the warm start itself on the same validation seeds
        history.append({"round": -1, "source": str(cfg.warm_start), "val": validate(task, policy, cfg, filter_config)})
        history_path.write_text(json.dumps(history, indent=1) + "\n")
        done = 1
    generator = torch.Generator().manual_seed(cfg.seed + done)
    prior = _load_prior(Path(cfg.prior_labels)) if cfg.prior_labels else None
    t_start = time.perf_counter()
    for k in range(done, cfg.rounds + 1):
        t0 = time.perf_counter()
        labels, stats_path = run_dir / "labels" / f"round_{k:04d}.npz", run_dir / "labels" / f"round_{k:04d}.json"
        if labels.is_file() and stats_path.is_file():     # collected before a stop: the rows are kept
            flown = json.loads(stats_path.read_text())
        else:
            parts, flown = [], []
            for j in range(cfg.episodes_per_round):
                part, stats = collect_episode(collect_env, expert, policy,
                                              cfg.train_seed + (k - 1) * cfg.episodes_per_round + j,
                                              episode_flight(cfg, j), filter_config, label_config,
                                              cfg.collect_decisions)
                stats["fly"] = episode_flight(cfg, j)
                parts.append(part)
                flown.append(stats)
            batch = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
            np.savez_compressed(labels, **batch)
            stats_path.write_text(json.dumps(flown, default=_json_scalar) + "\n")
        collect_s = time.perf_counter() - t0
        data = _load_rows(run_dir)
        t1 = time.perf_counter()
        terms = fit(policy, data, cfg, norm_mode, generator, prior)
        fit_s = time.perf_counter() - t1
        t2 = time.perf_counter()
        val = validate(task, policy, cfg, filter_config)
        val_s = time.perf_counter() - t2
        config = {**warm_cfg, "recipe": "satenv.training.safe_imitation", "safe_dagger": cfg.to_json(), "round": k}
        save_artifacts(run_dir / "rounds" / f"{k:04d}", policy, env_meta=warm_meta, config=config,
                       source="satenv.training.safe_imitation round checkpoint")
        steps = sum(s["agent_steps"] for s in flown)
        history.append({"round": k, "rows": int(len(data["obs"])), "loss": terms,
                        "weights": {f: getattr(cfg, f) for f in ("label", "label_filter", "collect_decisions",
                                                                 "alone_weight", "fly",
                                                                 "w_int", "w_bar",
                                                                 "bar_margin",
                                                                 "prior_weight", "imitation_space", "prior_space",
                                                                 "learning_rate",
                                                                 "epochs")}, "collect_s": round(collect_s, 1),
                        "fit_s": round(fit_s, 1), "val_s": round(val_s, 1),
                        "session_wall_s": round(time.perf_counter() - t_start, 1),
                        "flown_interventions_per_agent_step": sum(s["interventions"] for s in flown) / max(1, steps),
                        "flown_collisions": sum(s["collision"] for s in flown), "val": val})
        history_path.write_text(json.dumps(history, indent=1) + "\n")
        a, s = val["alone"], val["shield"]
        print(f"round {k}: rows {len(data['obs'])} loss {json.dumps({t: round(v, 5) for t, v in terms.items()})} "
              f"alone: success {a['success_rate']:.2f} coll {a['collision_episodes']} viol {a['violation_episodes']} "
              f"final err {_final_error(a)} | shield: success {s['success_rate']:.2f} final err {_final_error(s)} "
              f"interv/step {s.get('interventions_per_agent_step', 0):.4f} "
              f"| collect {collect_s:.0f}s fit {fit_s:.0f}s val {val_s:.0f}s", flush=True)


def _final_error(agg: dict[str, Any]) -> str:
    f = agg.get("final_error_m")
    return f"{f:.1f} m" if isinstance(f, (int, float)) else "n/a"


def choose(run_dir: Path) -> int:
    """The round of a run to ship: the lowest :func:`selection_key` on validation (round -1, the
    warm start, competes too: a run that never beat it returns -1)."""
    history = json.loads((run_dir / "history.json").read_text())
    return min(history, key=lambda h: (*selection_key(h["val"]), -h["round"]))["round"]


def ship(run_dir: Path, k: int, dest: Path) -> Path:
    """Copy round ``k`` of a run to the policy folder ``dest`` (a new folder: an existing one is an
    error) with the run's history; returns ``dest``."""
    import shutil

    from satenv.training.policy import write_manifest

    src = run_dir / "rounds" / f"{k:04d}"
    if not src.is_dir():
        raise SatenvError(f"ship: {src} is not a round folder of the run")
    if dest.exists():
        raise SatenvError(f"ship: {dest} exists; a shipped folder is never overwritten")
    shutil.copytree(src, dest)
    shutil.copy(run_dir / "history.json", dest / "history.json")
    write_manifest(dest)
    return dest


def validate_round(cfg: SafeDaggerConfig, run_dir: Path, k: int) -> Path:
    """Round ``k`` of a run (``-1``: the warm start) on ``cfg.val_seeds`` / ``cfg.val_shield_seeds``
    validation seeds (:func:`validate`, the warm start's shipped filter), written to
    ``<run>/validation/round_NNNN_<alone>_<filtered>.json``; returns that path."""
    from satenv import tasks
    from satenv.training.policy import load

    folder = Path(cfg.warm_start) if k == -1 else run_dir / "rounds" / f"{k:04d}"
    if not folder.is_dir():
        raise SatenvError(f"validate_round: round {k} has no folder {folder}")
    val = validate(tasks.training_task(cfg.system), load(folder, shielded=False), cfg,
                   warm_start_filter(Path(cfg.warm_start)))
    out = run_dir / "validation" / f"round_{k:04d}_{cfg.val_seeds}_{cfg.val_shield_seeds}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"round": k, "source": str(folder), "val": val}, indent=1, default=float) + "\n")
    return out


def _json_scalar(v: Any) -> Any:
    """numpy scalars in the flown-episode stats as JSON values."""
    return v.item() if isinstance(v, np.generic) else str(v)


def _load_prior(folder: Path) -> dict[str, np.ndarray]:
    """``obs`` and ``act`` of every ``round_*.npz`` of a DAgger run's labels folder."""
    parts = []
    for f in sorted(folder.glob("round_*.npz")):
        with np.load(f, allow_pickle=False) as d:
            if "obs" not in d.files or "act" not in d.files:
                raise SatenvError(f"prior_labels: {f} has no 'obs' and 'act' arrays (has {d.files})")
            parts.append({"obs": d["obs"].astype(np.float32), "act": d["act"].astype(np.float32)})
    if not parts:
        raise SatenvError(f"prior_labels: no round_*.npz in {folder}")
    return {k: np.concatenate([p[k] for p in parts]) for k in ("obs", "act")}


def _load_rows(run_dir: Path) -> dict[str, np.ndarray]:
    """Every round's rows of a run; a label file written before the ``alone`` flag counts its rows
    as flown behind the filter."""
    parts = []
    for f in sorted((run_dir / "labels").glob("round_*.npz")):
        with np.load(f, allow_pickle=False) as d:
            part = {k: d[k] for k in d.files}
        part.setdefault("alone", np.zeros(len(part["obs"]), dtype=bool))
        parts.append(part)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run-dir", required=True, type=Path)
    parser.add_argument("--ship", type=Path, default=None,
                        help="ship the round chosen on validation (or --ship-round) to this new policy folder")
    parser.add_argument("--ship-round", type=int, default=None)
    parser.add_argument("--validate-round", type=int, default=None,
                        help="only validate this round (-1: the warm start) on --val-seeds / --val-shield-seeds")
    for f in SafeDaggerConfig.__dataclass_fields__.values():
        parser.add_argument("--" + f.name.replace("_", "-"), type=str, default=None, help="a JSON value")
    ns = parser.parse_args(argv)
    if ns.ship is not None:
        k = choose(ns.run_dir) if ns.ship_round is None else ns.ship_round
        print(f"shipped round {k} to {ship(ns.run_dir, k, ns.ship)}")
        return
    saved = ns.run_dir / "config.json"
    base = SafeDaggerConfig(**json.loads(saved.read_text())) if saved.is_file() else SafeDaggerConfig()
    over = {}
    for k, v in vars(ns).items():
        if k in ("run_dir", "ship", "ship_round", "validate_round") or v is None:
            continue
        over[k] = v if SafeDaggerConfig.__dataclass_fields__[k].type in (str, "str") else json.loads(v)
    if ns.validate_round is not None:
        path = validate_round(replace(base, **over), ns.run_dir, ns.validate_round)
        val = json.loads(path.read_text())["val"]
        print(f"wrote {path}: " + json.dumps({w: {m: val[w].get(m) for m in ("success_rate", "collision_episodes",
              "violation_episodes", "interventions_per_agent_step")} for w in val}))
        return
    run(replace(base, **over), ns.run_dir)


if __name__ == "__main__":
    main()
