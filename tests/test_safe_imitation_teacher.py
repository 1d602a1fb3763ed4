"""satenv.training.safe_imitation with the frozen composite (warm-start network + its shipped filter) as
the expert, flown by the network alone: the label, the filter it uses and the objective."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from satenv import tasks  # noqa: E402
from satenv.errors import SatenvError  # noqa: E402
from satenv.safety import SafetyConfig, SafetyFilter  # noqa: E402
from satenv.training.safe_imitation import (  # noqa: E402
    SafeDaggerConfig,
    agent_constraints,
    check_label_space,
    collect_episode,
    episode_flight,
    fit,
    label_filter_config,
    warm_start_filter,
)


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
    rows, _ = collect_episode(env, teacher, student, 700_321, fly, config)
    ref = tasks.training_task("platoon-pereira2022").make_env(**kw)
    obs, _ = ref.reset(seed=700_321)
    filt = SafetyFilter(ref, config)
    changed = 0
    for k in range(len(rows["obs"]) // n):
        sl = slice(k * n, (k + 1) * n)
        expected, rec = filt.filter(teacher.a)
        changed += int(rec.intervened.sum())
        assert np.allclose(rows["label"][sl], expected, atol=1e-5)
        assert np.allclose(rows["expert"][sl], teacher.a)
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
    tight = label_filter_config(SafeDaggerConfig(label_filter={"margin": 3.0, "velocity_margin": 0.9, "gamma": 0.1}),
                                shipped)
    assert (tight.margin, tight.velocity_margin, tight.gamma, tight.los_margin) == (3.0, 0.9, 0.1, shipped.los_margin)
    rows, _ = collect_episode(env, teacher, student, 700_321, "filtered", shipped, tight)
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
    assert label_filter_config(SafeDaggerConfig(), SafetyConfig(margin=0.05)) is None


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
        check_label_space(SafeDaggerConfig(label="teacher", imitation_space="network",
                                           system="servicing-pereira2022"), with_fb)
    check_label_space(SafeDaggerConfig(label="teacher", imitation_space="flown", system="servicing-pereira2022"), with_fb)
    check_label_space(SafeDaggerConfig(label="teacher", imitation_space="network", system="servicing-pereira2022"),
                      without)
    check_label_space(SafeDaggerConfig(label="expert", imitation_space="network"), with_fb)


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
    assert [episode_flight(cfg, j) for j in range(4)] == ["alone", "filtered", "alone", "filtered"]
    assert episode_flight(SafeDaggerConfig(fly="alone"), 1) == "alone"
    with pytest.raises(SatenvError, match="fly"):
        collect_episode(None, None, None, 0, "mixed")


def test_handover_flies_alone_until_the_first_failure_then_behind_the_filter():
    """fly="handover": the env is stepped with the network's own action up to the first step whose
    infos report a collision or a hard-bound violation, with the filter's output after it."""
    kw = {"terminate_on_collision": False, "max_steps": 60}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    agents = list(env.possible_agents)
    n, d = len(agents), env.action_space(agents[0]).shape[0]
    student = _Fixed(np.where(np.arange(n)[:, None] % 2 == 1, 1.0, -1.0) * np.ones((n, d)))
    rows, stats = collect_episode(env, None, student, 700_321, "handover")
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


def test_validate_round_writes_the_validation_of_a_round(tmp_path):
    """``--validate-round -1`` validates the warm start on the given seed counts into the run's
    ``validation/`` folder; a round the run does not have is refused, naming it."""
    from satenv.training.safe_imitation import main

    warm = str(tasks_root() / "satenv/training/policies/platoon_pereira2022_dagger_shield")
    argv = ["--run-dir", str(tmp_path), "--system", "platoon-pereira2022", "--warm-start", warm,
            "--val-seeds", "1", "--val-shield-seeds", "1"]
    main([*argv, "--validate-round", "-1"])
    out = json.loads((tmp_path / "validation" / "round_-001_1_1.json").read_text())
    assert out["round"] == -1 and out["val"]["alone"]["episodes"] == 1 and out["val"]["shield"]["episodes"] == 1
    with pytest.raises(SatenvError, match="round 3"):
        main([*argv, "--validate-round", "3"])


def test_collect_decisions_cuts_a_collection_episode():
    """``max_decisions`` stops the flight after that many decisions (every agent labelled each);
    a negative or non-integer count is refused."""
    env = tasks.training_task("platoon-pereira2022").make_env(terminate_on_collision=False, max_steps=25)
    n, d = len(env.possible_agents), env.action_space(env.possible_agents[0]).shape[0]
    student = _Fixed(np.zeros((n, d)))
    rows, stats = collect_episode(env, None, student, 700_321, "alone", None, None, 7)
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
