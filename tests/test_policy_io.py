"""satenv.training.policy: the no-pickle policy format (export, save/load, manifest, normaliser, trust)."""

import base64
import json
import pickle
import zipfile

import numpy as np
import pytest
from test_env_base import ToyEnv

from satenv import training
from satenv.training.policy import (
    ObsNormalizer,
    PolicyLoadError,
    convert_sb3,
    from_sb3,
    save_artifacts,
)

META = {"env_id": "test_env_base:ToyEnv", "observation_shape": [6], "action_shape": [3]}


def _model(algo):
    from stable_baselines3 import PPO, SAC

    from satenv.training.vec_env import SatVecEnv

    vec = SatVecEnv(ToyEnv(), n_copies=1, seed=0)
    if algo == "ppo":
        return PPO("MlpPolicy", vec, n_steps=8, policy_kwargs={"net_arch": [8, 8], "log_std_init": -1.0},
                   seed=0, device="cpu")
    return SAC("MlpPolicy", vec, policy_kwargs={"net_arch": [8]}, seed=0, device="cpu", buffer_size=10)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_exported_actor_reproduces_sb3_predict_and_round_trips(tmp_path, algo):
    model = _model(algo)
    norm = ObsNormalizer(np.arange(6.0), np.full(6, 4.0), clip_obs=5.0)
    policy = from_sb3(model, norm, obs_shape=(6,), meta=META)
    obs = np.random.default_rng(0).normal(size=(5, 6)) * 3
    expected, _ = model.predict(norm(obs), deterministic=True)
    np.testing.assert_allclose(policy.predict(obs), np.clip(expected, -1, 1), atol=1e-6)
    folder = save_artifacts(tmp_path / "p", policy, env_meta=META, config={"algo": algo})
    loaded = training.load(folder, env=ToyEnv())
    np.testing.assert_array_equal(loaded.predict(obs), policy.predict(obs))
    assert not list(folder.glob("*.zip")) and not list(folder.glob("*.pkl"))


def _saved(tmp_path):
    policy = from_sb3(_model("ppo"), ObsNormalizer(), obs_shape=(6,), meta=META)
    return save_artifacts(tmp_path / "p", policy, env_meta=META, config={"algo": "ppo"})


def test_manifest_is_checked(tmp_path):
    folder = _saved(tmp_path)
    (folder / "obs_norm.json").write_text(json.dumps({"identity": False, "mean": [0.0] * 6, "var": [1.0] * 6}))
    with pytest.raises(PolicyLoadError, match=r"\['obs_norm.json'\] do not match manifest.json"):
        training.load(folder)


@pytest.mark.parametrize(("norm", "match"), [
    ({"identity": False, "mean": [0.0] * 5 + [float("nan")], "var": [1.0] * 6}, "finite"),
    ({"identity": False, "mean": [0.0] * 6, "var": [1.0] * 5 + [-1.0]}, "variance"),
    ({"identity": False, "mean": [0.0] * 6, "var": [0.0] * 6, "epsilon": 0.0}, "variance"),
    ({"identity": False, "mean": [0.0] * 4, "var": [1.0] * 4}, "shape"),
    ({"identity": "yes"}, "identity"),
    ([1, 2], "identity"),
])
def test_bad_normaliser_is_a_policy_load_error(tmp_path, norm, match):
    from satenv.training.policy import write_manifest

    folder = _saved(tmp_path)
    (folder / "obs_norm.json").write_text(json.dumps(norm))
    write_manifest(folder)
    with pytest.raises(PolicyLoadError, match=match):
        training.load(folder)


