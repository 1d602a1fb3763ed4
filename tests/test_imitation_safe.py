"""satenv.training.imitation's safe variants: the filter's rows as a differentiable barrier, the
collection behind (or beside) the filter, the frozen composite (warm start + its shipped filter)
as the teacher, the safe loss's terms and the choice of the round to ship."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from satenv import tasks  # noqa: E402
from satenv.errors import SatenvError  # noqa: E402
from satenv.perturbations import UncertaintyBounds  # noqa: E402
from satenv.safety import SafetyConfig, SafetyFilter  # noqa: E402
from satenv.training.imitation.barrier import (  # noqa: E402
    agent_constraints,
    barrier_hinge,
    env_action,
    terminal_affine,
)
from satenv.training.imitation.collect import collect_episode, episode_flight  # noqa: E402
from satenv.training.imitation.config import ImitationConfig  # noqa: E402
from satenv.training.imitation.fit import fit_safe  # noqa: E402
from satenv.training.imitation.rounds import check_label_space, label_filter_config, safe_loss  # noqa: E402
from satenv.training.imitation.setup import warm_start_filter  # noqa: E402

WARM = "satenv/training/policies/platoon_pereira2022_dagger_shield"
SYSTEM_TASKS = {"platoon-pereira2022": "platoon-pereira2022-random", "platoon-pereira2023": "platoon-tplf30-random-cw",
                "servicing-pereira2022": "servicing-pereira2022-random"}


def SafeDaggerConfig(system: str = "platoon-pereira2022", learning_rate: float = 1e-4, **kw):  # noqa: N802
    """A safe-variant config (the earlier field names ``system`` and ``learning_rate`` kept)."""
    return ImitationConfig(**{"task": SYSTEM_TASKS[system], "warm_start": WARM, "fly": "filtered",
                              "label": "filtered", "lr": learning_rate, **kw})


def _space(cfg):
    return cfg.label, cfg.imitation_space


def fit(policy, data, cfg, norm_mode, generator, prior=None):
    """The safe fit of ``cfg`` (its loss, learning rate, epochs and batch size)."""
    return fit_safe(policy, data, safe_loss(cfg), lr=cfg.lr, epochs=cfg.epochs, batch_size=cfg.batch_size,
                    norm_mode=norm_mode, generator=generator, prior=prior)


def _states(system: str, steps: int, seed: int, bounds=None):
    """(proposed, filtered, intervened, infeasible, rows, lower) along an episode of full thrust
    in a fixed random direction per agent, reversed 10 steps in 40 (many actions unsafe),
    stepping the filtered actions (a filter told ``bounds``, tightened by them)."""
    env = tasks.training_task(system).make_env(terminate_on_collision=False)
    env.reset(seed=seed)
    filt = SafetyFilter(env, bounds=bounds)
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(len(env.possible_agents), filt.model.action_dim))
    d /= np.abs(d).max(axis=1, keepdims=True)
    out = []
    for k in range(steps):
        if len(env.agents) != len(env.possible_agents):
            break
        a = d if k % 40 < 30 else -d
        safe, rec = filt.filter(a)
        rows, lower = agent_constraints(filt, safe)
        out.append((a, safe, rec.intervened[0], rec.infeasible[0], rows, lower, filt.model.norm_mode))
        env.step(dict(zip(env.possible_agents, safe.astype(np.float32), strict=True)))
    return out


THRUST_LOSS = UncertaintyBounds(thrust=0.5)
"""A filter told half the thrust may be lost: its positive bounds double (the barrier must follow)."""


@pytest.mark.parametrize("system,bounds", [("platoon-pereira2022", None), ("platoon-pereira2023", None),
                                           ("servicing-pereira2022", None), ("platoon-pereira2022", THRUST_LOSS),
                                           ("platoon-pereira2023", THRUST_LOSS)])
def test_hinge_is_zero_exactly_where_the_filter_passes_the_action(system, bounds):
    seen_intervention = seen_pass = False
    for a, safe, intervened, infeasible, rows, lower, norm_mode in _states(system, 160, 3, bounds):
        h = barrier_hinge(torch.as_tensor(a), torch.as_tensor(rows, dtype=torch.float64),
                          torch.as_tensor(lower, dtype=torch.float64), norm_mode=norm_mode).numpy()
        hs = barrier_hinge(torch.as_tensor(safe), torch.as_tensor(rows, dtype=torch.float64),
                           torch.as_tensor(lower, dtype=torch.float64), norm_mode=norm_mode).numpy()
        for i in range(len(a)):
            if intervened[i]:
                seen_intervention = True
                assert h[i] > 0, "the filter changed an action the hinge calls safe"
                if not infeasible[i]:
                    assert hs[i] < 1e-6, "the filter's own output must satisfy its rows"
            else:
                seen_pass = True
                assert h[i] < 1e-8, "the hinge penalises an action the filter passed"
    assert seen_intervention and seen_pass


def test_hinge_grows_with_the_distance_outside_and_has_a_gradient():
    rows = torch.tensor([[[1.0, 0.0, 0.0]]])
    lower = torch.tensor([[0.5]])
    a = torch.tensor([[0.0, 0.0, 0.0]], requires_grad=True)
    h = barrier_hinge(a, rows, lower)
    assert h.item() == pytest.approx(0.25)
    h.sum().backward()
    assert a.grad[0, 0].item() < 0     # descent moves the action into the safe side
    assert barrier_hinge(torch.tensor([[0.6, 0.0, 0.0]]), rows, lower).item() == 0.0
    assert barrier_hinge(torch.tensor([[0.6, 0.0, 0.0]]), rows, lower, margin=0.2).item() == pytest.approx(0.01)


def test_env_action_applies_the_action_map():
    y = torch.tensor([[-2.0, 0.5, -0.5]])
    assert torch.allclose(env_action(y, 1.0), torch.tensor([[-1.0, 0.5, -0.5]]))
    assert torch.allclose(env_action(y, 3.0), torch.tensor([[-1.0, 0.125, -0.125]]))


def test_fit_with_the_barrier_term_removes_interventions_on_its_rows():
    """A tiny actor fitted on rows whose labels break the filter: the barrier term pulls it inside."""
    from satenv.training.actor import MLPActor
    from satenv.training.policy import LearnedPolicy, ObsNormalizer

    rng = np.random.default_rng(0)
    n = 256
    obs = rng.normal(size=(n, 4)).astype(np.float32)
    rows = np.zeros((n, 2, 3), np.float32)
    rows[:, 0, 0] = 1.0                               # a_x >= 0.3
    lower = np.full((n, 2), -10.0, np.float32)
    lower[:, 0] = 0.3
    label = np.zeros((n, 3), np.float32)              # the label itself breaks the row
    data = {"obs": obs, "label": label, "act": label, "filtered": label,
            "intervened": np.zeros(n, bool), "rows": rows, "lower": lower}
    torch.manual_seed(0)
    actor = MLPActor(4, 3, [32], "tanh", True)
    pol = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(4,))
    gen = torch.Generator().manual_seed(0)
    cfg = SafeDaggerConfig(w_bar=0.0, w_int=0.0, epochs=60, batch_size=64, learning_rate=3e-3)
    fit(pol, data, cfg, False, gen)
    assert np.mean(pol.predict(obs)[:, 0] < 0.3) > 0.9        # imitation alone: breaks the row
    cfg = SafeDaggerConfig(w_bar=100.0, w_int=0.0, bar_margin=0.1, epochs=60, batch_size=64, learning_rate=3e-3)
    fit(pol, data, cfg, False, gen)
    assert np.mean(pol.predict(obs)[:, 0] >= 0.3) > 0.95


@pytest.mark.parametrize("field,value", [("w_bar", -1.0), ("label", "nope"), ("lr", float("nan")),
                                         ("alone_weight", float("inf")), ("imitation_space", "x")])
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        ImitationConfig(**{"task": "platoon-pereira2022-random", "warm_start": WARM, "fly": "filtered",
                           "label": "filtered", field: value})


def test_the_expert_is_the_registrys_and_safe_labels_need_a_safe_flight_and_a_warm_start():
    """One per-system table: the safe variants label with the expert satenv.tasks names (the
    earlier table gave servicing none); a filtered label needs a flight that records the filter,
    which needs a network to fly from the first round."""
    for system in ("platoon-pereira2023", "servicing-pereira2022"):
        assert SafeDaggerConfig(system=system).expert == tasks.system(system).expert
    assert SafeDaggerConfig(system="servicing-pereira2022", label="teacher").expert is None
    with pytest.raises(ValueError, match="label 'filtered' .* fly must be one of"):
        ImitationConfig(task="platoon-pereira2022-random", label="filtered")
    with pytest.raises(ValueError, match="warm_start must name"):
        ImitationConfig(task="platoon-pereira2022-random", fly="alone")


def test_terminal_affine_reproduces_the_feedback_blend():
    from satenv.training.shaping import TerminalFeedback

    class P:
        terminal = TerminalFeedback(radius=30.0)

    rng = np.random.default_rng(1)
    obs = rng.normal(scale=20.0, size=(50, 9))
    a = rng.uniform(-1, 1, size=(50, 3))
    off, slope = terminal_affine(P(), obs, 3)
    assert np.allclose(off + slope * a, P.terminal(obs, a))
    assert np.any(slope < 0.999)                 # the blend is active on some rows


def test_interventions_are_counted_per_agent_step():
    """The filter counts decisions; the rate divides agent-actions changed by decisions x agents."""
    from satenv.safety import shield
    from satenv.scoring import aggregate, run_episodes

    class FullThrust:
        def reset(self, seed=None):
            pass

        def act(self, obs):
            return {a: np.ones(3, np.float32) for a in obs}

    env = tasks.training_task("platoon-pereira2022").make_env()
    agg = aggregate(run_episodes(env, shield(FullThrust(), env), [700_000]))
    n = len(env.possible_agents)
    assert agg["safety_agent_steps"] == n * agg["safety_steps"]
    assert agg["interventions_per_agent_step"] == pytest.approx(agg["safety_interventions"] / (n * agg["safety_steps"]))
    assert 0 < agg["interventions_per_agent_step"] <= 1.0


def test_choose_ranks_rounds_safety_first_and_ship_never_overwrites(tmp_path):
    from satenv.training.imitation.ship import choose, ship
    from satenv.training.runfolder import RunFolderError

    def entry(k, coll, viol, succ, rate):
        return {"round": k, "val": {"collision_episodes": coll, "violation_episodes": viol, "success_rate": succ},
                "shield": {"val": {"interventions_per_agent_step": rate}}}

    hist = [entry(0, 2, 60, 0.98, 0.05), entry(1, 0, 3, 1.0, 0.01), entry(2, 0, 2, 0.97, 0.02),
            entry(3, 0, 2, 0.99, 0.0), entry(4, 1, 0, 1.0, 0.0)]
    assert choose(hist) == 3
    with pytest.raises(RunFolderError, match="round 2: its validation holds a value that is not a number"):
        choose([*hist[:2], {**hist[2], "val": {**hist[2]["val"], "success_rate": "1"}}])
    (tmp_path / "history.json").write_text(json.dumps(hist))
    with pytest.raises(RunFolderError, match="not a round folder"):
        ship(tmp_path, 3, tmp_path / "out")
    (tmp_path / "rounds" / "0003").mkdir(parents=True)
    (tmp_path / "exists").mkdir()
    with pytest.raises(RunFolderError, match="never overwritten"):
        ship(tmp_path, 3, tmp_path / "exists")


class _FixedThrust:
    """A 'network' that always proposes full thrust, in opposite directions for neighbouring agents
    (closing on each other: often unsafe)."""

    def __init__(self, n: int, d: int):
        self.a = np.where(np.arange(n)[:, None] % 2 == 1, 1.0, -1.0) * np.ones((n, d))

    def reset(self, seed=None):
        pass

    def predict(self, obs):
        return self.a[: len(obs)].copy()


@pytest.mark.parametrize("fly", ["filtered", "alone"])
def test_collection_applies_the_flown_or_the_filtered_action(fly):
    """fly="alone" steps the network's own action (the filter's output only recorded): the
    recorded observations are those of an env stepped with that action; "filtered" steps the
    filter's output."""
    kw = {"terminate_on_collision": False, "max_steps": 30}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    n = len(env.possible_agents)
    net = _FixedThrust(n, env.action_space(env.possible_agents[0]).shape[0])
    rows, stats = collect_episode(env, None, net, 700_123, fly=fly)
    assert stats["agent_steps"] == len(rows["obs"]) > n
    assert rows["intervened"].any()                    # the filter disagreed somewhere
    ref = tasks.training_task("platoon-pereira2022").make_env(**kw)
    obs, _ = ref.reset(seed=700_123)
    agents = list(ref.possible_agents)
    for k in range(len(rows["obs"]) // n):
        assert np.allclose(np.stack([obs[a] for a in agents]), rows["obs"][k * n:(k + 1) * n], atol=1e-5)
        applied = rows["flown" if fly == "alone" else "filtered"][k * n:(k + 1) * n]
        obs, *_ = ref.step({a: np.clip(applied[i], -1, 1) for i, a in enumerate(agents)})


def test_prior_rows_are_imitated_beside_the_runs_own():
    """Rows of an earlier DAgger run (``prior``) pull the actor to their labels where the run has none."""
    from satenv.training.actor import MLPActor
    from satenv.training.policy import LearnedPolicy, ObsNormalizer

    rng = np.random.default_rng(2)
    n = 256
    obs = rng.normal(loc=-2.0, size=(n, 4)).astype(np.float32)
    prior_obs = rng.normal(loc=+2.0, size=(n, 4)).astype(np.float32)
    zeros = np.zeros((n, 3), np.float32)
    data = {"obs": obs, "label": zeros, "act": zeros, "filtered": zeros, "intervened": np.zeros(n, bool),
            "rows": np.zeros((n, 1, 3), np.float32), "lower": np.full((n, 1), -10.0, np.float32)}
    prior = {"obs": prior_obs, "act": np.full((n, 3), 0.5, np.float32)}
    cfg = SafeDaggerConfig(w_bar=0.0, w_int=0.0, epochs=60, batch_size=64, learning_rate=3e-3)
    errs = {}
    for weight in (0.0, 1.0):
        torch.manual_seed(0)
        pol = LearnedPolicy(MLPActor(4, 3, [32], "tanh", True), ObsNormalizer(), obs_shape=(4,))
        terms = fit(pol, data, cfg.replace(prior_weight=weight), False,
                    torch.Generator().manual_seed(0), prior)
        errs[weight] = float(np.abs(pol.predict(prior_obs) - 0.5).mean())
        assert np.abs(pol.predict(obs)).mean() < 0.1          # the run's own rows still fitted
    assert terms["prior"] < 0.01
    assert errs[1.0] < 0.05 < errs[0.0]


@pytest.mark.parametrize("field,value", [("fly", "nope"), ("prior_weight", -1.0), ("collect_decisions", -1),
                                         ("label_filter", {"bogus": 1.0})])
def test_config_rejects_bad_flight_and_prior(field, value):
    with pytest.raises(ValueError, match=field):
        SafeDaggerConfig(**{field: value})


@pytest.mark.parametrize("norm_mode", [True, False])
def test_hinge_of_an_unreachable_bound_asks_for_the_best_along_the_row(norm_mode):
    """A row whose bound no action reaches: the hinge is zero at the action that goes furthest
    along it and grows as (attainable - r.a)^2 elsewhere, not as (bound - r.a)^2."""
    r = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    rows = torch.as_tensor(r[None, None, :])
    lower = torch.tensor([[5.0]], dtype=torch.float64)
    best = r if norm_mode else np.array([1.0, 1.0, 0.0])
    top = 1.0 if norm_mode else np.sqrt(2.0)
    hinge = barrier_hinge(torch.as_tensor(best[None]), rows, lower, norm_mode=norm_mode).item()
    assert hinge == pytest.approx(0.0, abs=1e-12)
    zero = torch.zeros((1, 3), dtype=torch.float64)
    assert barrier_hinge(zero, rows, lower, norm_mode=norm_mode).item() == pytest.approx(top ** 2)
    assert barrier_hinge(zero, rows, lower, margin=0.5, norm_mode=norm_mode).item() == pytest.approx(top ** 2)


@pytest.mark.parametrize("space", ["flown", "network"])
def test_imitation_space_fits_the_flown_action_or_the_networks_output(space, feedback_policy, unconstrained_rows):
    """With terminal feedback blended in, "flown" fits what is flown to the label and "network"
    the network's own output (the DAgger engine's objective)."""
    rng = np.random.default_rng(3)
    n = 256
    obs = rng.normal(scale=0.05, size=(n, 9))
    e = rng.normal(size=(n, 3))
    obs[:, :3] = 3.5 * e / np.linalg.norm(e, axis=1, keepdims=True)   # w = exp(-3.5 / 2) = 0.17: label reachable
    obs = obs.astype(np.float32)
    label = np.full((n, 3), 0.3, np.float32)
    data = unconstrained_rows(obs, label)
    torch.manual_seed(0)
    pol = feedback_policy()
    cfg = SafeDaggerConfig(label="expert", w_bar=0.0, w_int=0.0, epochs=80, batch_size=64, learning_rate=3e-3,
                           imitation_space=space)
    fit(pol, data, cfg, False, torch.Generator().manual_seed(0))
    with torch.no_grad():
        raw = pol.actor(torch.as_tensor(obs)).numpy()
    flown = pol.predict(obs)
    fitted, other = (flown, raw) if space == "flown" else (raw, flown)
    assert np.abs(fitted - 0.3).mean() < 0.02
    assert np.abs(other - 0.3).mean() > 0.05


class _Fixed:
    """A 'network' proposing a fixed action per agent (``act`` too, as a teacher policy)."""

    def __init__(self, a: np.ndarray):
        self.a = np.asarray(a, dtype=float)

    def reset(self, seed=None):
        pass

    def predict(self, obs):
        return self.a[: len(obs)].copy()

    def act(self, obs):
        return {k: self.a[i].astype(np.float32) for i, k in enumerate(obs)}


@pytest.mark.parametrize("fly", ["alone", "filtered"])
def test_teacher_label_is_the_teachers_action_filtered_at_the_students_state(fly):
    """The label of every agent-step is the teacher's action at the state the *student* reached
    (the env stepped with the student's flown or filtered action), filtered at that state with
    the given filter config; teacher and student differ, so a label from the teacher's own
    trajectory would not match, and the filter changes the teacher's action somewhere (so an
    unfiltered label would not match either)."""
    kw = {"terminate_on_collision": False, "max_steps": 25}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    agents = list(env.possible_agents)
    n, d = len(agents), env.action_space(agents[0]).shape[0]
    student = _Fixed(np.where(np.arange(n)[:, None] % 2 == 1, 1.0, -1.0) * np.ones((n, d)))
    teacher = _Fixed(-student.a if fly == "alone" else np.roll(student.a, 1, axis=1))
    config = SafetyConfig(margin=0.05)
    rows, _ = collect_episode(env, teacher, student, 700_321, fly=fly, filter_config=config)
    ref = tasks.training_task("platoon-pereira2022").make_env(**kw)
    obs, _ = ref.reset(seed=700_321)
    filt = SafetyFilter(ref, config)
    changed = 0
    for k in range(len(rows["obs"]) // n):
        sl = slice(k * n, (k + 1) * n)
        expected, rec = filt.filter(teacher.a)
        changed += int(rec.intervened.sum())
        assert np.allclose(rows["label"][sl], expected, atol=1e-5)
        assert np.allclose(rows["act"][sl], teacher.a)
        applied = rows["flown" if fly == "alone" else "filtered"][sl]
        obs, *_ = ref.step({a: np.clip(applied[i], -1, 1).astype(np.float32) for i, a in enumerate(agents)})
    assert changed > 0                                   # the filter did change the teacher somewhere


def test_a_label_filter_tightens_the_labels_and_rows_not_the_flight():
    """With a tighter label filter the label is the teacher's action through *that* filter and the
    barrier rows are its rows, while the flown action and the intervention record stay the shipped
    filter's; the two filters disagree somewhere (else the test could not tell them apart)."""
    kw = {"terminate_on_collision": False, "max_steps": 25}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    agents = list(env.possible_agents)
    n, d = len(agents), env.action_space(agents[0]).shape[0]
    student = _Fixed(np.where(np.arange(n)[:, None] % 2 == 1, 1.0, -1.0) * np.ones((n, d)))
    teacher = _Fixed(np.roll(student.a, 1, axis=1))
    shipped = SafetyConfig(margin=0.05)
    tight = label_filter_config(
        (SafeDaggerConfig(label_filter={"margin": 3.0, "velocity_margin": 0.9, "gamma": 0.1})).label_filter, shipped)
    assert (tight.margin, tight.velocity_margin, tight.gamma, tight.los_margin) == (3.0, 0.9, 0.1, shipped.los_margin)
    rows, _ = collect_episode(env, teacher, student, 700_321, fly="filtered", filter_config=shipped,
                              label_config=tight)
    ref = tasks.training_task("platoon-pereira2022").make_env(**kw)
    ref.reset(seed=700_321)
    f_ship, f_tight = SafetyFilter(ref, shipped), SafetyFilter(ref, tight)
    differ = 0
    for k in range(len(rows["obs"]) // n):
        sl = slice(k * n, (k + 1) * n)
        label, _ = f_tight.filter(teacher.a)
        flown, _ = f_ship.filter(student.a)
        differ += int(not np.allclose(label, f_ship.filter(teacher.a)[0], atol=1e-5))
        assert np.allclose(rows["label"][sl], label, atol=1e-5)
        assert np.allclose(rows["filtered"][sl], flown, atol=1e-5)
        r, lo = agent_constraints(f_tight, flown)
        assert np.allclose(rows["rows"][sl], r, atol=1e-5) and np.allclose(rows["lower"][sl], lo, atol=1e-5)
        ref.step({a: np.clip(flown[i], -1, 1).astype(np.float32) for i, a in enumerate(agents)})
    assert differ > 0


@pytest.mark.parametrize("bad", [{"bogus": 1.0}, {"velocity_margin": 2.0}, ["margin", 0.1]])
def test_a_bad_label_filter_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="label_filter|bogus|velocity_margin"):
        SafeDaggerConfig(label_filter=bad)
    assert label_filter_config(SafeDaggerConfig().label_filter, SafetyConfig(margin=0.05)) is None


def test_the_filter_is_the_warm_starts_shipped_one(tmp_path):
    """Servicing ships with a 0.005 margin: labels, rows and validation use it; a folder that ships
    no filter gets the default."""
    cfg = warm_start_filter(tasks_root() / "satenv/training/policies/servicing_pereira2022_dagger_shield")
    assert cfg.margin == pytest.approx(0.005)
    (tmp_path / "env.json").write_text(json.dumps({"env_id": "servicing_v0"}))
    assert warm_start_filter(tmp_path) == SafetyConfig()


def tasks_root():
    from pathlib import Path

    return Path(__file__).resolve().parents[1]


def test_teacher_labels_with_terminal_feedback_must_be_compared_flown(feedback_policy):
    with_fb, without = feedback_policy(hidden=8), feedback_policy(hidden=8, terminal=False)
    with pytest.raises(SatenvError, match="imitation_space"):
        check_label_space(*_space(SafeDaggerConfig(label="teacher", imitation_space="network",
                                           system="servicing-pereira2022")), with_fb)
    check_label_space(*_space(SafeDaggerConfig(label="teacher", imitation_space="flown",
                                               system="servicing-pereira2022")), with_fb)
    check_label_space(*_space(SafeDaggerConfig(label="teacher", imitation_space="network",
                                               system="servicing-pereira2022")), without)
    check_label_space(*_space(SafeDaggerConfig(label="expert", imitation_space="network")), with_fb)


def test_the_warm_start_is_a_fixed_point_of_its_own_flown_teacher_labels(feedback_policy, unconstrained_rows):
    """With terminal feedback, the teacher's unfiltered flown action as the label: the flown
    objective is zero at the warm start (the fit does not move it), the network-space one is not."""
    from satenv.training.actor import MLPActor

    rng = np.random.default_rng(4)
    n = 256
    obs = rng.normal(scale=0.05, size=(n, 9))
    e = rng.normal(size=(n, 3))
    obs[:, :3] = 2.0 * e / np.linalg.norm(e, axis=1, keepdims=True)      # w = exp(-1) = 0.37
    obs = obs.astype(np.float32)
    torch.manual_seed(0)
    moved = {}
    for space in ("flown", "network"):
        pol = feedback_policy()
        torch.manual_seed(0)
        pol.actor.load_state_dict(MLPActor(9, 3, [32], "tanh", True).state_dict())
        label = pol.predict(obs)                          # the teacher's flown action, unfiltered
        before = pol.predict(obs)
        data = unconstrained_rows(obs, label)
        cfg = SafeDaggerConfig(label="teacher", system="servicing-pereira2022", w_bar=0.0, w_int=0.0, epochs=20,
                               batch_size=64, learning_rate=3e-3, imitation_space=space)
        terms = fit(pol, data, cfg, False, torch.Generator().manual_seed(0))
        moved[space] = float(np.abs(pol.predict(obs) - before).mean())
        if space == "flown":
            assert terms["imitation"] < 1e-6
    assert moved["flown"] < 1e-3 < moved["network"]


def test_mixed_flights_alternate_alone_and_filtered():
    cfg = SafeDaggerConfig(fly="mixed")
    assert [episode_flight(cfg.fly, j) for j in range(4)] == ["alone", "filtered", "alone", "filtered"]
    assert episode_flight(SafeDaggerConfig(fly="alone").fly, 1) == "alone"
    with pytest.raises(SatenvError, match="fly"):
        collect_episode(None, None, None, 0, fly="mixed")


def test_handover_flies_alone_until_the_first_failure_then_behind_the_filter():
    """fly="handover": the env is stepped with the network's own action up to the first step whose
    infos report a collision or a hard-bound violation, with the filter's output after it."""
    kw = {"terminate_on_collision": False, "max_steps": 60}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    agents = list(env.possible_agents)
    n, d = len(agents), env.action_space(agents[0]).shape[0]
    student = _Fixed(np.where(np.arange(n)[:, None] % 2 == 1, 1.0, -1.0) * np.ones((n, d)))
    rows, stats = collect_episode(env, None, student, 700_321, fly="handover")
    ref = tasks.training_task("platoon-pereira2022").make_env(**kw)
    obs, _ = ref.reset(seed=700_321)
    alone, alone_rows, after = True, 0, 0
    for k in range(len(rows["obs"]) // n):
        sl = slice(k * n, (k + 1) * n)
        assert np.allclose(np.stack([obs[a] for a in agents]), rows["obs"][sl], atol=1e-5)
        applied = rows["flown" if alone else "filtered"][sl]
        alone_rows += n if alone else 0
        after += 0 if alone else int(not np.allclose(rows["flown"][sl], rows["filtered"][sl]))
        obs, _, _, _, infos = ref.step({a: np.clip(applied[i], -1, 1).astype(np.float32) for i, a in enumerate(agents)})
        if any(bool(i.get("collision")) or bool(i.get("violations")) for i in infos.values()):
            alone = False
    assert not alone and after > 0          # the handover happened, and the filter then changed actions
    assert stats["alone_agent_steps"] == alone_rows < stats["agent_steps"]
    assert rows["alone"].sum() == alone_rows and rows["alone"][:alone_rows].all()   # the rows say who flew


@pytest.mark.parametrize("prior_space", ["network", "flown"])
def test_prior_term_compares_in_its_own_space(prior_space, feedback_policy, unconstrained_rows):
    """Teacher rows in flown space beside a DAgger run's expert labels: ``prior_space="network"``
    fits the network's own output to the prior labels, ``"flown"`` what is flown."""
    rng = np.random.default_rng(5)
    n = 256

    def near(loc):
        o = rng.normal(loc=loc, scale=0.05, size=(n, 9))
        e = rng.normal(size=(n, 3))
        o[:, :3] = 3.5 * e / np.linalg.norm(e, axis=1, keepdims=True)    # w = exp(-3.5 / 2) = 0.17
        return o.astype(np.float32)

    obs, prior_obs = near(-1.0), near(+1.0)
    data = unconstrained_rows(obs, np.zeros((n, 3), np.float32))
    prior = {"obs": prior_obs, "act": np.full((n, 3), 0.3, np.float32)}
    torch.manual_seed(0)
    pol = feedback_policy()
    cfg = SafeDaggerConfig(label="teacher", system="servicing-pereira2022", w_bar=0.0, w_int=0.0, epochs=80,
                           batch_size=64, learning_rate=3e-3, imitation_space="flown", prior_space=prior_space)
    fit(pol, data, cfg, False, torch.Generator().manual_seed(0), prior)
    with torch.no_grad():
        raw = pol.actor(torch.as_tensor(prior_obs)).numpy()
    flown = pol.predict(prior_obs)
    fitted, other = (raw, flown) if prior_space == "network" else (flown, raw)
    assert np.abs(fitted - 0.3).mean() < 0.03
    assert np.abs(other - 0.3).mean() > 0.05


def test_validate_round_writes_the_validation_of_a_round(tmp_path, capsys):
    """``--validate-round -1`` validates the warm start on the given validation seeds into the run's
    ``validation/`` folder; a round the run does not have is refused, naming it."""
    from satenv.training.imitation.cli import main

    warm = str(tasks_root() / WARM)
    argv = ["--run-dir", str(tmp_path), "--system", "platoon-pereira2022", "--warm-start", warm, "--fly", "filtered",
            "--label", "filtered", "--validate-seeds", "1", "--shield-seeds", "1"]
    assert main([*argv, "--validate-round", "-1"]) == 0
    out = json.loads((tmp_path / "validation" / "round_-001_1_1.json").read_text())
    assert out["round"] == -1 and out["val"]["episodes"] == 1 and out["shield"]["val"]["episodes"] == 1
    assert main([*argv, "--validate-round", "3"]) == 2
    assert "round 3" in capsys.readouterr().err


def test_collect_decisions_cuts_a_collection_episode():
    """``max_decisions`` stops the flight after that many decisions (every agent labelled each);
    a negative or non-integer count is refused."""
    env = tasks.training_task("platoon-pereira2022").make_env(terminate_on_collision=False, max_steps=25)
    n, d = len(env.possible_agents), env.action_space(env.possible_agents[0]).shape[0]
    student = _Fixed(np.zeros((n, d)))
    rows, stats = collect_episode(env, None, student, 700_321, fly="alone", max_decisions=7)
    assert len(rows["obs"]) == 7 * n and stats["agent_steps"] == 7 * n
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="collect_decisions"):
            SafeDaggerConfig(collect_decisions=bad)


def test_alone_weight_pulls_the_fit_towards_the_rows_flown_alone(feedback_policy, unconstrained_rows):
    """The same observations labelled +0.5 where flown alone and -0.5 where flown behind the filter:
    with equal weights the fit lands between them, with ``alone_weight`` 9 at their weighted mean
    (+0.4), so the alone rows' label wins."""
    obs = np.random.default_rng(5).normal(scale=0.05, size=(64, 9)).astype(np.float32)
    obs = np.concatenate([obs, obs])
    label = np.concatenate([np.full((64, 3), 0.5), np.full((64, 3), -0.5)]).astype(np.float32)
    data = {**unconstrained_rows(obs, label), "alone": np.r_[np.ones(64, bool), np.zeros(64, bool)]}
    means = {}
    for weight in (1.0, 9.0):
        pol = feedback_policy(terminal=False)
        cfg = SafeDaggerConfig(label="teacher", system="servicing-pereira2022", w_bar=0.0, w_int=0.0, epochs=150,
                               batch_size=128, learning_rate=1e-2, alone_weight=weight)
        fit(pol, data, cfg, False, torch.Generator().manual_seed(0))
        means[weight] = float(pol.predict(obs[:64]).mean())
    assert abs(means[1.0]) < 0.05 and abs(means[9.0] - 0.4) < 0.05
    data.pop("alone")                                 # rows of a label file without the flag: weight 1
    fit(feedback_policy(terminal=False), data, SafeDaggerConfig(label="teacher", system="servicing-pereira2022",
                                                                alone_weight=9.0, epochs=1), False,
        torch.Generator().manual_seed(0))
