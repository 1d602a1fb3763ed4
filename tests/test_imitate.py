"""DAgger (satenv.training.imitate, the one engine): config grammar and validation, data collection, a tiny run,
resume, the saved configs of earlier releases."""

from __future__ import annotations

import json

import numpy as np
import pytest

import satenv
from satenv import baselines, training
from satenv.training.imitate import DaggerConfig, ImitationConfig, collect_episode, main

SHORT = {"preset": "pereira2022", "randomize": True, "max_steps": 12}


@pytest.fixture(autouse=True)
def _private_baseline_cache(tmp_path_factory, monkeypatch):
    """Baseline results are cached on disk (satenv.training.evaluate.cache_dir): one cache per test session."""
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "satenv_cache"))


def test_config_validation_names_the_field(capsys):
    with pytest.raises(ValueError, match="beta"):
        DaggerConfig(beta=1.5)
    with pytest.raises(ValueError, match="rounds"):
        DaggerConfig(rounds=-1)
    with pytest.raises(ValueError, match="activation"):
        DaggerConfig(activation="sigmoid")
    with pytest.raises(ValueError, match="expert_options"):
        DaggerConfig(expert_options=[1])
    with pytest.raises(ValueError, match="expert: env 'platoon_v0' is not a task"):
        DaggerConfig(env_id="platoon_v0")                  # no task, no system: name the expert
    with pytest.raises(ValueError, match="expert must be one of"):
        DaggerConfig(expert="no_such_controller")
    with pytest.raises(ValueError, match=r"eval_seeds must be validation seeds .*\[5\]"):
        DaggerConfig(task="platoon-pereira2022-random", eval_seeds=(5,))
    with pytest.raises(SystemExit):
        main(["--expert-options", "[1]"])
    assert "--expert-options" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="unknown DaggerConfig field"):
        main(["--config", "tests/../satenv/training/policies/platoon_tplf_ppo/config.json"])
    assert ImitationConfig is DaggerConfig


def test_a_task_brings_its_system_expert_and_defaults_and_flags_override_them():
    from satenv.training.imitate import SYSTEM_DEFAULTS, parse

    cfg, resume = parse(["--task", "cluster-case1-random", "--epochs", "3"])
    assert (cfg.expert, cfg.obs_drop_dims, cfg.epochs, resume) == ("replanning_tube_rdmpc", (18,), 3, False)
    assert cfg.round0_episodes == SYSTEM_DEFAULTS["cluster-li2022"]["round0_episodes"]
    same, _ = parse(["--system", "cluster-li2022", "--run-dir", "x", "--epochs", "3"])
    assert same == cfg.replace(out_dir="x")
    plain, _ = parse(["--env-id", "formation_v0", "--expert", "cgmres"])   # no task: no system defaults
    assert (plain.task, plain.obs_drop_dims, plain.obs_symlog_scale) == (None, (), 0.0)
    named, _ = parse(["--task", "platoon-TPLF-cw", "--expert", "dmpc"])   # a task of no system: name the expert
    assert (named.task, named.expert, named.env_id) == ("platoon-TPLF-cw", "dmpc", "platoon_v0")


