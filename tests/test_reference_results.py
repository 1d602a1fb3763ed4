"""The reference results: the page is the render of results.json, the results file is complete
where it claims to be, the runner's log is resumable, the IQM and its stratified bootstrap are the
estimators they say (hand-computed examples), the grid covers the ladders."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from satenv import scoring, tasks
from satenv.bench.learning import grid as G
from satenv.bench.learning import render, results, runner, trainers

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "studies" / "reference_results" / "results.json"
RUNG = "platoon-tplf30-rung1-near"


def test_page_is_the_render_of_results_json():
    from satenv.bench.learning.datasets import MANIFEST

    data = json.loads(RESULTS.read_text())
    assert render.PAGE.read_text() == render.render_page(data, render.read_manifest(MANIFEST)), \
        "docs/reference_results.md is stale: satenv results render"


def test_every_published_record_has_its_curve_and_test_block():
    data = json.loads(RESULTS.read_text())
    for rec in data["records"]:
        assert len(rec["curve"]) >= G.CHECKPOINTS >= 5
        assert all(len(p) == 4 for p in rec["curve"])
        steps = [p[0] for p in rec["curve"]]
        assert steps == sorted(steps) and steps[-1] == rec["agent_steps"]
        assert rec["budget_agent_steps"] > 0 and rec["wall_s"] >= 0
        for key in ("success_rate", "collision_episodes", "violation_episodes", "episodes", "failure_modes"):
            assert key in rec["test"], (rec["task"], rec["algorithm"], key)
        assert rec["test"]["episodes"] == G.FINAL_TEST_SEEDS >= 20
        assert rec["test_seeds"] == list(G.test_seeds(rec["task"]))
        assert all(s in tasks.get(rec["task"]).seeds("test") for s in rec["test_seeds"])
        failed = rec["test"]["episodes"] - round(rec["test"]["success_rate"] * rec["test"]["episodes"])
        assert sum(rec["test"]["failure_modes"].values()) == failed
        assert rec["task"] == tasks.ladder(rec["system"])[rec["rung"] - 1]
        if rec["filter"]:
            assert "interventions_per_agent_step" in rec["test"]
        assert rec["command"].startswith("satenv results run ")


def test_iqm_by_hand():
    assert render.iqm([0.0, 1.0, 2.0, 3.0]) == pytest.approx(1.5)              # (1 + 2) / 2
    assert render.iqm([1.0, 0.0, 0.5, 0.2, 0.9]) == pytest.approx(1.6 / 3)    # int(5/4) = 1 cut each end
    assert render.iqm([0.0, 0.0, 1.0]) == pytest.approx(1 / 3)                # int(3/4) = 0: the mean


def test_bootstrap_interval_by_hand():
    # three runs scoring 0, 0, 1: a resample is all zeros with probability 8/27 > 2.5 % and all ones
    # with 1/27 > 2.5 %, so the 95 % percentile interval is [0, 1] around the IQM 1/3
    mid, lo, hi = render.iqm_ci([0.0, 0.0, 1.0])
    assert (mid, lo, hi) == (pytest.approx(1 / 3), 0.0, 1.0)
    # ten runs, nine 1s and a 0: P(no 0 drawn) = 0.9^10 = 0.35, so the upper end is 1; the IQM of a
    # resample drops below 0.9 only with >= 2 zeros among 10 draws (P = 0.26 > 2.5 %)
    mid, lo, hi = render.iqm_ci([1.0] * 9 + [0.0])
    assert mid == pytest.approx(1.0) and hi == 1.0 and lo < 1.0
    flat = render.iqm_ci(np.full(5, 0.4))
    assert flat == pytest.approx((0.4, 0.4, 0.4))


def test_late_drops_count_runs_that_lost_half_the_test_seeds_by_hand():
    def rec(published, last):
        return {"algorithm": "ppo", "test": {"success_rate": published}, "last_test": {"success_rate": last}}

    results = {"records": [rec(1.0, 0.0), rec(1.0, 0.5), rec(0.9, 0.45), rec(0.6, 0.6), rec(0.0, 0.0)]}
    said = render._late_drops(results)
    assert "of the 5 learning runs" in said
    assert "3 ended below" in said and "2 at least 0.5 below" in said   # 1.0 -> 0.0 and 1.0 -> 0.5


def test_bootstrap_is_stratified_by_task():
    """Task A scores 0 on both runs, task B 1: a stratified resample always holds two 0s and two 1s
    (IQM 0.5), a pooled one would not."""
    mid, lo, hi = render.iqm_ci(np.array([[0.0, 1.0], [0.0, 1.0]]))
    assert (mid, lo, hi) == pytest.approx((0.5, 0.5, 0.5))


@pytest.mark.parametrize("rec, mode", [
    ({"success": True, "collisions": 2}, None), ({"success": False, "collisions": 1, "violations": 3}, "collision"),
    ({"success": False, "collisions": 0, "violations": 1, "terminated": True}, "violation"),
    ({"success": False, "collisions": 0, "violations": 0, "terminated": True}, "left_region"),
    ({"success": False, "collisions": 0, "violations": 0, "terminated": False}, "timeout")])
def test_failure_mode(rec, mode):
    assert scoring.failure_mode(rec) == mode


@pytest.fixture
def zero_trainer(monkeypatch):
    """Every trainer (and the controller) replaced by the zero policy at every checkpoint, on a few
    test seeds (fast)."""
    calls = []

    def fake(run, checkpoint, finish):
        from satenv import baselines

        def zero(env, k):
            calls.append((run.label(), k))
            return baselines.make("zero", env)

        calls.append(run.label())
        for k, steps in enumerate(run.checkpoints):
            checkpoint(k, steps, 0.1 * (k + 1), lambda env, k=k: zero(env, k))
        finish()

    monkeypatch.setattr(trainers, "train", fake)
    monkeypatch.setattr(G, "FINAL_TEST_SEEDS", 3)
    monkeypatch.setattr(G, "CURVE_TEST_SEEDS", 2)
    monkeypatch.setattr(G, "VALIDATION_SEEDS", 2)
    return calls


def test_runner_logs_every_checkpoint_and_resumes(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    run = G.Run("platoon-pereira2023", "ppo", False, 0, str(log), budget_override=5000, rung=RUNG)
    out = runner.run_one(run)
    assert [r["checkpoint"] for r in out["records"]] == list(range(G.CHECKPOINTS + 1))
    assert [len(r["episodes"]) for r in out["records"]] == [2] * (G.CHECKPOINTS - 1) + [3, 3]
    assert {r["task"] for r in out["records"]} == {RUNG} and {r["rung"] for r in out["records"]} == {1}
    validations = [r["validation"] for r in out["records"][:-1]]
    assert all(v["seeds"] == list(tasks.get(RUNG).seeds("validation", 2)) for v in validations)
    chosen = out["records"][-1]
    assert chosen["selected_checkpoint"] == G.select_checkpoint(validations) == G.CHECKPOINTS - 1   # all tie: latest
    assert chosen["test_seeds"] == out["records"][-2]["test_seeds"]
    assert runner.done_runs([run], log) == {run}
    runner.run_one(run)
    assert len(log.read_text().splitlines()) == G.CHECKPOINTS + 1
    lines = log.read_text().splitlines()
    log.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])
    with pytest.warns(UserWarning, match="torn or corrupt"):
        runner.read_log(log, repair=True)
    assert runner.done_runs([run], log) == set()
    zero_trainer.clear()
    out = runner.run_one(run)
    assert [r["checkpoint"] for r in out["records"]] == [G.CHECKPOINTS]
    assert zero_trainer[-1] == (run.label(), G.CHECKPOINTS - 1)   # the selected checkpoint's own policy flew
    assert runner.done_runs([run], log) == {run}


@pytest.mark.parametrize(("validations", "chosen"), [
    ([(3, 0), (5, 1), (5, 0), (4, 0)], 2),      # most successes, then fewest unsafe episodes
    ([(5, 0), (5, 0), (2, 0)], 1),              # then the latest
    ([(0, 4), (0, 2), (0, 3)], 1),
])
def test_select_checkpoint_by_hand(validations, chosen):
    assert G.select_checkpoint([{"success": s, "unsafe": u} for s, u in validations]) == chosen
    with pytest.raises(G.LearningError, match="at least one"):
        G.select_checkpoint([])


def test_results_from_the_log(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    for algo in ("controller", "ppo"):
        runner.run_one(G.Run("platoon-pereira2023", algo, False, 0, str(log), budget_override=5000, rung=RUNG))
    data = results.build_results(runner.read_log(log))
    assert set(data["controllers"]) == {RUNG}
    (rec,) = data["records"]
    assert rec["rung"] == 1 and rec["task"] == RUNG
    assert [p[0] for p in rec["curve"]] == G.Run("platoon-pereira2023", "ppo", budget_override=5000).checkpoints
    assert rec["test"]["success_rate"] == 0.0 == rec["last_test"]["success_rate"]
    assert rec["selected_checkpoint"] == G.CHECKPOINTS - 1 and rec["validation_success"] == [0.0] * G.CHECKPOINTS
    assert sum(rec["test"]["failure_modes"].values()) == rec["test"]["episodes"] == 3
    assert rec["command"] == ("satenv results run --systems platoon-pereira2023 --rungs 1 --algorithms ppo --seeds 0 "
                              "--filter-systems '' --budget 5000")
    page = render.render_page(data)
    assert "## platoon, pereira2023" in page and "rung 1: not solved by standard RL" in page
    assert "| platoon, pereira2023: standard RL solves rung 1 (platoon-tplf30-rung1-near) | 0.00" in page
    modes = render._failures([data["controllers"][RUNG]])   # a failing controller names how it fails
    assert modes != "none" and f"| 0.00 (3 seeds; {modes}) |" in page


def test_a_longer_budget_is_its_own_run_and_row(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    short, longer = (G.Run("platoon-pereira2023", "ppo", False, 0, str(log), budget_override=b, rung=RUNG)
                     for b in (5000, 10000))
    runner.run_one(short)
    assert runner.done_runs([short, longer], log) == {short}
    runner.run_one(longer)
    data = results.build_results(runner.read_log(log))
    assert sorted(r["budget_agent_steps"] for r in data["records"]) == [5000, 10000]
    page = render.render_page(data)
    assert "PPO (lean), 5,000 agent-steps" in page and "PPO (lean), 10,000 agent-steps" in page
    assert "--budget" not in results.command("platoon-pereira2023", 1, "ppo", False, "0",
                                             G.BUDGET_AGENT_STEPS["platoon-pereira2023"])


def test_grid_covers_the_ladders():
    runs = G.grid(tasks.SYSTEMS, G.DEFAULT_ALGORITHMS, G.DEFAULT_SEEDS)
    for system in tasks.SYSTEMS:
        for rung in tasks.ladder(system):
            mine = [r for r in runs if r.task.name == rung]
            algos = {r.algorithm for r in mine if not r.filter}
            assert {"ppo", "ippo", "mappo", "ppo_lag", "masac", "dagger", "controller"} <= algos
            assert len({r.seed for r in mine if r.algorithm == "ppo"}) >= 5
            assert any(r.filter for r in mine) == (system in G.FILTER_SYSTEMS)
    assert all(G.BUDGET_AGENT_STEPS[s] >= 10_000_000 for s in tasks.SYSTEMS if s.startswith(("platoon", "formation")))
    assert ([r.task.name for r in G.grid(["cluster-li2022"], ["ppo"], [0], (), rungs=[2])]
            == [tasks.ladder("cluster-li2022")[1]])
    with pytest.raises(G.LearningError, match="rungs"):
        G.grid(["cluster-li2022"], ["ppo"], [0], rungs=[4])


def test_bad_run_fields_are_errors():
    with pytest.raises(G.LearningError, match="algorithm"):
        G.Run("platoon-pereira2023", "dqn")
    with pytest.raises(G.LearningError, match="seed"):
        G.Run("platoon-pereira2023", "ppo", seed=-1)
    with pytest.raises(G.LearningError, match="rung"):
        G.Run("platoon-pereira2023", "ppo", rung="cluster-case1-random")
    for bad in (-5, 2.5, True):
        with pytest.raises(G.LearningError, match="budget"):
            G.Run("platoon-pereira2023", "ppo", budget_override=bad)


def test_interventions_are_per_agent_step():
    """The filter counts decisions; an intervention is one agent's action (2 agents, 10 decisions,
    10 corrected actions: half the agent-steps)."""
    ep = {"seed": 0, "success": False, "collisions": 0, "violations": 0, "terminated": False, "rmse": 1.0,
          "delta_v": 1.0, "safety_interventions": 10, "safety_infeasible": 0, "safety_steps": 10}
    block = results._test_block([ep], None, n_agents=2)
    assert block["interventions_per_agent_step"] == pytest.approx(0.5)
    assert block["failure_modes"]["timeout"] == 1


@pytest.mark.parametrize("args, field", [
    (["--budget", "-5"], "argument --budget: expected an int >= 0, got '-5'"), (["--seeds", "x"], "--seeds 'x'"),
    (["--rungs", "x"], "--rungs 'x'"), (["--rungs", "4"], "rungs [4]"),
    (["--workers", "0"], "argument --workers: expected an int >= 1, got '0'"),
    (["--systems", "nope"], "--systems 'nope': expected comma-separated names"),
    (["--systems", ","], "--systems ',': expected comma-separated names"),
    (["--log", "."], "argument --log: '.' is a folder; expected a file path"),
    (["--log", ""], "argument --log: expected a file path, got ''")])
def test_bad_run_arguments_are_a_one_line_error(tmp_path, capsys, args, field):
    from satenv.bench.learning.cli import main

    log = tmp_path / "log.jsonl"
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--log", str(log), *args])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "Traceback" not in err
    (line,) = [x for x in err.splitlines() if "error:" in x]
    assert line.startswith("satenv results run: error: ") and field in line, line
    assert not log.exists()   # nothing ran, nothing was written


def test_the_commands_write_into_a_user_folder_unless_asked_to_update_the_record(tmp_path, monkeypatch, capsys):
    """``satenv results results`` / ``render`` read and write ``results/reference_results/`` by default;
    the committed record is touched only with ``--update-published`` (given with a path, one error)."""
    from satenv.bench.learning import cli

    monkeypatch.chdir(tmp_path)
    committed = {p: p.read_bytes() for p in (cli.RESULTS, ROOT / "docs" / "reference_results.md")}
    user = tmp_path / cli.USER
    user.mkdir(parents=True)
    (user / "log.jsonl").write_bytes(cli.LOG.read_bytes())
    assert cli.main(["results"]) == 0 and cli.main(["render"]) == 0
    assert (user / "results.json").is_file() and (user / "reference_results.md").is_file()
    assert all(p.read_bytes() == data for p, data in committed.items())
    with pytest.raises(SystemExit) as exit_:
        cli.main(["results", "--update-published", "--out", str(tmp_path / "r.json")])
    assert exit_.value.code == 2 and "--update-published" in capsys.readouterr().err


def test_render_writes_into_a_given_folder(tmp_path):
    from satenv.bench.learning.cli import main
    from satenv.bench.learning.datasets import MANIFEST

    out = tmp_path / "page"
    out.mkdir()
    assert main(["render", "--results", str(RESULTS), "--out-dir", str(out)]) in (0, None)
    page = render.render_page(json.loads(RESULTS.read_text()), render.read_manifest(MANIFEST))
    assert (out / "reference_results.md").read_text() == page


def test_masac_runs_at_the_standard_update_to_data_ratio(tmp_path):
    """The experiment BenchMARL builds for a grid MASAC run: >= 0.25 gradient steps per collected frame,
    each on BenchMARL's standard off-policy batch of 128 frames."""
    pytest.importorskip("benchmarl")
    from satenv.training.benchmarl_train import build_experiment

    run = next(r for r in G.grid(["platoon-pereira2023"], ["masac"], [0], (), rungs=[1]))
    ec = build_experiment(trainers.benchmarl_config(run, 4, tmp_path)).config
    assert ec.off_policy_n_optimizer_steps / ec.off_policy_collected_frames_per_batch >= 0.25
    assert ec.off_policy_train_batch_size == 128
