"""Every path that takes ``safety_filter=True`` filters (or refuses): a ramming adversary flies
through each, and the env's own collision flags are counted (agent-steps). The same adversary
without the filter collides (:func:`test_the_ramming_adversary_collides_unfiltered`), so each
zero below is a measurement that can fail. Also: no non-finite output of a filtered env on any
input, and the filter's own bad-input errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import satenv
from satenv.errors import SatenvError
from satenv.safety import MIN_MARGIN, SafetyConfig, SafetyError, SafetyFilter, SafetyWarning, Shield

STEPS = 60                     # the unfiltered adversary collides within 30 steps on both scenarios
SCENARIOS = [("platoon_v0", {}), ("cluster_v0", {"randomize": True})]
GYM_IDS = {"platoon_v0": "satenv/Platoon-v0", "cluster_v0": "satenv/Cluster-v0"}


def ram(x: np.ndarray, action_dim: int) -> np.ndarray:
    """The ramming adversary: every agent at full thrust straight at its nearest other agent,
    ``(B, M, action_dim)`` from the true states ``x (B, M, >= 3)``."""
    p = np.asarray(x, dtype=float)[..., :3]
    diff = p[:, None, :, :] - p[:, :, None, :]             # [b, i, j] = p_j - p_i
    dist = np.linalg.norm(diff, axis=-1)
    m = p.shape[1]
    dist[:, np.arange(m), np.arange(m)] = np.inf
    nearest = np.take_along_axis(diff, dist.argmin(-1)[..., None, None], axis=2)[:, :, 0]
    out = np.zeros((*nearest.shape[:2], action_dim))
    out[..., :3] = nearest / np.maximum(np.abs(nearest).max(-1, keepdims=True), 1e-12)
    return out


def _count(flags) -> int:
    return int(np.sum(np.asarray(flags, dtype=bool)))


def _vec_collisions(vec, steps: int = STEPS) -> int:
    """Collision agent-steps of a :class:`satenv.vector.SatVectorEnv` under :func:`ram`."""
    vec.reset(seed=0)
    total = 0
    for _ in range(steps):
        _, _, _, _, info = vec.step(ram(vec.core.x, vec.single_action_space.shape[0]))
        total += _count(info.get("final_info", info)["collision"])
    return total


def _dict_collisions(env, steps: int = STEPS, seeds=(0, 1)) -> int:
    """Collision agent-steps of a PettingZoo env under :func:`ram` (a new episode when one ends)."""
    total, done = 0, 0
    for seed in seeds:
        env.reset(seed=seed)
        while env.agents and done < steps:
            a = ram(env.core.x, env.core.action_dim)[0]
            _, _, _, _, infos = env.step(dict(zip(env.possible_agents, a, strict=True)))
            total += sum(_count(i["collision"]) for i in infos.values())
            done += 1
    return total


# ------------------------------------------------------------------------ the adversary is real
@pytest.mark.parametrize("env_id,kwargs", SCENARIOS)
def test_the_ramming_adversary_collides_unfiltered(env_id, kwargs):
    assert _vec_collisions(satenv.make_vec(env_id, 2, **kwargs)) > 0
    assert _dict_collisions(satenv.make(env_id, **kwargs)) > 0


# ------------------------------------------------------------------------ every path
@pytest.mark.parametrize("env_id,kwargs", SCENARIOS)
def test_make_filters(env_id, kwargs):
    assert _dict_collisions(satenv.make(env_id, safety_filter=True, **kwargs)) == 0


@pytest.mark.parametrize("env_id,kwargs", SCENARIOS)
def test_make_vec_filters(env_id, kwargs):
    vec = satenv.make_vec(env_id, 2, safety_filter=True, **kwargs)
    assert vec.safety is not None and _vec_collisions(vec) == 0


@pytest.mark.parametrize("env_id,kwargs", SCENARIOS)
def test_a_batch_of_a_filtered_env_filters_and_cannot_drop_it(env_id, kwargs):
    from satenv.vector import SatVectorEnv

    template = satenv.make(env_id, safety_filter=SafetyConfig(margin=0.05), **kwargs)
    vec = SatVectorEnv(template, 2)
    assert vec.safety.config.margin == 0.05 and _vec_collisions(vec) == 0
    with pytest.raises(SatenvError, match="safety_filter=False with a filtered env"):
        SatVectorEnv(template, 2, safety_filter=False)
    plain = SatVectorEnv(satenv.make(env_id, **kwargs), 2, safety_filter=True)
    assert plain.safety is not None and _vec_collisions(plain) == 0


@pytest.mark.parametrize("env_id,kwargs", SCENARIOS)
def test_gymnasium_make_filters(env_id, kwargs):
    import gymnasium as gym

    env = gym.make(GYM_IDS[env_id], safety_filter=True, **kwargs)
    core = env.unwrapped.env.core
    total = 0
    env.reset(seed=0)
    for _ in range(STEPS):
        _, _, term, trunc, info = env.step(ram(core.x, core.action_dim).reshape(-1))
        total += sum(_count(i["collision"]) for i in info["agents"].values())
        if term or trunc:
            env.reset()
    assert total == 0


@pytest.mark.parametrize("mode", ["vector_entry_point", "sync", "async"])
def test_gymnasium_make_vec_filters_in_every_mode(mode):
    import gymnasium as gym

    env_id, kwargs = SCENARIOS[1]
    make = dict(num_envs=2, safety_filter=True, **kwargs)
    vec = gym.make_vec(GYM_IDS[env_id], vectorization_mode=mode, **make)
    # the adversary reads the true states; an async worker's env does not pickle, so its states
    # come from a sync twin flown with the same seeds and actions (observations checked equal)
    twin = gym.make_vec(GYM_IDS[env_id], vectorization_mode="sync", **make) if mode == "async" else vec
    try:
        obs, _ = vec.reset(seed=0)
        if twin is not vec:
            assert np.array_equal(obs, twin.reset(seed=0)[0])
        total = 0
        for _ in range(STEPS):
            if mode == "vector_entry_point":
                x, d = vec.vec.core.x, vec.vec.core.action_dim
            else:
                cores = [e.unwrapped.env.core for e in twin.envs]
                x, d = np.concatenate([c.x for c in cores]), cores[0].action_dim
            a = ram(x, d).reshape(2, -1)
            obs, _, _, _, info = vec.step(a)
            if mode == "vector_entry_point":
                total += _count(info["final_info"]["collision"] if "final_info" in info else info["collision"])
                assert "safety_intervened" in info
            else:
                total += sum(_count(v["collision"]) for k, v in info["agents"].items() if not k.startswith("_"))
                assert "safety_intervened" in info["agents"]["sat_1"]
            if twin is not vec:
                assert np.array_equal(obs, twin.step(a)[0])
        assert total == 0
    finally:
        vec.close()
        twin.close()


def _spy(vec, seen: list) -> None:
    """Record the infos of every ``step`` of a :class:`satenv.vector.SatVectorEnv` (collision flags)."""
    step = vec.step

    def spied(actions):
        out = step(actions)
        seen.append(_count(out[4].get("final_info", out[4])["collision"]))
        return out

    vec.step = spied


def _torchrl_rammer(env):
    """:func:`ram` as a TorchRL policy on a :class:`satenv.torchrl.SatTorchRLEnv`."""
    import torch

    core = env.vec.core

    def policy(td):
        td["agents", "action"] = torch.as_tensor(ram(core.x, core.action_dim), dtype=torch.float32)
        return td

    return policy


def test_torchrl_env_filters():
    pytest.importorskip("torchrl")
    from satenv.torchrl import make_env

    env_id, kwargs = SCENARIOS[1]
    env = make_env(env_id, 2, seed=0, safety_filter=True, **kwargs)
    seen: list[int] = []
    _spy(env.vec, seen)
    td = env.rollout(STEPS, policy=_torchrl_rammer(env))
    assert td["next", "agents", "safety_intervened"].any()
    assert len(seen) == td.shape[-1] > 0 and sum(seen) == 0


def test_sb3_training_env_filters():
    pytest.importorskip("stable_baselines3")
    from satenv.training.envs import make_env
    from satenv.training.vec_env import SatVecEnv

    env_id, kwargs = SCENARIOS[1]
    venv = SatVecEnv(make_env(env_id, safety_filter=True, **kwargs), 2, seed=0)   # as satenv.training.train builds it
    assert venv.vec.safety is not None
    venv.reset()
    total = 0
    for _ in range(STEPS):
        venv.step(ram(venv.core.x, venv.core.action_dim).reshape(venv.num_envs, -1))
        total += _count(venv.last_info["collision"])
        assert "safety_delta" in venv.last_info
    assert total == 0


def test_benchmarl_task_env_filters():
    pytest.importorskip("benchmarl")
    from satenv.training.benchmarl_task import task_for

    env_id, kwargs = SCENARIOS[1]
    env = task_for(env_id, {"safety_filter": True, **kwargs}).get_env_fun(2, True, 0, "cpu")()
    assert env.vec.safety is not None
    seen: list[int] = []
    _spy(env.vec, seen)
    td = env.rollout(STEPS, policy=_torchrl_rammer(env))
    assert len(seen) == td.shape[-1] > 0 and sum(seen) == 0


def test_rllib_training_env_filters():
    pytest.importorskip("ray.rllib")
    from satenv.training.rllib_train import _env_creator

    env_id, kwargs = SCENARIOS[1]
    env = _env_creator(env_id, {"safety_filter": True, **kwargs})()
    par = env.par_env
    assert par.safety is not None
    total = 0
    env.reset(seed=0)
    for _ in range(STEPS):
        a = ram(par.core.x, par.core.action_dim)[0]
        _, _, term, trunc, infos = env.step(dict(zip(par.possible_agents, a, strict=True)))
        total += sum(_count(i["collision"]) for k, i in infos.items() if k != "__common__")
        if term["__all__"] or trunc["__all__"]:
            env.reset()
    assert total == 0


def test_shield_filters():
    env_id, kwargs = SCENARIOS[1]
    env = satenv.make(env_id, **kwargs)

    class Rammer:
        def reset(self, seed=None):
            pass

        def act(self, observations):
            return dict(zip(env.possible_agents, ram(env.core.x, env.core.action_dim)[0], strict=True))

    policy = Shield(env, Rammer())
    total = 0
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        policy.reset(seed)
        for _ in range(STEPS // 2):
            obs, _, _, _, infos = env.step(policy.act(obs))
            total += sum(_count(i["collision"]) for i in infos.values())
            if not env.agents:
                break
    assert total == 0 and policy.info["safety_interventions"] > 0


# ------------------------------------------------------------------------ no non-finite output
HUGE = [1e300, -np.finfo(float).max, np.finfo(float).max]


@pytest.mark.parametrize("env_id", ["servicing_v0", "platoon_v0", "cluster_v0"])
def test_a_filtered_env_never_returns_non_finite_values(env_id):
    env = satenv.make(env_id, safety_filter=SafetyConfig(penalty=1.0))
    d = env.core.action_dim
    rng = np.random.default_rng(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)        # no overflow on the way either
        for value in HUGE:
            env.reset(seed=0)
            for _ in range(3):
                a = {ag: np.full(d, value) * rng.choice([-1.0, 1.0], d) for ag in env.agents}
                obs, rew, _, _, infos = env.step(a)
                assert all(np.all(np.isfinite(o)) for o in obs.values())
                assert all(np.isfinite(r) for r in rew.values())
                for i in infos.values():
                    assert all(np.all(np.isfinite(np.asarray(v, dtype=float))) for k, v in i.items()
                               if k != "safety_active"), i
                    assert 0.0 <= i["safety_delta"] <= 2.0 * np.sqrt(d)
                if not env.agents:
                    break
    for bad in (np.inf, -np.inf, np.nan):      # rejected before the filter, named
        env.reset(seed=0)
        with pytest.raises(SatenvError, match="non-finite|NaN|inf"):
            env.step({ag: np.full(d, bad) for ag in env.agents})


def test_a_filtered_batch_never_returns_non_finite_values():
    vec = satenv.make_vec("servicing_v0", 2, seed=0, safety_filter=SafetyConfig(penalty=3.0))
    vec.reset()
    d = vec.single_action_space.shape[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        for value in HUGE:
            obs, rew, _, _, info = vec.step(np.full((2, 2, d), value))
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
            assert np.all(np.isfinite(info["safety_delta"])) and info["safety_delta"].max() <= 2.0 * np.sqrt(d)
    with pytest.raises(SatenvError):
        vec.step(np.full((2, 2, d), np.inf))


def test_the_record_measures_the_change_of_the_clipped_proposal():
    env = satenv.make("cluster_v0", randomize=True)
    env.reset(seed=0)
    filt = SafetyFilter(env)
    for _ in range(STEPS):                                    # ram unfiltered until the filter must act
        unsafe = np.sign(ram(env.core.x, 3)[0])               # entries 0 or +-1: the box clips 1e300 to them
        if filt.filter(unsafe)[1].intervened.any():
            break
        env.step(dict(zip(env.possible_agents, unsafe, strict=True)))
    out1, rec1 = filt.filter(unsafe)
    out2, rec2 = filt.filter(unsafe * 1e300)                  # the env applies the same action
    assert rec1.intervened.any() and np.array_equal(rec1.intervened, rec2.intervened)
    changed = rec1.intervened[0]
    assert np.array_equal(out1[changed], out2[changed]) and np.array_equal(rec1.delta, rec2.delta)
    assert np.all(rec2.delta <= 2.0 * np.sqrt(3)) and rec2.delta.max() > 0


# ------------------------------------------------------------------------ the filter's bad input
def test_the_filter_names_the_argument_and_rejects_what_it_cannot_read():
    env = satenv.make("platoon_v0")
    env.reset(seed=0)
    filt = SafetyFilter(env)
    with pytest.raises(SafetyError, match=r"actions has 2 copies .* the env it filters for has 1"):
        filt.filter(np.zeros((2, 4, 3)))
    with pytest.raises(TypeError, match="actions must be a real array, got .*complex"):
        filt.filter(np.zeros((4, 3)) + 1j)
    with pytest.raises(TypeError, match="actions must be a real array, got MaskedArray"):
        filt.filter(np.ma.masked_array(np.zeros((4, 3)), mask=True))
    with pytest.raises(TypeError, match="actions must be a real array"):
        filt.filter(np.zeros((4, 3), dtype=bool))

    class Complex:
        def reset(self, seed=None):
            pass

        def act(self, observations):
            return {a: np.zeros(3) + 0.5j for a in env.possible_agents}

    with pytest.raises(TypeError, match="action of follower_1 must be a real array"):
        Shield(env, Complex()).act({})
    out, _ = filt.filter(np.zeros((4, 3)))                    # a rejected call leaves it usable
    assert np.array_equal(out, np.zeros((4, 3)))


@pytest.mark.parametrize("options,match", [
    ({"margin": 10**400}, "SafetyConfig.margin must be finite"),
    ({"penalty": -10**400}, "SafetyConfig.penalty must be finite"),
    ({"margin": 1e-300}, "SafetyConfig.margin must be >= MIN_MARGIN"),
    ({"los_margin": 1e-300}, "SafetyConfig.los_margin must be >= MIN_MARGIN"),
    ({"velocity_margin": 5e-324}, "SafetyConfig.velocity_margin must be >= MIN_MARGIN"),
])
def test_the_config_rejects_out_of_range_values_with_a_value_error(options, match):
    with pytest.raises(SafetyError, match=match) as err:
        SafetyConfig.from_options(**options)
    assert isinstance(err.value, ValueError) and not isinstance(err.value, OverflowError)
    assert SafetyConfig(margin=MIN_MARGIN).margin == MIN_MARGIN


def test_a_filter_without_a_keep_out_warns():
    with pytest.warns(SafetyWarning, match="collision_distance"):
        satenv.make("formation_v0", safety_filter=True)
    with pytest.warns(SafetyWarning):
        satenv.make("formation_v0", preset="kannan2022-collision", safety_filter=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SafetyWarning)
        satenv.make("formation_v0", collision_distance=5.0, safety_filter=True)
        satenv.make("cluster_v0", safety_filter=True)
