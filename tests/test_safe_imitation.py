"""satenv.training.safe_imitation: the filter's rows as a differentiable intervention penalty."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from satenv import tasks  # noqa: E402
from satenv.errors import SatenvError  # noqa: E402
from satenv.safety import SafetyFilter  # noqa: E402
from satenv.training.safe_imitation import (  # noqa: E402
    SafeDaggerConfig,
    _env_action,
    agent_constraints,
    barrier_hinge,
    fit,
)


def _states(system: str, steps: int, seed: int):
    """(proposed, filtered, intervened, infeasible, rows, lower) along an episode of full thrust
    in a fixed random direction per agent, reversed 10 steps in 40 (many actions unsafe),
    stepping the filtered actions."""
    env = tasks.training_task(system).make_env(terminate_on_collision=False)
    env.reset(seed=seed)
    filt = SafetyFilter(env)
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


@pytest.mark.parametrize("system", ["platoon-pereira2022", "platoon-pereira2023", "servicing-pereira2022"])
def test_hinge_is_zero_exactly_where_the_filter_passes_the_action(system):
    seen_intervention = seen_pass = False
    for a, safe, intervened, infeasible, rows, lower, norm_mode in _states(system, 160, 3):
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
    assert torch.allclose(_env_action(y, 1.0), torch.tensor([[-1.0, 0.5, -0.5]]))
    assert torch.allclose(_env_action(y, 3.0), torch.tensor([[-1.0, 0.125, -0.125]]))


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
    data = {"obs": obs, "label": label, "expert": label, "filtered": label,
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


@pytest.mark.parametrize("field,value", [("w_bar", -1.0), ("label", "nope"), ("system", "formation-kannan2022-collision"),
                                         ("learning_rate", float("nan"))])
def test_config_rejects_bad_values(field, value):
    with pytest.raises(SatenvError, match=field if field != "system" else "system"):
        SafeDaggerConfig(**{field: value})


def test_a_system_without_expert_needs_self_labels():
    with pytest.raises(SatenvError, match="label must be .self. or .teacher."):
        SafeDaggerConfig(system="platoon-pereira2023", label="filtered")


def test_terminal_affine_reproduces_the_feedback_blend():
    from satenv.training.shaping import TerminalFeedback

    class P:
        terminal = TerminalFeedback(radius=30.0)

    rng = np.random.default_rng(1)
    obs = rng.normal(scale=20.0, size=(50, 9))
    a = rng.uniform(-1, 1, size=(50, 3))
    off, slope = __import__("satenv.training.safe_imitation", fromlist=["x"]).terminal_affine(P(), obs, 3)
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
    import json

    from satenv.training.safe_imitation import choose, ship

    def val(coll, viol, succ, rate):
        return {"alone": {"collision_episodes": coll, "violation_episodes": viol, "success_rate": succ},
                "shield": {"interventions_per_agent_step": rate}}

    hist = [{"round": -1, "val": val(2, 60, 0.98, 0.05)}, {"round": 1, "val": val(0, 3, 1.0, 0.01)},
            {"round": 2, "val": val(0, 2, 0.97, 0.02)}, {"round": 3, "val": val(0, 2, 0.99, 0.0)},
            {"round": 4, "val": val(1, 0, 1.0, 0.0)}]
    (tmp_path / "history.json").write_text(json.dumps(hist))
    assert choose(tmp_path) == 3
    with pytest.raises(SatenvError, match="not a round folder"):
        ship(tmp_path, 3, tmp_path / "out")
    (tmp_path / "rounds" / "0003").mkdir(parents=True)
    (tmp_path / "exists").mkdir()
    with pytest.raises(SatenvError, match="never overwritten"):
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
    from satenv.training.safe_imitation import collect_episode

    kw = {"terminate_on_collision": False, "max_steps": 30}
    env = tasks.training_task("platoon-pereira2022").make_env(**kw)
    n = len(env.possible_agents)
    net = _FixedThrust(n, env.action_space(env.possible_agents[0]).shape[0])
    rows, stats = collect_episode(env, None, net, 700_123, fly)
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
    data = {"obs": obs, "label": zeros, "expert": zeros, "filtered": zeros, "intervened": np.zeros(n, bool),
            "rows": np.zeros((n, 1, 3), np.float32), "lower": np.full((n, 1), -10.0, np.float32)}
    prior = {"obs": prior_obs, "act": np.full((n, 3), 0.5, np.float32)}
    cfg = SafeDaggerConfig(w_bar=0.0, w_int=0.0, epochs=60, batch_size=64, learning_rate=3e-3)
    errs = {}
    for weight in (0.0, 1.0):
        torch.manual_seed(0)
        pol = LearnedPolicy(MLPActor(4, 3, [32], "tanh", True), ObsNormalizer(), obs_shape=(4,))
        terms = fit(pol, data, SafeDaggerConfig(**{**cfg.to_json(), "prior_weight": weight}), False,
                    torch.Generator().manual_seed(0), prior)
        errs[weight] = float(np.abs(pol.predict(prior_obs) - 0.5).mean())
        assert np.abs(pol.predict(obs)).mean() < 0.1          # the run's own rows still fitted
    assert terms["prior"] < 0.01
    assert errs[1.0] < 0.05 < errs[0.0]


@pytest.mark.parametrize("field,value", [("fly", "nope"), ("prior_labels", "/nonexistent/labels"),
                                         ("prior_weight", -1.0)])
def test_config_rejects_bad_flight_and_prior(field, value):
    with pytest.raises(SatenvError, match=field):
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
    assert barrier_hinge(torch.as_tensor(best[None]), rows, lower, norm_mode=norm_mode).item() == pytest.approx(0.0, abs=1e-12)
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