def test_a_run_folder_of_the_earlier_imitate_is_not_silently_restarted(tmp_path):
    from satenv.training.imitate import run

    (tmp_path / "eval_history.json").write_text("[]")
    with pytest.raises(ValueError, match="earlier satenv.training.imitate .* --config"):
        run(DaggerConfig(out_dir=str(tmp_path)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval_history.json"]


def test_collect_episode_labels_every_visited_state_with_the_expert():
    env = satenv.make("platoon_v0", **SHORT)
    expert = baselines.make("dmpc", env)
    rng = np.random.default_rng(0)
    rows, stats = collect_episode(env, expert, None, seed=3, beta=1.0, noise=0.0, rng=rng)
    x, y = rows["obs"], rows["act"]
    assert x.shape == (12 * 2, 22) and y.shape == (12 * 2, 3) and rows["state"].shape[0] == 24
    assert np.isfinite(x).all() and list(rows["agent"][:2]) == [0, 1] and list(rows["t"][:4]) == [0, 0, 1, 1]
    assert stats["steps"] == 12 and stats["learner"] is False
    # the expert flies beta = 1: its own rollout gives the same first observation and label
    obs, _ = env.reset(seed=3)
    expert.reset(seed=3)
    first = expert.act(obs)
    np.testing.assert_allclose(y[:2], np.stack([first[a] for a in obs]), rtol=1e-6)


def test_tiny_run_on_an_env_without_a_task_writes_a_loadable_policy_and_resumes(tmp_path):
    """An env id without a task (no system defaults, no paper start) and a baseline expert."""
    out = tmp_path / "run"
    flags = ["--env-id", "platoon_v0", "--env-kwargs", json.dumps(SHORT), "--expert", "dmpc", "--rounds", "2",
             "--round0-episodes", "1", "--episodes-per-round", "1", "--epochs", "2", "--net-arch", "16",
             "--eval-seeds", "700007", "--test-seeds", "900008,900009", "--eval-baselines", "zero",
             "--out-dir", str(out), "--progress", "false", "--lr", "0.001"]
    final = main(flags)
    policy = training.load(final, env=satenv.make("platoon_v0", **SHORT))
    ev = json.loads((final / "eval.json").read_text())
    assert ev["test_seeds"] == [900008, 900009] and set(ev["aggregate"]) == {"learned", "dmpc", "zero"}
    assert ev["vs_DMPC"]["all_seeds"]["seeds"] == 2 and "matched_seeds" in ev["vs_DMPC"]["matched"]
    assert ev["labels"] == 2 * 12 * 2 and ev["rounds"] == 2 and ev["expert"] == "dmpc"
    history = json.loads((out / "history.json").read_text())
    assert [h["round"] for h in history] == [0, 1] and all("paper" not in h for h in history)
    assert (out / "learning_curve.png").is_file() and (out / "labels" / "round_0001.npz").is_file()
    with pytest.raises(SystemExit, match="--resume"):
        main(flags)
    again = main([*flags, "--rounds", "3", "--resume"])  # one more round on top of the saved two
    assert len(json.loads((out / "history.json").read_text())) == 3
    assert json.loads((again / "eval.json").read_text())["labels"] == 3 * 12 * 2
    obs, _ = satenv.make("platoon_v0", **SHORT).reset(seed=0)
    assert set(policy.act(obs)) == set(obs)


def test_every_saved_dagger_config_parses(tmp_path):
    """The shipped policies' DAgger configs (``--config``) and the committed run folders (resumed by
    ``python -m satenv.training.recipes.dagger --run-dir``) load, in either earlier format, without running."""
    import shutil
    from pathlib import Path

    from satenv.training.imitate import parse
    from satenv.training.recipes.dagger import UNTIL_STOPPED

    root = Path(__file__).parents[1] / "satenv" / "training"
    runs = Path(__file__).parents[1] / "studies" / "runs"
    replays = [p for p in sorted(root.glob("policies/*/*config.json"))   # DAgger's (another recipe's: not)
               if ("expert" in json.loads(p.read_text()) or "system" in json.loads(p.read_text()))
               and not json.loads(p.read_text()).get("recipe", "").endswith("training.safe_imitation")]
    assert len(replays) >= 9
    for path in replays:
        saved = json.loads(path.read_text())
        cfg, resume = parse(["--config", str(path)])
        assert cfg.net_arch == tuple(saved["net_arch"]) and not resume, path
        assert cfg.lr == saved.get("lr", saved.get("learning_rate")), path
    for name, task in (("cluster_case1_dagger", "cluster-case1-random"),
                       ("servicing_pereira2022_dagger", "servicing-pereira2022-random")):
        run = tmp_path / name
        shutil.copytree(runs / name / "", run, ignore=shutil.ignore_patterns("labels", "rounds"))
        saved = json.loads((run / "config.json").read_text())
        cfg, resume = parse(["--run-dir", str(run)], auto_resume=True, defaults={"--rounds": str(UNTIL_STOPPED)})
        assert resume and cfg.task == task and cfg.rounds == saved["rounds"] and cfg.learner_shield
        assert cfg.eval_seeds == tuple(saved["val_seeds"]) and cfg.terminal == saved["terminal"]
        assert (cfg.round0_episodes, cfg.episodes_per_round) == (saved["round0_episodes"], saved["episodes_per_round"])
    fresh, resume = parse(["--system", "platoon-pereira2022", "--run-dir", str(tmp_path / "new")], auto_resume=True,
                          defaults={"--rounds": str(UNTIL_STOPPED)})
    assert not resume and fresh.rounds == UNTIL_STOPPED and fresh.expert == "joint_platoon_mpc"


def test_policy_cards_read_every_shipped_folder_and_judge_the_targets():
    from satenv.training.card import card, shipped_table, targets

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

    from satenv.training.card import shipped_table

    page = (Path(__file__).parents[1] / "docs" / "training.md").read_text()
    assert shipped_table() in page, "docs/training.md's shipped-policies table is stale: paste `python -m satenv.training.card`"
