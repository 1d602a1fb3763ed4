"""The training reward (satenv.rewards), the safety cost and the ladders (satenv.tasks).

Seeds: the reward's checks run on the test seeds from the 100th on (900100...: a band nobody
looked at while the reward was designed on validation seeds); the rungs' checks on the first
test seeds (the rungs were chosen before any episode on them was run). The reward's constants
are derived from the task (satenv.rewards), never fitted to an episode.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import satenv
from satenv import metrics, rewards, tasks
from satenv.dynamics import unit_box_to_accel
from satenv.errors import SatenvError, SatenvTypeError
from satenv.vector import SatVectorEnv

TRAINING = [s.training_task for s in tasks.SYSTEMS.values()]
RUNGS = [name for system in tasks.SYSTEMS for name in tasks.ladder(system)]
CHEAP_CONTROLLER = {"platoon-tplf30-random-cw": 5, "platoon-pereira2022-random": 2,
                    "formation-kannan2022-position-random": 1, "formation-kannan2022-collision-random": 1}
"""Training tasks whose reference controller runs in seconds an episode: how many test seeds the
default run gives it (the cluster's tube-RDMPC and the servicing NMPC take minutes: slow test)."""
REWARD_SEEDS_FROM = 100
"""Where in the test band the reward's checks take their seeds."""
TRIVIAL_RATE = 0.10
"""A rung is trivial when zero thrust or a uniform random policy succeeds on this share of seeds."""

PAPER_ENV_KWARGS = {
    "platoon-PLF-cw": {"preset": "pereira2023", "topology": "PLF", "dynamics": "cw", "terminate_on_collision": False},
    "platoon-pereira2022": {"preset": "pereira2022"},
    "cluster-case1": {"preset": "li2022-case1"},
    "servicing-pereira2022": {"preset": "pereira2022"},
    "formation-kannan2022-position": {"preset": "kannan2022-position"},
    "formation-kannan2022-collision": {"preset": "kannan2022-collision"},
}
"""The paper tasks' env keywords as they were before the ladders and the training reward."""


# ----------------------------------------------------------------------------- scripted episodes
def _translation(vec: SatVectorEnv, thrust: np.ndarray) -> np.ndarray:
    """Normalised actions with ``thrust`` (B, M, 3) on the translation axes (the rest zero)."""
    a = np.zeros(vec.action_shape)
    a[..., :3] = np.clip(thrust, -1.0, 1.0)
    return a


def _unit(v: np.ndarray) -> np.ndarray:
    """Directions saturating the unit box (largest component +-1)."""
    return v / np.maximum(np.abs(v).max(axis=-1, keepdims=True), 1e-12)


def exploit(name: str, vec: SatVectorEnv, info: dict[str, np.ndarray], rng: np.random.Generator) -> np.ndarray:
    """The scripted exploits: ``zero`` thrust, ``flee`` (full thrust along the tracking error,
    away from the target), ``ram`` (full thrust at the nearest other spacecraft), ``random``."""
    if name == "zero":
        return np.zeros(vec.action_shape)
    if name == "random":
        return rng.uniform(-1.0, 1.0, vec.action_shape)
    if name == "flee":
        return _translation(vec, _unit(info["tracking_error"][..., :3]))
    pos = info["state"][..., :3]
    rel = pos[:, None, :, :] - pos[:, :, None, :]                  # (B, M, M, 3): j minus i
    dist = np.where(np.eye(pos.shape[1], dtype=bool), np.inf, np.linalg.norm(rel, axis=-1))
    j = dist.argmin(axis=-1)
    return _translation(vec, _unit(np.take_along_axis(rel, j[..., None, None], axis=2)[:, :, 0]))


def reward_seeds(task: tasks.Task, n: int) -> range:
    """``n`` consecutive test seeds of the band the reward's checks use."""
    start = task.seeds("test")[REWARD_SEEDS_FROM]
    return range(start, start + n)


def scripted(task: tasks.Task, policy: str, seeds: range, **overrides) -> tuple[np.ndarray, np.ndarray]:
    """Team returns and successes ``(len(seeds),)`` of a scripted policy, one batched env whose copy
    ``b`` plays seed ``seeds[b]`` (the PettingZoo env's ``reset(seed=seeds[b])`` episode)."""
    env = satenv.make(task.env_id, **{**task.env_kwargs, **overrides})
    vec = SatVectorEnv(env, len(seeds), seed=seeds[0], autoreset=False)
    _, info = vec.reset()
    rng = np.random.default_rng(seeds[0])
    sc = env.scenario
    live = np.ones(len(seeds), dtype=bool)
    returns, collided = np.zeros(len(seeds)), np.zeros(len(seeds), dtype=bool)
    final_dist = np.zeros((len(seeds), vec.n_agents))
    while live.any():
        _, rew, term, trunc, info = vec.step(exploit(policy, vec, info, rng))
        returns += np.where(live, rew.sum(axis=1), 0.0)
        collided |= live & info["collision"].any(axis=1)
        ended = term[:, 0] | trunc[:, 0]
        done = live & ended
        final_dist[done] = rewards.target_distance(info)[done]
        live &= ~done
        if ended.any() and live.any():   # finished copies replay ignored episodes meanwhile
            _, reset_info = vec.reset(indices=ended)
            info = {k: v.copy() for k, v in info.items()}
            for k, v in reset_info.items():
                info[k][ended] = v
    success = (final_dist <= sc.success_tol).all(axis=1) & ~(sc.collision_voids_success & collided)
    return returns, success


def test_scripted_matches_the_pettingzoo_env():
    """The batched runner's returns and successes are the PettingZoo env's episode by episode."""
    task = tasks.get("platoon-tplf30-random-cw")
    seeds = task.seeds("test", 3)
    returns, success = scripted(task, "zero", range(seeds[0], seeds[0] + 3))
    from satenv.baselines import make
    from satenv.rollout import rollout

    for b, seed in enumerate(seeds):
        env = task.make_env()
        traj = rollout(env, make("zero", env), seed=seed)
        assert traj.rewards.sum() == pytest.approx(returns[b], rel=1e-9, abs=1e-9)
        assert metrics.success(traj) == success[b]


# ----------------------------------------------------------------------------- structure
@pytest.mark.parametrize("name", TRAINING)
def test_penalties_exceed_every_remaining_gain(name):
    """Per state of the region: a penalty is more than the rest of the potential and the whole
    in-tolerance bonus together; the success bonus is more than a failing agent can earn plus a
    penalty plus the potential left inside the tolerance."""
    spec = rewards.TrainingReward.of(tasks.get(name).make_env().scenario)
    dist = np.concatenate([np.linspace(0.0, spec.reach, 100_001), np.geomspace(1e-9, spec.reach, 1001)])
    phi = rewards.potential(dist, spec)
    assert phi.max() <= 0.0 and phi.min() >= -rewards.POTENTIAL_SPAN
    remaining = -phi + rewards.IN_TOLERANCE_BONUS
    assert rewards.PENALTY > remaining.max()
    earn = (phi.max() - phi.min()) + rewards.IN_TOLERANCE_BONUS
    assert rewards.SUCCESS_BONUS > earn + rewards.PENALTY - rewards.potential(np.array(spec.tol), spec)


def _success_floor(task: tasks.Task) -> float:
    """The least team return of any successful episode of a task where a collision voids success:
    each agent ends within the tolerance (potential >= phi(tol)), gets the success bonus and has
    paid at most a violation penalty."""
    env = task.make_env()
    spec = rewards.TrainingReward.of(env.scenario)
    assert spec.voids
    per_agent = (rewards.SUCCESS_BONUS - rewards.PENALTY + float(rewards.potential(np.array(spec.tol), spec))
                 + 1.0 / spec.horizon)
    return len(env.possible_agents) * per_agent


EXPLOITS = ("zero", "flee", "ram", "random")


@pytest.mark.parametrize("name", RUNGS)
def test_exploits_score_below_any_success(name):
    """On 20 test seeds of every rung (the training tasks included), every scripted exploit's team
    return is below the least return any successful episode can have."""
    task = tasks.get(name)
    seeds = reward_seeds(task, 20)
    floor = _success_floor(task)
    for policy in EXPLOITS:
        returns, success = scripted(task, policy, seeds)
        assert not success.any(), policy
        assert returns.max() < floor, (policy, returns.max(), floor)


def controller_episodes(task: tasks.Task, seeds: range) -> tuple[np.ndarray, np.ndarray]:
    """Team returns and successes of the task's reference controller on ``seeds``."""
    from satenv.baselines import make
    from satenv.rollout import rollout

    out = []
    for seed in seeds:
        env = task.make_env()
        traj = rollout(env, make(task.controller, env), seed=seed)
        out.append((traj.rewards.sum(), metrics.success(traj)))
    returns, success = map(np.array, zip(*out, strict=True))
    return returns, success


def _check_exploits_below_controller(name: str, n: int) -> None:
    task = tasks.get(name)
    returns, success = controller_episodes(task, reward_seeds(task, n))
    assert success.any(), f"{name}: the controller succeeded on none of {n} test seeds"
    best_success = returns[success].min()
    seeds = reward_seeds(task, 20)
    for policy in EXPLOITS:
        exploit_returns, _ = scripted(task, policy, seeds)
        assert exploit_returns.max() < best_success, (policy, exploit_returns.max(), best_success)
    assert (returns[~success] < best_success).all()   # the controller's own failures too


@pytest.mark.parametrize("name", list(CHEAP_CONTROLLER))
def test_exploits_score_below_every_controller_success(name):
    """Zero thrust, flee, ram and random (20 test seeds) each score below every successful
    episode of the task's reference controller (its first test seeds)."""
    _check_exploits_below_controller(name, CHEAP_CONTROLLER[name])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cluster-case1-random", "servicing-pereira2022-random"])
def test_exploits_score_below_every_controller_success_slow(name):
    """The same for the cluster's tube-RDMPC and the servicing NMPC (minutes an episode)."""
    _check_exploits_below_controller(name, 2)


# ----------------------------------------------------------------------------- keyword and infos
def test_reward_keyword():
    """``reward=`` is validated; a bare ``satenv.make`` keeps the paper's cost; a training task's
    env has the training reward, ``paper_env_kwargs`` the paper's."""
    with pytest.raises(SatenvError, match="reward must be one of"):
        satenv.make("platoon_v0", reward="sparse")
    with pytest.raises(SatenvTypeError, match="reward must be one of"):
        satenv.make("platoon_v0", reward=1)
    assert satenv.make("platoon_v0").reward == "paper"
    for name in TRAINING:
        task = tasks.get(name)
        assert task.make_env().reward == "training"
        assert task.make_env(reward="paper").reward == "paper"
        assert satenv.make(task.env_id, **task.paper_env_kwargs).reward == "paper"
    for name, kwargs in PAPER_ENV_KWARGS.items():
        assert dict(tasks.get(name).env_kwargs) == kwargs
        assert tasks.get(name).make_env().reward == "paper"


@pytest.mark.parametrize("env_id", satenv.ENV_IDS)
def test_paper_reward_unchanged(env_id):
    """``reward="paper"`` gives the core's own rewards (the paper's cost), step for step."""
    env = satenv.make(env_id, randomize=True, reward="paper")
    twin = satenv.make(env_id, randomize=True)
    env.reset(seed=900_000)
    twin.reset(seed=900_000)
    core = twin.core
    rng = np.random.default_rng(0)
    for _ in range(3):
        a = rng.uniform(-1, 1, (1, len(env.possible_agents), env.core.action_dim))
        _, rew, *_ = env.step(dict(zip(env.possible_agents, a[0], strict=True)))
        res = core.step(unit_box_to_accel(a, env.scenario.u_max, env.scenario.thrust_mode), np.random.default_rng(0))
        np.testing.assert_array_equal(list(rew.values()), res.rewards[0])


@pytest.mark.parametrize("name", TRAINING)
def test_vector_training_reward_is_the_pettingzoo_envs(name):
    """``make_vec`` with ``**task.env_kwargs`` gives copy b the PettingZoo env's training rewards
    and safety costs (seed s + b), through an auto-reset."""
    task = tasks.get(name)
    seed = task.seeds("test")[0]
    vec = satenv.make_vec(task.env_id, 2, seed=seed, **task.env_kwargs, max_steps=5)
    vec.reset()
    envs = [task.make_env(max_steps=5) for _ in range(2)]
    for b, env in enumerate(envs):
        env.reset(seed=seed + b)
    rng = np.random.default_rng(0)
    for step in range(7):
        a = rng.uniform(-1, 1, vec.action_shape)
        _, rew, _, _, infos = vec.step(a)
        for b, env in enumerate(envs):
            if not env.agents:
                env.reset()
            _, r, _, _, inf = env.step(dict(zip(env.possible_agents, a[b], strict=True)))
            src = infos["final_info"] if infos.get("_final_info", np.zeros(2, bool))[b] else infos
            np.testing.assert_allclose(rew[b], list(r.values()), rtol=1e-9, atol=1e-12, err_msg=f"step {step}")
            np.testing.assert_array_equal(src["safety_cost"][b], [i["safety_cost"] for i in inf.values()])


def test_safety_cost_marks_collisions_and_violations():
    """``safety_cost`` is 1.0 exactly where an agent collides or violates a bound, else 0.0, in
    the env, ``make_vec`` and (when installed) the TorchRL env; the env's ``cost`` stays."""
    info = {"collision": np.array([[True, False, False]]), "violations": np.array([[0, 2, 0]])}
    np.testing.assert_array_equal(rewards.safety_cost(info), [[1.0, 1.0, 0.0]])
    task = tasks.get("cluster-case1-random")
    returns, _ = scripted(task, "ram", range(900_000, 900_002))   # ramming collides: cost paid
    assert (returns < 0).all()
    env = task.make_env()
    env.reset(seed=900_000)
    _, _, _, _, inf = env.step({a: np.zeros(3) for a in env.agents})
    assert all({"safety_cost", "cost"} <= set(i) for i in inf.values())
    vec = satenv.make_vec(task.env_id, 2, seed=0, **task.env_kwargs)
    _, infos = vec.reset()
    assert infos["safety_cost"].shape == (2, len(env.possible_agents))


def test_torchrl_safety_cost():
    pytest.importorskip("torchrl")
    from satenv.torchrl import make_env

    env = make_env("platoon_v0", 3, seed=0, reward="training", randomize=True)
    td = env.rollout(4)
    assert td["next", "agents", "safety_cost"].shape == (3, 4, 4, 1)
    assert td["agents", "safety_cost"].dtype.is_floating_point


# ----------------------------------------------------------------------------- ladders
ALLOWED_RUNG_CHANGES = {"initial_state", "initial_positions", "random_position_spread", "random_start",
                        "random_shell", "random_cone", "success_tol", "dt", "substeps", "max_steps"}
"""What a rung may change on top of its training task: where the starts are drawn, the number of
agents, the success tolerance, the decision period and the horizon (the physics step stays:
:func:`physics_step`)."""


def physics_step(scenario) -> float:
    """The integration step of a scenario's truth [s]: ``physics_dt``, else ``dt / substeps``; the
    platoon and formation propagate their relative motion exactly over a decision, so their ``dt``."""
    if hasattr(scenario, "physics_dt"):
        return float(scenario.physics_dt)
    return float(scenario.dt) / getattr(scenario, "substeps", 1)


@pytest.mark.parametrize("system", list(tasks.SYSTEMS))
def test_ladder(system):
    names = tasks.ladder(system)
    assert len(names) >= 3 and len(set(names)) == len(names)
    training = tasks.training_task(system)
    assert names[-1] == training.name
    for name in names[:-1]:
        rung = tasks.get(name)
        assert rung.env_id == training.env_id and rung.system == system and rung.randomized
        changed = {k for k in {*rung.env_kwargs, *training.env_kwargs}
                   if rung.env_kwargs.get(k) != training.env_kwargs.get(k)}
        assert changed and changed <= ALLOWED_RUNG_CHANGES, changed
        assert rung.make_env().reward == "training"
    scenarios = [tasks.get(n).make_env().scenario for n in names]
    tols = [sc.success_tol for sc in scenarios]
    assert tols == sorted(tols, reverse=True)
    if scenarios[-1].__class__.__name__ in ("ClusterScenario", "ServicingScenario"):   # integrated truths
        assert len({round(physics_step(sc), 9) for sc in scenarios}) == 1


def test_ladder_unknown_system():
    with pytest.raises(SatenvError, match="unknown system"):
        tasks.ladder("platoon")


def _trivial_rates(name: str, n: int) -> dict[str, float]:
    task = tasks.get(name)
    start = task.seeds("test")[0]
    return {p: float(scripted(task, p, range(start, start + n))[1].mean()) for p in ("zero", "random")}


@pytest.mark.parametrize("name", RUNGS)
def test_no_rung_is_trivial(name):
    """Zero thrust and a uniform random policy each succeed on < 10 % of 20 test seeds."""
    rates = _trivial_rates(name, 20)
    assert max(rates.values()) < TRIVIAL_RATE, rates


@pytest.mark.slow
@pytest.mark.parametrize("name", RUNGS)
def test_no_rung_is_trivial_full(name):
    """The same on every test seed of the rung (1,000)."""
    rates = _trivial_rates(name, len(tasks.get(name).seeds("test")))
    assert max(rates.values()) < TRIVIAL_RATE, rates


def test_rewards_are_finite_and_bounded_per_step():
    """A training-reward step is finite and within the potential span, the bonuses and the penalties."""
    task = tasks.get("formation-kannan2022-position-random")
    vec = satenv.make_vec(task.env_id, 8, seed=900_000, **task.env_kwargs, max_steps=50)
    vec.reset()
    rng = np.random.default_rng(0)
    bound = rewards.POTENTIAL_SPAN + rewards.IN_TOLERANCE_BONUS + rewards.SUCCESS_BONUS + 3 * rewards.PENALTY
    for _ in range(60):
        _, rew, *_ = vec.step(rng.uniform(-1, 1, vec.action_shape))
        assert np.isfinite(rew).all() and (np.abs(rew) <= bound).all()
    assert math.isclose(rewards.SUCCESS_BONUS, rewards.EARNABLE + rewards.PENALTY + rewards.POTENTIAL_SPAN)


def test_each_penalty_once_per_agent_and_episode():
    """A collision lasting several steps costs its agent one penalty; a new episode charges again."""
    spec = rewards.TrainingReward(1.0, 200.0, 100.0, 10, True)
    state = rewards.RewardState(spec, 1, 2)
    info = {"tracking_error": np.full((1, 2, 6), 5.0), "state": np.zeros((1, 2, 6)),
            "collision": np.array([[True, False]]), "violations": np.array([[0, 0]])}
    state.reset(info)
    no = np.zeros(1, dtype=bool)
    first, second = state.step(info, no, no), state.step(info, no, no)
    np.testing.assert_allclose(first, [[-rewards.PENALTY, 0.0]])
    np.testing.assert_allclose(second, [[0.0, 0.0]])
    state.reset(info)
    np.testing.assert_allclose(state.step(info, no, no), [[-rewards.PENALTY, 0.0]])


def test_docs_tabulate_every_ladder():
    """docs/tasks.md names every rung of every ladder, in the ladder's order."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "tasks.md").read_text(encoding="utf-8")
    for system in tasks.SYSTEMS:
        where = [text.find(f"`{name}`") for name in tasks.ladder(system)]
        assert -1 not in where and where == sorted(where), (system, where)
