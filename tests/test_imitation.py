"""DAgger in satenv.training.imitation (the one engine): config grammar and validation, data
collection, a tiny run, resume, shipping, hostile run folders, the saved configs of earlier releases."""

from __future__ import annotations

import json

import numpy as np
import pytest

import satenv
from satenv import baselines, training
from satenv.training.imitation import ImitationConfig, collect_episode
from satenv.training.imitation.cli import main, parse

DaggerConfig = ImitationConfig

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
    assert main(["--expert-options", "[1]"]) == 2
    assert "--expert-options" in capsys.readouterr().err
    assert main(["--config", "tests/../satenv/training/policies/platoon_tplf_ppo/config.json"]) == 2
    assert "unknown ImitationConfig field" in capsys.readouterr().err


def test_a_task_brings_its_system_expert_and_defaults_and_flags_override_them():
    from satenv import tasks

    _, cfg, resume = parse(["--task", "cluster-case1-random", "--epochs", "3"])
    assert (cfg.expert, cfg.obs_drop_dims, cfg.epochs, resume) == ("replanning_tube_rdmpc", (18,), 3, False)
    assert cfg.round0_episodes == tasks.system("cluster-li2022").imitation["round0_episodes"]
    assert cfg.eval_seeds == tasks.get("cluster-case1-random").seeds("validation", 3)   # the band, not literals
    _, same, _ = parse(["--system", "cluster-li2022", "--run-dir", "x", "--epochs", "3"])
    assert same == cfg.replace(out_dir="x")
    _, plain, _ = parse(["--env-id", "formation_v0", "--expert", "cgmres"])   # no task: no system defaults
    assert (plain.task, plain.obs_drop_dims, plain.obs_symlog_scale) == (None, (), 0.0)
    _, named, _ = parse(["--task", "platoon-TPLF-cw", "--expert", "dmpc"])   # a task of no system: name the expert
    assert (named.task, named.expert, named.env_id) == ("platoon-TPLF-cw", "dmpc", "platoon_v0")


