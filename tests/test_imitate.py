"""DAgger imitation (training.imitate): config validation, data collection, a tiny run, resume."""

from __future__ import annotations

import json

import numpy as np
import pytest

import baselines
import satenv
import training
from training.imitate import ImitationConfig, collect_episode, main

SHORT = {"preset": "pereira2022", "randomize": True, "max_steps": 12}


@pytest.fixture(autouse=True)
def _private_baseline_cache(tmp_path_factory, monkeypatch):
    """Baseline results are cached on disk (training.evaluate.cache_dir): one cache per test session."""
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "satenv_cache"))


def test_config_validation_names_the_field(capsys):
    with pytest.raises(ValueError, match="beta"):
        ImitationConfig(beta=1.5)
    with pytest.raises(ValueError, match="rounds"):
        ImitationConfig(rounds=0)
    with pytest.raises(ValueError, match="activation"):
        ImitationConfig(activation="sigmoid")
    with pytest.raises(ValueError, match="expert_options"):
        ImitationConfig(expert_options=[1])
    with pytest.raises(SystemExit):
        main(["--expert-options", "[1]"])
    assert "--expert-options" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="unknown ImitationConfig field"):
        main(["--config", "tests/../training/policies/platoon_tplf_ppo/config.json"])


def test_collect_episode_labels_every_visited_state_with_the_expert():
    env = satenv.make("platoon_v0", **SHORT)
    expert = baselines.make("dmpc", env)
    rng = np.random.default_rng(0)
    x, y = collect_episode(env, expert, None, seed=3, beta=1.0, rng=rng)
    assert x.shape == (12 * 2, 22) and y.shape == (12 * 2, 3)
    assert np.all(np.abs(y) <= 1.0) and np.isfinite(x).all()
    # the expert flies beta = 1: its own rollout gives the same first observation and label
    obs, _ = env.reset(seed=3)
    expert.reset(seed=3)
    first = expert.act(obs)
    np.testing.assert_allclose(y[:2], np.clip(np.stack([first[a] for a in obs]), -1, 1))


def test_tiny_run_writes_a_loadable_policy_and_resumes(tmp_path):
    out = tmp_path / "run"
    flags = ["--env-kwargs", json.dumps(SHORT), "--rounds", "2", "--episodes-per-round", "1",
             "--epochs", "2", "--net-arch", "16", "--eval-seeds", "7", "--test-seeds", "8,9",
             "--out-dir", str(out), "--progress", "false", "--lr", "0.001"]
    final = main(flags)
    policy = training.load(final, env=satenv.make("platoon_v0", **SHORT))
    ev = json.loads((final / "eval.json").read_text())
    assert ev["test_seeds"] == [8, 9] and set(ev["aggregate"]) == {"learned", "dmpc", "zero"}
    assert ev["vs_DMPC"]["all_seeds"]["seeds"] == 2 and "matched_seeds" in ev["vs_DMPC"]["matched"] and ev["labels"] == 2 * 12 * 2
    assert (out / "learning_curve.png").is_file() and len(json.loads((out / "eval_history.json").read_text())) == 2
    with pytest.raises(SystemExit, match="--resume"):
        main(flags)
    again = main([*flags, "--rounds", "3", "--resume"])  # one more round on top of the saved two
    assert len(json.loads((out / "eval_history.json").read_text())) == 3
    assert json.loads((again / "eval.json").read_text())["labels"] == 3 * 12 * 2
    obs, _ = satenv.make("platoon_v0", **SHORT).reset(seed=0)
    assert set(policy.act(obs)) == set(obs)


def test_policy_cards_read_every_shipped_folder_and_judge_the_targets():
    from training.card import card, shipped_table, targets

    table = shipped_table()
    for folder in training.POLICIES_DIR.iterdir():
        if (folder / "eval.json").is_file():
            assert f"`{folder.name}`" in table
    good = {"success": 0.96, "baseline_success": 0.9, "collision_episodes": 0, "violations": 0.0,
            "violation_episodes": 0, "rmse_ratio": 1.2, "delta_v_ratio": 1.49}
    assert all(targets(good).values())
    assert not targets({**good, "success": 0.88})["success"]          # below 90 %
    assert targets({**good, "baseline_success": 1.0})["success"]      # within 5 points of the baseline
    assert not targets({**good, "success": 0.94, "baseline_success": 1.0})["success"]  # more than 5 below
    assert not targets({**good, "violation_episodes": 1})["no_violations"]
    assert not targets({**good, "delta_v_ratio": 1.51})["delta_v"]
    assert not targets({**good, "collision_episodes": 1})["no_collisions"]
    c = card(training.POLICIES_DIR / "platoon_tplf_ppo")
    assert c["baseline"].lower() == "dmpc" and c["episodes"] == 50


def test_training_page_lists_every_shipped_policy_with_its_current_numbers():
    from pathlib import Path

    from training.card import shipped_table

    page = (Path(__file__).parents[1] / "docs" / "training.md").read_text()
    assert shipped_table() in page, "docs/training.md's shipped-policies table is stale: paste `python -m training.card`"
