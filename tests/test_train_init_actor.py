"""``satenv.training.train --init-actor``: a PPO run started from a saved (e.g. DAgger) network."""

import json

import numpy as np
import pytest
import torch
from test_env_base import ToyEnv
from test_training import TOY, _cfg

from satenv import training
from satenv.training.actor import MLPActor
from satenv.training.envs import policy_env_meta
from satenv.training.policy import LearnedPolicy, ObsNormalizer, save_artifacts
from satenv.training.shaping import ObsFeatures
from satenv.training.train import build_model, init_policy, latest_checkpoint, seed_actor, train

SEED_FEATURES = {"obs_symlog_scale": 10.0, "obs_symlog_dims": 3}


@pytest.fixture(autouse=True)
def _private_baseline_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "satenv_cache"))


def _seed_folder(tmp_path):
    """A DAgger-like folder: ReLU MLP with a tanh output, symlog features, a normaliser."""
    torch.manual_seed(0)
    actor = MLPActor(9, 3, [16, 16], "relu", True)
    with torch.no_grad():
        actor.head.weight.mul_(20.0)   # outputs well inside tanh's saturation, where a missing tanh shows
    rng = np.random.default_rng(1)
    norm = ObsNormalizer(rng.normal(size=9), rng.uniform(0.5, 2.0, size=9), clip_obs=10.0)
    env = ToyEnv(max_steps=10)
    policy = LearnedPolicy(actor, norm, obs_shape=(6,), features=ObsFeatures(10.0, 3))
    meta = policy_env_meta(TOY, env, {"max_steps": 10}, {"max_steps": 10})
    return save_artifacts(tmp_path / "seed", policy, env_meta=meta, config=dict(SEED_FEATURES), source="test seed")


def test_a_seeded_ppo_run_starts_from_the_seed_and_resumes(tmp_path):
    folder = _seed_folder(tmp_path)
    cfg = _cfg(tmp_path, init_actor=str(folder), lr=1e-12, total_timesteps=96, eval_every=0,
               checkpoint_every=96, **SEED_FEATURES)
    final = train(cfg)
    seed, got = training.load(folder), training.load(final)
    assert got.actor.spec == seed.actor.spec == {"type": "mlp", "obs_dim": 9, "act_dim": 3, "hidden": [16, 16],
                                                 "activation": "relu", "squash": True}
    obs = np.random.default_rng(2).normal(0.0, 3.0, size=(64, 6))
    want = seed.predict(obs)
    assert np.abs(want).max() > 0.99   # the test reaches the squashed range
    np.testing.assert_allclose(got.predict(obs), want, atol=1e-4)   # lr 1e-12: still the seed
    np.testing.assert_allclose(got.normalizer.mean, seed.normalizer.mean, atol=1e-6)
    # the resumed model is built the same way (tanh head, ReLU) and loads its checkpoint
    resumed = train(cfg.replace(total_timesteps=192), resume=True)
    assert latest_checkpoint(tmp_path / "run")[0] == 192
    np.testing.assert_allclose(training.load(resumed).predict(obs), want, atol=1e-4)
    assert json.loads((resumed / "config.json").read_text())["init_actor"] == str(folder)


def test_the_seeding_check_fails_on_a_model_of_another_shape(tmp_path):
    from stable_baselines3.common.vec_env import VecNormalize

    from satenv.training.vec_env import SatVecEnv

    folder = _seed_folder(tmp_path)
    cfg = _cfg(tmp_path, **SEED_FEATURES)   # no init_actor: tanh hidden layers, no tanh on the head
    seed = init_policy(cfg.replace(init_actor=str(folder)))
    venv = VecNormalize(SatVecEnv(ToyEnv(max_steps=10), 2, seed=0, obs_fn=ObsFeatures(10.0, 3)))
    obs = np.random.default_rng(3).normal(0.0, 3.0, size=(32, 6))
    maps = {"features": ObsFeatures(10.0, 3), "action_map": None}
    with pytest.raises(ValueError, match="does not reproduce the seed's actions"):
        seed_actor(build_model(cfg, venv), venv, seed, obs, maps)
    seeded = cfg.replace(init_actor=str(folder))
    assert seed_actor(build_model(seeded, venv), venv, seed, obs, maps) <= 1e-5


def test_a_seed_that_does_not_fit_the_run_is_a_value_error_naming_the_field(tmp_path):
    folder = str(_seed_folder(tmp_path))
    with pytest.raises(ValueError, match=r"hidden layers \[16, 16\]; give --net-arch 16,16"):
        init_policy(_cfg(tmp_path, init_actor=folder, net_arch=(32, 32), **SEED_FEATURES))
    with pytest.raises(ValueError, match="observation features"):
        init_policy(_cfg(tmp_path, init_actor=folder))
    with pytest.raises(ValueError, match="--clip-obs"):
        init_policy(_cfg(tmp_path, init_actor=folder, clip_obs=5.0, **SEED_FEATURES))
    with pytest.raises(ValueError, match="init_actor seeds a PPO actor"):
        _cfg(tmp_path, init_actor=folder, algo="sac")
    with pytest.raises(ValueError, match="init_actor must be a policy folder"):
        _cfg(tmp_path, init_actor=3)


def test_the_filtered_training_env_takes_the_filter_options_a_folder_ships_with():
    from satenv.bench.learning.trainers import filtered_task_env
    from satenv.safety import SafetyError

    env = filtered_task_env("servicing-pereira2022-random", penalty=1.0, safety={"margin": 0.005})
    assert (env.safety.config.margin, env.safety.config.penalty) == (0.005, 1.0)
    assert filtered_task_env("servicing-pereira2022-random").safety.config.margin == 0.02   # the default
    with pytest.raises(SafetyError, match="unknown option.*'margn'"):
        filtered_task_env("servicing-pereira2022-random", safety={"margn": 0.005})
