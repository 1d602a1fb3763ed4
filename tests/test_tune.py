"""satenv ppo-tune: candidates trained on a train seed, chosen on validation seeds by its rule."""

import json

import pytest

from satenv.training.rl import tune

TASK = "platoon-tplf30-rung1-near"
TINY = 64 * 4 * 32   # one iteration of the platoon's 4 agents


def test_choose_follows_the_rule():
    scores = {"a": {"success_rate": 0.5, "collision_episodes": 0, "final_error_m": 1.0},
              "b": {"success_rate": 0.8, "collision_episodes": 3, "final_error_m": 9.0},
              "c": {"success_rate": 0.8, "collision_episodes": 1, "final_error_m": 5.0},
              "d": {"success_rate": 0.8, "collision_episodes": 1, "final_error_m": 2.0}}
    assert tune.choose(scores) == "d"
    del scores["d"]
    assert tune.choose(scores) == "c"


@pytest.mark.parametrize("config", [{"lrr": 0.1}, {"budget": 10}, {"seed": 3}])
def test_a_candidate_sets_only_tunable_fields(config):
    with pytest.raises(ValueError, match="not tunable"):
        tune.check_candidate("x", config)


def test_tune_writes_the_record_and_resumes(tmp_path, capsys):
    out = tmp_path / "tuned.json"
    argv = ["--task", TASK, "--budget", str(TINY), "--validation-seeds", "2", "--candidate", 'lr={"lr": 0.001}',
            "--work-dir", str(tmp_path / "work"), "--out", str(out), "--no-progress"]
    assert tune.main(argv) == 0
    record = json.loads(out.read_text())
    assert set(record["candidates"]) == {tune.DEFAULT, "lr"} and record["chosen"] in record["candidates"]
    assert record["config"] == record["candidates"][record["chosen"]]["config"]
    assert record["chosen_on"] == {"split": "validation", "seeds": "700000-700001", "training_seed": 0,
                                   "budget_agent_steps": TINY, "rule": tune.RULE}
    final = tmp_path / "work" / "lr" / "final" / "eval.json"
    stamp = final.stat().st_mtime_ns
    assert tune.main(argv) == 0                      # finished candidates are read back, not retrained
    assert final.stat().st_mtime_ns == stamp and json.loads(out.read_text()) == record


def test_bad_input_is_a_clear_error(tmp_path, capsys):
    base = ["--task", TASK, "--work-dir", str(tmp_path / "w"), "--out", str(tmp_path / "t.json")]
    assert tune.main([*base, "--candidate", 'x={"nope": 1}']) == 2
    assert "not tunable" in capsys.readouterr().err
    assert tune.main([*base, "--candidate", 'x={"lr": NaN}']) == 2        # refused before anything trains
    assert "lr must be" in capsys.readouterr().err and not (tmp_path / "w").exists()
    with pytest.raises(SystemExit):
        tune.main([*base, "--candidate", "x=1"])
    assert "expected a JSON object" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        tune.main([*base, "--candidate", 'A_default={"lr": 0.1}'])
    assert tune.main(["--task", "no-such-task", "--out", str(tmp_path / "t.json")]) == 2
    assert "unknown task" in capsys.readouterr().err


def test_a_work_folder_of_another_configuration_is_refused(tmp_path, capsys):
    base = ["--task", TASK, "--budget", str(TINY), "--validation-seeds", "1", "--work-dir", str(tmp_path / "w"),
            "--out", str(tmp_path / "t.json"), "--no-progress"]
    assert tune.main([*base, "--candidate", 'x={"lr": 0.001}']) == 0
    assert tune.main([*base, "--candidate", 'x={"lr": 0.002}']) == 2
    assert "another configuration (['lr'])" in capsys.readouterr().err
