"""``satenv.training.load``'s contract with a caller: shipped filters fail closed, run folders resolve to
``final/``, inference on one torch thread without touching the caller's setting, typed errors."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

import satenv
from satenv import training
from satenv.training.policy import PolicyLoadError, ShippedFilterError, write_manifest

SHIPPED = sorted(p.name for p in training.POLICIES_DIR.iterdir() if (p / "manifest.json").is_file())
FILTERED = [n for n in SHIPPED if "safety_filter" in json.loads((training.POLICIES_DIR / n / "env.json").read_text())]


def test_some_shipped_folders_ship_behind_their_filter():
    """The next test walks every shipped folder; some of them are filtered (so it checks the refusal)."""
    assert FILTERED and "platoon_pereira2022_dagger_shield" in FILTERED


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_folder_without_env_loads_only_as_safe_as_shipped(name):
    """Without ``env=``: a folder that ships behind its filter raises (never the bare network by
    accident); ``shielded=False`` returns the network alone; an unfiltered folder loads."""
    folder = training.POLICIES_DIR / name
    if name in FILTERED:
        with pytest.raises(ShippedFilterError, match="shielded=False") as err:
            training.load(folder)
        assert isinstance(err.value, ValueError) and str(folder) in str(err.value)
        net = training.load(folder, shielded=False)
        assert type(net).__name__ == "LearnedPolicy"
    else:
        assert type(training.load(folder)).__name__ == "LearnedPolicy"


def test_a_filtered_folder_with_its_env_is_returned_behind_the_filter():
    from satenv.safety import Shield

    name = next(n for n in FILTERED if n.startswith("platoon"))
    env = satenv.platoon_v0(preset="pereira2022", randomize=True)
    assert isinstance(training.load(training.POLICIES_DIR / name, env=env), Shield)


def test_a_run_folder_resolves_to_its_final(tmp_path):
    """``satenv.training.load(out_dir)`` of a trainer's run folder loads ``out_dir/final``; a folder with
    neither policy files nor ``final/`` names what is missing."""
    src = training.POLICIES_DIR / "platoon_pereira2022_ppo"
    run = tmp_path / "run"
    shutil.copytree(src, run / "final")
    (run / "config.json").write_text("{}")       # a run folder's own config.json is not a policy file
    policy = training.load(run)
    assert policy.obs_shape == training.load(src).obs_shape
    with pytest.raises(PolicyLoadError, match="missing"):
        training.load(tmp_path)                  # no final/ inside tmp_path itself


def test_unusable_paths_are_typed_errors(tmp_path):
    with pytest.raises(PolicyLoadError, match="cannot be looked up"):
        training.load("x" * 5000)                # ENAMETOOLONG, not an untyped OSError
    with pytest.raises(PolicyLoadError, match="not a directory"):
        training.load(tmp_path / "nowhere")
    with pytest.raises(PolicyLoadError, match="shielded must be a bool"):
        training.load(training.POLICIES_DIR / SHIPPED[0], shielded="no")


def test_an_observation_shape_that_does_not_fit_names_the_files(tmp_path):
    """env.json's observation_shape against policy.json's actor (through config.json's features):
    the message names the files to compare."""
    folder = tmp_path / "p"
    shutil.copytree(training.POLICIES_DIR / "platoon_pereira2022_ppo", folder)
    meta = json.loads((folder / "env.json").read_text())
    meta["observation_shape"] = [meta["observation_shape"][0] + 1]
    (folder / "env.json").write_text(json.dumps(meta))
    write_manifest(folder)
    with pytest.raises(PolicyLoadError) as err:
        training.load(folder)
    assert "env.json" in str(err.value) and "policy.json" in str(err.value) and "obs_dim" in str(err.value)
    config = json.loads((folder / "config.json").read_text())
    meta["observation_shape"][0] -= 1
    (folder / "env.json").write_text(json.dumps(meta))
    config.update(obs_symlog_scale=1.0, obs_symlog_dims=3)
    (folder / "config.json").write_text(json.dumps(config))
    write_manifest(folder)
    with pytest.raises(PolicyLoadError) as err:
        training.load(folder)
    assert "config.json" in str(err.value) and "obs_symlog_scale" in str(err.value)


def test_inference_runs_on_one_thread_and_restores_the_callers_count():
    import torch

    from satenv.training import policy as tp

    pol = training.load(training.POLICIES_DIR / "platoon_pereira2022_ppo")
    seen = []
    forward = pol.actor.forward

    def spy(x):
        seen.append(torch.get_num_threads())
        return forward(x)

    pol.actor.forward = spy
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        pol.predict(np.zeros((3, *pol.obs_shape)))
        assert seen == [tp.INFERENCE_THREADS] and torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