def test_a_run_folder_of_the_earlier_imitate_is_not_silently_restarted(tmp_path):
    from satenv.training.imitation import run

    (tmp_path / "eval_history.json").write_text("[]")
    with pytest.raises(ValueError, match="earlier DAgger .* --config"):
        run(DaggerConfig(out_dir=str(tmp_path)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval_history.json"]


def test_collect_episode_labels_every_visited_state_with_the_expert():
    env = satenv.make("platoon_v0", **SHORT)
    expert = baselines.make("dmpc", env)
    rng = np.random.default_rng(0)
    rows, stats = collect_episode(env, expert, None, 3, beta=1.0, noise=0.0, rng=rng)
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
    assert main(flags) == 0
    final = out / "final"
    policy = training.load(final, env=satenv.make("platoon_v0", **SHORT))
    ev = json.loads((final / "eval.json").read_text())
    assert ev["test_seeds"] == [900008, 900009] and set(ev["aggregate"]) == {"learned", "dmpc", "zero"}
    assert ev["vs_DMPC"]["all_seeds"]["seeds"] == 2 and "matched_seeds" in ev["vs_DMPC"]["matched"]
    assert ev["labels"] == 2 * 12 * 2 and ev["rounds"] == 2 and ev["expert"] == "dmpc"
    history = json.loads((out / "history.json").read_text())
    assert [h["round"] for h in history] == [0, 1] and all("paper" not in h for h in history)
    assert (out / "learning_curve.png").is_file() and (out / "labels" / "round_0001.npz").is_file()
    assert main(flags) == 0                                # the same command: nothing left to do
    assert len(json.loads((out / "history.json").read_text())) == 2
    assert main([*flags, "--rounds", "3", "--resume"]) == 0  # one more round on top of the saved two
    assert len(json.loads((out / "history.json").read_text())) == 3
    assert json.loads((final / "eval.json").read_text())["labels"] == 3 * 12 * 2
    assert main(["--out-dir", str(out), "--ship", str(tmp_path / "shipped")]) == 0   # chosen on validation
    shipped = training.load(tmp_path / "shipped", env=satenv.make("platoon_v0", **SHORT))
    assert json.loads((tmp_path / "shipped" / "config.json").read_text())["shipped_round"] in (0, 1, 2)
    assert set(shipped.act(satenv.make("platoon_v0", **SHORT).reset(seed=0)[0]))
    obs, _ = satenv.make("platoon_v0", **SHORT).reset(seed=0)
    assert set(policy.act(obs)) == set(obs)


def test_every_saved_dagger_config_parses(tmp_path):
    """The shipped policies' imitation configs (``--config``: DAgger's and the safe variants') and the
    committed run folders (resumed by ``satenv imitate --run-dir``) load, in every earlier format,
    without running."""
    import shutil
    from pathlib import Path

    root = Path(__file__).parents[1] / "satenv" / "training"
    runs = Path(__file__).parents[1] / "studies" / "runs"
    replays = [p for p in sorted(root.glob("policies/*/*config.json"))
               if {"expert", "system", "safe_dagger"} & set(json.loads(p.read_text()))]
    assert len(replays) >= 13
    for path in replays:
        saved = json.loads(path.read_text())
        _, cfg, resume = parse(["--config", str(path), "--out-dir", str(tmp_path / "none")])
        assert not resume, path
        if "safe_dagger" in saved:                     # a safe variant: its own fields, from its warm start
            safe = saved["safe_dagger"]
            assert cfg.warm_start.endswith(safe["warm_start"]) and cfg.lr == safe["learning_rate"], path
            assert (root.parents[1] / cfg.warm_start / "weights.safetensors").is_file(), path   # the moved folder
            assert (cfg.fly, cfg.label) == (safe.get("fly", "filtered"), safe["label"]) and cfg.safe, path
            assert len(cfg.eval_seeds) == safe["val_seeds"] and cfg.rounds == safe["rounds"], path
            assert cfg.round0_episodes == cfg.episodes_per_round == safe["episodes_per_round"], path
            assert cfg.label_filter == safe.get("label_filter", {}), path
        else:
            assert cfg.net_arch == tuple(saved["net_arch"]) and not cfg.safe, path
            assert cfg.lr == saved.get("lr", saved.get("learning_rate")), path
    for path in sorted(runs.glob("*/config.json")):      # every committed run replays (--config)
        _, cfg, _ = parse(["--config", str(path), "--out-dir", str(tmp_path / "none")])
        assert cfg.rounds >= 0, path
    for name, task in (("cluster_case1_dagger", "cluster-case1-random"),
                       ("servicing_pereira2022_dagger", "servicing-pereira2022-random")):
        run = tmp_path / name
        shutil.copytree(runs / name / "", run, ignore=shutil.ignore_patterns("labels", "rounds"))
        saved = json.loads((run / "config.json").read_text())
        _, cfg, resume = parse(["--run-dir", str(run)])
        assert resume and cfg.task == task and cfg.rounds == saved["rounds"] and cfg.learner_shield
        assert cfg.eval_seeds == tuple(saved["val_seeds"]) and cfg.terminal == saved["terminal"]
        assert (cfg.round0_episodes, cfg.episodes_per_round) == (saved["round0_episodes"], saved["episodes_per_round"])
    _, fresh, resume = parse(["--system", "platoon-pereira2022", "--run-dir", str(tmp_path / "new")])
    assert not resume and fresh.expert == "joint_platoon_mpc" and fresh.expert_options == {"coupling": "sequential"}


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
    assert shipped_table() in page, ("docs/training.md's shipped-policies table is stale: "
                                     "paste `python -m satenv.training.card`")


def _npz_declaring(path, shape):
    """A label file whose one array's header declares ``shape`` of float64 but holds 8 bytes."""
    import io
    import zipfile

    from numpy.lib import format as npy

    buf = io.BytesIO()
    npy.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("obs.npy", buf.getvalue() + b"\0" * 8)


def test_hostile_run_folders_are_refused_before_anything_is_read(tmp_path, capsys):
    """Links (the folder, a round, a file), files past their cap, object or oversized label arrays,
    malformed history or config: one clear error naming the file, no traceback, nothing read."""
    import os

    from satenv.training.imitation.folder import MAX_HISTORY_BYTES, read_history, read_labels
    from satenv.training.imitation.setup import warm_start_filter
    from satenv.training.imitation.ship import ship
    from satenv.training.runfolder import RunFolderError

    real = tmp_path / "real"
    (real / "rounds" / "0000").mkdir(parents=True)
    os.symlink(real, tmp_path / "link")
    with pytest.raises(RunFolderError, match="symbolic link"):
        read_history(tmp_path / "link")
    os.symlink("/dev/zero", real / "history.json")
    with pytest.raises(RunFolderError, match="history.json: is a symbolic link"):
        read_history(real)
    assert main(["--out-dir", str(real), "--ship", str(tmp_path / "out")]) == 2
    assert "symbolic link" in capsys.readouterr().err and not (tmp_path / "out").exists()
    (real / "history.json").unlink()
    with open(real / "history.json", "wb") as fh:             # sparse: huge on stat, nothing on disk
        fh.truncate(MAX_HISTORY_BYTES + 1)
    with pytest.raises(RunFolderError, match="more than the cap"):
        read_history(real)
    (real / "history.json").write_text('[{"round": 0}, {"rou')
    with pytest.raises(RunFolderError, match="history.json: not valid JSON"):
        read_history(real)
    (real / "history.json").write_text('[{"round": 0}]')
    src = training.POLICIES_DIR / "platoon_pereira2022_dagger"
    for name in os.listdir(src):
        (real / "rounds" / "0000" / name).write_bytes((src / name).read_bytes())
    (real / "rounds" / "0000" / "env.json").unlink()
    secret = tmp_path / "secret.json"
    secret.write_text(json.dumps({"outside": True}))
    os.symlink(secret, real / "rounds" / "0000" / "env.json")
    with pytest.raises(ValueError, match="env.json: is a symbolic link"):
        ship(real, 0, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    (real / "rounds" / "0001").symlink_to(real / "rounds" / "0000")
    with pytest.raises(RunFolderError, match="round folder is a symbolic link"):
        ship(real, 1, tmp_path / "out")
    with pytest.raises(RunFolderError, match="symbolic link"):
        warm_start_filter(real / "rounds" / "0000")            # a warm start's env.json: checked first
    labels = tmp_path / "labels"
    labels.mkdir()
    np.savez(labels / "round_0000.npz", obs=np.array([{"a": 1}], dtype=object))
    with pytest.raises(RunFolderError, match="dtype object"):
        read_labels(labels / "round_0000.npz")
    _npz_declaring(labels / "round_0001.npz", (2**27,))       # 1 GiB declared in an 8-byte entry
    with pytest.raises(RunFolderError, match="declares"):
        read_labels(labels / "round_0001.npz")
    bad = tmp_path / "bad.json"
    for text in ("{not json", "[1, 2]", json.dumps({"rounds": "many"}), json.dumps({"eval_seeds": None}),
                 json.dumps({"net_arch": 5}), json.dumps({"prior_labels": 5}),
                 json.dumps({"terminal": {"radius": "x"}}),
                 json.dumps({"safe_dagger": {"system": 5}})):
        bad.write_text(text)
        assert main(["--config", str(bad), "--out-dir", str(tmp_path / "r")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("satenv imitate: error:") and "Traceback" not in err and err.count("\n") == 1
        assert "object is not" not in err and not (tmp_path / "r").exists(), err      # named, refused up front
        assert f"error: --config {bad}: " in err, err


@pytest.mark.parametrize("where", ["missing", "a file"])
def test_a_warm_start_that_is_no_folder_is_refused_before_anything_is_written(where, tmp_path, capsys):
    warm = tmp_path / "warm"
    if where == "a file":
        warm.write_text("{}")
    assert main(["--system", "platoon-pereira2022", "--warm-start", str(warm), "--fly", "filtered", "--label",
                 "filtered", "--rounds", "1", "--out-dir", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "warm_start policy folder is not a folder" in err if where == "a file" else "no such policy folder" in err
    assert not (tmp_path / "r" / "config.json").exists() and not (tmp_path / "r" / "labels").exists(), err


@pytest.mark.parametrize("flag,value,expected", [("--seed", "null", "--seed 'null': expected an int"),
                                                  ("--epochs", "-1", "--epochs must be an int >= 1, got -1"),
                                                  ("--batch-size", "[]", "--batch-size '[]': expected an int"),
                                                  ("--expert-options", "{x", "--expert-options '{x': expected a JSON"),
                                                  ("--beta", "x", "--beta 'x': expected a number"),
                                                  ("--squash", "maybe", "--squash 'maybe': expected true or false"),
                                                  ("--fly", "nope", "--fly: invalid choice: 'nope'"),
                                                  ("--validate-seeds", "0", "--validate-seeds: expected an int >= 1"),
                                                  ("--validate-seeds", "-1", "--validate-seeds: expected an int >= 1"),
                                                  ("--env-kwargs", '{"nope": 1}',
                                                   "--env-kwargs: platoon_v0: unknown keyword argument(s) ['nope']")])
def test_a_bad_flag_value_is_one_clear_error(flag, value, expected, tmp_path, capsys):
    assert main(["--task", "platoon-pereira2022-random", "--out-dir", str(tmp_path / "r"), flag, value]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1 and not (tmp_path / "r").exists()


@pytest.mark.slow  # ~15 s: two expert QP builds, three fits and learning-curve plots
def test_dagger_run_saves_every_round_and_resumes(tmp_path):
    from dataclasses import replace

    from satenv.training.imitation import run, system_config

    cfg = system_config("platoon-pereira2022", env_kwargs={"max_steps": 6}, round0_episodes=2,
                        episodes_per_round=1, rounds=2, eval_seeds=(700_000,), net_arch=(16,), epochs=1,
                        final_eval=False)
    run(cfg, tmp_path)
    hist = json.loads((tmp_path / "history.json").read_text())
    assert [h["round"] for h in hist] == [0, 1] and hist[-1]["labels"] == (2 + 1) * 6 * 2
    assert (tmp_path / "rounds" / "0001" / "manifest.json").is_file()
    run(replace(cfg, rounds=3), tmp_path)            # resume: one more round, labels kept
    hist = json.loads((tmp_path / "history.json").read_text())
    assert [h["round"] for h in hist] == [0, 1, 2] and hist[-1]["labels"] == 4 * 6 * 2
    assert len(list((tmp_path / "labels").glob("round_*.npz"))) == 3
    assert all(h["paper"]["episodes"] == 1 for h in hist)     # the system's paper start, evaluated every round


def test_every_imitate_command_in_the_docs_parses():
    """The ``satenv imitate`` examples of README.md, docs/ and the policies' and studies' READMEs use
    valid flags and values (parsed, nothing run)."""
    import re
    import shlex
    from pathlib import Path

    root = Path(__file__).parents[1]
    pages = [root / "README.md", *root.glob("docs/**/*.md"), *root.glob("satenv/training/policies/*/README.md"),
             *root.glob("studies/runs/*/README.md")]
    found = 0
    for page in pages:
        text = page.read_text().replace("\\\n", " ")
        for m in re.finditer(r"satenv imitate\b([^\n#`|]*)", text):
            argv = shlex.split(m.group(1))
            if not argv or "..." in argv or argv == ["--help"] or any("$" in a for a in argv):   # a shell variable
                continue
            parse(argv)
            found += 1
    assert found >= 6


def test_every_flag_refuses_bad_values_naming_the_flag():
    """Values of the wrong kind or range for every config flag: each is refused with the flag (or
    its field) named, or is a value the field takes (a path, a name, a count)."""
    import dataclasses

    from satenv.cliargs import flag_name

    takes_any_text = {"--out-dir", "--prior-labels", "--warm-start"}      # paths, checked when the run reads them
    for f in dataclasses.fields(ImitationConfig):
        flag = flag_name(ImitationConfig, f)
        for token in ("null", "[]", "{x", "nan", "-1", "1e999", "true"):
            try:
                parse(["--task", "platoon-pereira2022-random", "--out-dir", "unused-run", flag, token])
            except ValueError as err:
                assert flag in str(err) or f.name in str(err), (flag, token, str(err))
                continue
            flags = {f.name: f for f in dataclasses.fields(ImitationConfig)}
            valid = (token == "true" and isinstance(flags[f.name].default, bool)
                     or (flag, token) == ("--clip-obs", "1e999"))             # no clip
            assert flag in takes_any_text or valid, (flag, token)


def test_a_shipped_safe_variant_config_replays_a_round(tmp_path, capsys):
    """The earlier safe variant's config (the teacher, hand-over flights, a tighter label filter, its
    warm start at the earlier layout's path) replays on the one engine: one short round."""
    config = training.POLICIES_DIR / "servicing_pereira2022_tight_teacher" / "config.json"
    out = tmp_path / "run"
    assert main(["--config", str(config), "--out-dir", str(out), "--prior-labels", "", "--rounds", "1",
                 "--round0-episodes", "1", "--env-kwargs", '{"max_steps": 6}', "--eval-seeds", "700000",
                 "--shield-seeds", "1", "--epochs", "1", "--progress", "false"]) == 0
    saved = json.loads((out / "config.json").read_text())
    assert (saved["fly"], saved["label"], saved["label_filter"]) == (
        "handover", "teacher", {"margin": 0.02, "velocity_margin": 0.2, "gamma": 0.5})
    history = json.loads((out / "history.json").read_text())
    assert history[0]["labels"] == 6 * 2
    assert set(history[0]["loss"]) == {"imitation", "intervention", "barrier", "prior"}
    shipped = json.loads((out / "rounds" / "0000" / "env.json").read_text())
    assert "safety_filter" in shipped                        # the warm start's env.json, its filter named
    capsys.readouterr()


def test_a_warm_start_that_is_no_folder_is_refused_on_the_command_line(tmp_path, capsys):
    """``--warm-start`` naming a missing path or a file is one error naming the flag, before any folder is made."""
    from satenv.training.imitation.cli import main

    (tmp_path / "a_file").write_text("x")
    for bad in (tmp_path / "missing", tmp_path / "a_file"):
        assert main(["--warm-start", str(bad), "--out-dir", str(tmp_path / "run")]) == 2
        assert "--warm-start" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