class _Boom:
    """Unpickling this creates a file: the marker that code ran."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (str(self.path), "w"))


def test_a_crafted_policy_folder_runs_no_code(tmp_path):
    marker = tmp_path / "PWNED"
    payload = pickle.dumps(_Boom(marker))
    from satenv.training.policy import write_manifest

    # 1. weights.safetensors that is a malicious pickle
    folder = _saved(tmp_path)
    (folder / "weights.safetensors").write_bytes(payload)
    write_manifest(folder)
    with pytest.raises(PolicyLoadError, match="weights.safetensors"):
        training.load(folder)
    # 1b. a legacy weights.pt that is one: refused, and even trusted=True reads it weights-only
    (folder / "weights.safetensors").unlink()
    (folder / "weights.pt").write_bytes(payload)
    write_manifest(folder)
    with pytest.raises(PolicyLoadError, match="weights.pt.*convert_weights_pt"):
        training.load(folder)
    with pytest.warns(UserWarning, match="trusted=True"), pytest.raises(PolicyLoadError, match="weights.pt"):
        training.load(folder, trusted=True)
    # 2. an SB3 model.zip whose data would unpickle the payload
    sb3 = tmp_path / "sb3"
    sb3.mkdir()
    for name in ("env.json", "config.json"):
        (sb3 / name).write_text(json.dumps(META if name == "env.json" else {"algo": "ppo"}))
    np.savez(sb3 / "obs_norm.npz", identity=np.array(True))
    with zipfile.ZipFile(sb3 / "model.zip", "w") as z:
        data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>",
                                 ":serialized:": base64.b64encode(payload).decode()}}
        z.writestr("data", json.dumps(data))
    with pytest.raises(PolicyLoadError, match="trusted=True"):
        training.load(sb3)
    # 3. the scoreboard's --policy path goes through the same loader
    assert not marker.exists(), "loading a policy folder ran code"


def test_trusted_sb3_zip_loads_with_a_warning_and_converts(tmp_path):
    model = _model("ppo")
    folder = tmp_path / "old"
    folder.mkdir()
    model.save(folder / "model.zip")
    np.savez(folder / "obs_norm.npz", identity=np.array(True))
    (folder / "env.json").write_text(json.dumps(META))
    (folder / "config.json").write_text(json.dumps({"algo": "ppo"}))
    with pytest.raises(PolicyLoadError, match="unpickle"):
        training.load(folder)
    with pytest.warns(UserWarning, match="trusted=True"):
        old = training.load(folder, trusted=True)
    convert_sb3(folder)
    (folder / "model.zip").unlink()
    new = training.load(folder)
    obs = np.random.default_rng(1).normal(size=(3, 6))
    np.testing.assert_array_equal(new.predict(obs), old.predict(obs))


def test_a_folder_shipped_behind_the_safety_filter_loads_as_shipped(tmp_path):
    """``env.json`` ``safety_filter``: ``satenv.training.load(folder, env=env)`` returns the filtered
    policy, ``shielded=False`` the network, no env an error; the entry is data (never imported)."""
    import json
    import shutil

    import satenv
    from satenv.safety import Shield
    from satenv.training.card import card
    from satenv.training.policy import PolicyLoadError, write_manifest

    src = training.POLICIES_DIR / "platoon_pereira2022_dagger_shield"
    env = satenv.platoon_v0(preset="pereira2022", randomize=True)
    assert isinstance(training.load(src, env=env), Shield)
    assert not isinstance(training.load(src, env=env, shielded=False), Shield)
    with pytest.raises(PolicyLoadError, match="ships behind the safety filter"):
        training.load(src)      # fails closed: never the bare network by accident
    assert not isinstance(training.load(src, shielded=False), Shield)
    c = card(src)
    assert c["filtered"] and c["shipped"] != "learned" and c["network_alone"]["episodes"] > 0
    bad = tmp_path / "bad"
    shutil.copytree(src, bad)
    meta = json.loads((bad / "env.json").read_text())
    meta["safety_filter"] = {"wrapper": "os:system", "options": {}}
    (bad / "env.json").write_text(json.dumps(meta))
    write_manifest(bad)
    with pytest.raises(PolicyLoadError, match="safety_filter"):
        training.load(bad, env=env)
    meta["safety_filter"] = {"wrapper": "satenv.safety.shield", "options": {"margin": float("nan")}}
    (bad / "env.json").write_text(json.dumps(meta))
    write_manifest(bad)
    with pytest.raises(PolicyLoadError, match="env.json: safety_filter options.*margin"):
        training.load(bad, env=env)
