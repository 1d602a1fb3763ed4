"""satenv.bench.safety_alone: the network alone and behind the filter, resumable, JSON + PNG."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("torch")


def test_two_episodes_write_json_png_and_resume_from_the_cache(tmp_path):
    from satenv.bench import safety_alone

    folder = "satenv/training/policies/platoon_tplf_safe_distill"
    args = ["--entry", f"platoon-pereira2023={folder}", "--seeds", "2", "--controller-seeds", "1",
            "--out", str(tmp_path)]
    safety_alone.main(args)
    res = json.loads((tmp_path / "safety_alone.json").read_text())
    assert (tmp_path / "safety_alone.png").stat().st_size > 0
    (block,) = res["entries"]
    assert block["seeds"] == [900_000, 900_001] and block["controller_seeds"] == [900_000, 900_000]
    alone, shielded = block["network alone"], block["network + filter"]
    assert alone["aggregate"]["episodes"] == shielded["aggregate"]["episodes"] == 2
    assert "interventions_per_agent_step" in shielded["aggregate"]
    assert "interventions_per_agent_step" not in alone["aggregate"]
    assert set(alone["targets"]) >= {"success", "no_collisions", "no_violations", "rmse", "delta_v"}
    cache = next(tmp_path.glob("cache/*network_alone.jsonl"))
    first = cache.read_text()
    cache.write_text(first + '{"seed": 9')          # a line cut by an interrupted run
    safety_alone.main(args)                          # reuses the cached episodes, skips the cut line
    assert json.loads((tmp_path / "safety_alone.json").read_text())["entries"][0]["network alone"]["episodes"] == \
        block["network alone"]["episodes"]
    assert all(e["wall_s"] > 0 for e in alone["episodes"]) and alone["wall_s"] > 0   # times survive a resume


def test_a_run_is_written_into_a_policy_folder_that_the_card_reads(tmp_path):
    """--folders-from: each entry (no episode records) into its folder; the card reads it both ways."""
    import shutil

    from satenv import training
    from satenv.bench import safety_alone
    from satenv.training.card import BOTH_WAYS_FILE, card

    folder = tmp_path / "policy"
    shutil.copytree(training.POLICIES_DIR / "platoon_tplf_ppo_shield", folder)
    (folder / BOTH_WAYS_FILE).unlink(missing_ok=True)
    out = tmp_path / "run"
    safety_alone.main(["--entry", f"platoon-pereira2023={folder}", "--seeds", "2", "--controller-seeds", "1",
                       "--out", str(out)])
    assert not (folder / BOTH_WAYS_FILE).exists()             # only when asked
    safety_alone.main(["--folders-from", str(out / "safety_alone.json")])
    saved = json.loads((folder / BOTH_WAYS_FILE).read_text())
    assert saved["test_seeds"] == [900_000, 900_001] and saved["source"] == str(out / "safety_alone.json")
    assert "episodes" not in saved["network + filter"] and saved["network + filter"]["test_seeds"] == [900_000, 900_001]
    c = card(folder)
    assert c["evaluation"] == BOTH_WAYS_FILE and c["episodes"] == c["network_alone"]["episodes"] == 2
    assert c["interventions_per_agent_step"] is not None and c["baseline_episodes"] == 1
    stamp = (folder / BOTH_WAYS_FILE).stat().st_mtime_ns
    result = out / "safety_alone.json"
    assert safety_alone.write_folders(json.loads(result.read_text()), result) == []
    assert (folder / BOTH_WAYS_FILE).stat().st_mtime_ns == stamp   # the same evaluation: left as it is


def _error(capsys, argv) -> str:
    """The one ``error:`` line of a rejected command line (exit status 2)."""
    from satenv.bench import safety_alone

    with pytest.raises(SystemExit) as exit_:
        safety_alone.main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    return err.strip().splitlines()[-1]


def test_a_bad_command_line_is_one_error_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    folder = "satenv/training/policies/platoon_tplf_safe_distill"
    entry = ["--entry", f"platoon-pereira2023={folder}"]
    out = tmp_path / "out"
    for argv, expected in [
            (["--entry", "platoon-pereira2023", "--out", str(out)], "system=policy-folder"),
            (["--entry", "platoon-pereira2023=x@many", "--out", str(out)], "system=policy-folder"),
            (["--entry", "platoon-pereira2023=x@10:some", "--out", str(out)], "system=policy-folder"),
            (["--entry", f"nope={folder}", "--out", str(out)], "system 'nope' is not one of"),
            (["--entry", f"platoon-pereira2023={tmp_path}", "--out", str(out)], "is not a policy folder"),
            (["--out", str(out)], "--entry"),
            (["--folders-from", str(tmp_path / "missing.json")], "--folders-from"),
            ([*entry, "--out", ""], "argument --out: expected a folder path, got ''"),
            ([*entry, "--controller-seeds", "-1", "--out", str(out)],
             "argument --controller-seeds: expected an int >= 0, got '-1'"),
            ([*entry, "--seeds", "0", "--out", str(out)], "argument --seeds: expected an int >= 1, got '0'")]:
        line = _error(capsys, argv)
        assert line.startswith("satenv safety-alone: error:") and expected in line, (argv, line)
    (tmp_path / "a_file").write_text("x")
    line = _error(capsys, [*entry, "--out", str(tmp_path / "a_file")])
    assert "argument --out:" in line and "exists and is not a folder" in line
    monkeypatch.chdir(tmp_path)
    _error(capsys, [*entry, "--out", ""])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]       # nothing written


def test_perturbation_entries_puts_the_first_n_entries_under_every_perturbation(tmp_path, capsys):
    from satenv import tasks
    from satenv.bench import safety_alone

    folder = "satenv/training/policies/platoon_tplf_safe_distill"
    base = ["--seeds", "1", "--controller-seeds", "0", "--perturbation-seeds", "1", "--out", str(tmp_path)]
    entries = ["--entry", f"platoon-pereira2023={folder}", "--entry", f"platoon-pereira2023={folder}@1:0"]
    safety_alone.main(entries + base + ["--perturbation-entries", "2"])
    first, second = json.loads((tmp_path / "safety_alone.json").read_text())["entries"]
    names = set(tasks.get(first["task"]).perturbations)
    assert set(first["perturbations"]) - {"seeds"} == set(second["perturbations"]) - {"seeds"} == names
    safety_alone.main(entries + base)                       # the default: the first entry only
    first, second = json.loads((tmp_path / "safety_alone.json").read_text())["entries"]
    assert set(first["perturbations"]) - {"seeds"} == names and "perturbations" not in second
    for n in ("0", "3"):
        with pytest.raises(SystemExit):
            safety_alone.main(entries + base + ["--perturbation-entries", n])
        assert "--perturbation-entries" in capsys.readouterr().err


def test_both_ways_is_built_with_load_only_and_the_board_uses_it():
    """satenv.training.both_ways: the network alone and as shipped; the board's trained: entries
    name it and keep the fingerprints of logs written when they called load directly."""
    from satenv import tasks, training
    from satenv.bench.scoreboard.registry import discover_trained_policies
    from satenv.bench.scoreboard.specs import LEARNED_TARGET, _content_hash, _fingerprint
    from satenv.safety import Shield
    from satenv.training import both_ways

    env = tasks.training_task("platoon-pereira2023").make_env()
    filtered = training.POLICIES_DIR / "platoon_tplf_ppo_shield"
    assert both_ways.ships_filtered(filtered)
    assert isinstance(both_ways.policy(filtered, env), Shield)
    assert not isinstance(both_ways.policy(filtered, env, both_ways.NETWORK_ALONE), Shield)
    with pytest.raises(ValueError, match="variant"):
        both_ways.policy(filtered, env, "shielded")
    plain = training.POLICIES_DIR / "platoon_tplf_ppo"
    assert not isinstance(both_ways.policy(plain, env), Shield)                # shipped without the filter
    assert isinstance(both_ways.policy(plain, env, filter_defaults=True), Shield)   # behind it at its defaults
    assert not isinstance(both_ways.policy(plain, env, both_ways.NETWORK_ALONE, filter_defaults=True), Shield)
    for bad in ("yes", 1, None):
        with pytest.raises(TypeError, match="filter_defaults"):
            both_ways.policy(plain, env, filter_defaults=bad)
    eps = both_ways.evaluate(plain, env, [900_000, 900_001], shipped_seeds=1)
    assert eps[both_ways.AS_SHIPPED] == eps[both_ways.NETWORK_ALONE][:1]        # shipped without it: run once
    specs = discover_trained_policies()
    for name, variant, kwargs in (("trained:platoon_tplf_ppo_shield", both_ways.AS_SHIPPED, {}),
                                  ("trained:platoon_tplf_ppo_shield:network", both_ways.NETWORK_ALONE,
                                   {"shielded": False})):
        spec = specs[name]
        assert (spec.target, dict(spec.kwargs)) == (LEARNED_TARGET, {"variant": variant})
        assert spec.fingerprint() == _fingerprint({"targets": ["satenv.training:load"], "kwargs": kwargs,
                                                   "checkpoint": _content_hash(filtered)})
        assert isinstance(spec.make(env), Shield) == (variant == both_ways.AS_SHIPPED)
