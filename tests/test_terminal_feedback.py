"""satenv.training.shaping.TerminalFeedback: the feedback law a policy blends in near its target."""

import json

import numpy as np
import pytest
from test_env_base import ToyEnv

from satenv import training
from satenv.training.actor import MLPActor
from satenv.training.policy import (
    LearnedPolicy,
    ObsNormalizer,
    PolicyLoadError,
    save_artifacts,
    write_manifest,
)
from satenv.training.shaping import TerminalFeedback

META = {"env_id": "test_env_base:ToyEnv", "observation_shape": [6], "action_shape": [3]}
TERM = {"radius": 10.0, "gain": 2.0, "bandwidth": 0.1, "speed": 0.5}


def _obs(e, v):
    return np.concatenate([np.atleast_2d(e), np.atleast_2d(v)], axis=1).astype(float)


def test_blend_weights_network_far_and_feedback_at_the_target():
    term = TerminalFeedback(**TERM)
    net = np.full((1, 3), 0.3)
    far = term(_obs([1e4, 0, 0], [0, 0, 0]), net)
    np.testing.assert_allclose(far, net, atol=1e-12)               # exp(-1000): the network alone
    at = term(_obs([0.0, 0, 0], [0.1, -0.2, 0.0]), net)
    np.testing.assert_allclose(at, [[-0.2, 0.4, 0.0]], atol=1e-12)  # w = 1: gain * (0 - v)
    # halfway: w = exp(-1); the commanded speed is capped at `speed`, opposing the error
    e = np.array([10.0, 0, 0])
    mid = term(_obs(e, [0, 0, 0]), net)
    w = np.exp(-1.0)
    fb = np.clip(2.0 * (-0.5 * e / 10.0), -1, 1)                  # |v_ref| = 1 > 0.5: capped
    np.testing.assert_allclose(mid, (1 - w) * net + w * fb, atol=1e-12)


def test_off_by_default_and_bad_fields_named():
    assert not TerminalFeedback().active
    with pytest.raises(ValueError, match="terminal gain"):
        TerminalFeedback(radius=1.0, gain=-1.0)
    with pytest.raises(ValueError, match="terminal radius"):
        TerminalFeedback(radius=float("nan"))
    with pytest.raises(ValueError, match=r"unknown field\(s\) \['gian'\]"):
        TerminalFeedback.from_config({"terminal": {"gian": 1.0}})
    for bad in ([], 0, "", [["radius", 1.0]]):         # not an object: an error, never "off"
        with pytest.raises(ValueError, match="terminal must be an object"):
            TerminalFeedback.from_config({"terminal": bad})
    assert not TerminalFeedback.from_config({"terminal": None}).active
    with pytest.raises(ValueError, match="do not fit"):
        TerminalFeedback(radius=1.0, velocity_at=5)(np.zeros((1, 6)), np.zeros((1, 3)))


def test_a_folder_carries_its_feedback_and_a_bad_one_is_a_load_error(tmp_path):
    actor = MLPActor(6, 3, [8], "relu", True)
    policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(6,), meta=META)
    folder = save_artifacts(tmp_path / "p", policy, env_meta=META, config={"terminal": TERM})
    loaded = training.load(folder, env=ToyEnv())
    assert loaded.terminal == TerminalFeedback(**TERM)
    obs = _obs([0.0, 0, 0], [0.1, 0, 0])
    np.testing.assert_allclose(loaded.predict(obs), [[-0.2, 0, 0]], atol=1e-6)
    cfg = json.loads((folder / "config.json").read_text())
    cfg["terminal"] = {"radius": "big"}
    (folder / "config.json").write_text(json.dumps(cfg))
    write_manifest(folder)
    with pytest.raises(PolicyLoadError, match="config.json.*terminal radius"):
        training.load(folder, env=ToyEnv())


def test_a_non_finite_observation_gives_the_flagged_zero_action_not_nan():
    actor = MLPActor(6, 3, [8], "relu", True)
    policy = LearnedPolicy(actor, ObsNormalizer(), obs_shape=(6,), meta=META,
                           terminal=TerminalFeedback(**TERM))
    obs = np.zeros((3, 6))
    obs[0, 0], obs[1, 1] = np.nan, np.inf           # position errors the feedback reads
    out = policy.predict(obs)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[:2], 0.0)
    assert policy.info["fallbacks"] == 2
