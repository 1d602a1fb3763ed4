"""The reference results: the page is the render of results.json, the results file is complete
where it claims to be, the runner's log is resumable, the IQM band is the estimator it says."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from satenv.bench.learning import grid as G
from satenv.bench.learning import render, results, runner, trainers

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "studies" / "reference_results" / "results.json"


def test_page_is_the_render_of_results_json():
    from satenv.bench.learning.datasets import MANIFEST

    data = json.loads(RESULTS.read_text())
    assert render.PAGE.read_text() == render.render_page(data, render.read_manifest(MANIFEST)), \
        "docs/reference_results.md is stale: python -m satenv.bench.learning render"


def test_every_published_record_has_its_curve_and_test_block():
    data = json.loads(RESULTS.read_text())
    for rec in data["records"]:
        assert len(rec["curve"]) >= G.CHECKPOINTS >= 5
        assert all(len(p) == 4 for p in rec["curve"])
        steps = [p[0] for p in rec["curve"]]
        assert steps == sorted(steps) and steps[-1] == rec["agent_steps"]
        assert rec["budget_agent_steps"] > 0 and rec["wall_s"] >= 0
        for key in ("success_rate", "collision_episodes", "violation_episodes", "episodes"):
            assert key in rec["test"], (rec["system"], rec["algorithm"], key)
        assert rec["test"]["episodes"] == G.TEST_SEEDS_PER_CHECKPOINT
        assert rec["test_seeds"] == list(G.test_seeds(rec["system"]))
        if rec["filter"]:
            assert "interventions_per_agent_step" in rec["test"]
        assert rec["command"].startswith("python -m satenv.bench.learning run ")


def test_iqm_and_its_band():
    assert render.iqm(np.array([0.0, 1.0, 2.0, 3.0])) == pytest.approx(1.5)
    flat = np.full((3, 5), 0.4)
    mid, lo, hi = render.iqm_band(flat, reps=200)
    assert np.allclose(mid, 0.4) and np.allclose(lo, 0.4) and np.allclose(hi, 0.4)
    spread = np.array([[0.0, 0.0], [0.5, 1.0], [1.0, 1.0], [1.0, 1.0]])
    mid, lo, hi = render.iqm_band(spread, reps=500)
    assert np.all(lo <= mid) and np.all(mid <= hi) and lo[0] < hi[0]


@pytest.fixture
def zero_trainer(monkeypatch):
    """PPO replaced by a 'trainer' that reports the zero policy at every checkpoint (fast)."""
    calls = []

    def fake(run, checkpoint, workdir):
        from satenv import baselines
        calls.append(run.label())
        for k, steps in enumerate(run.checkpoints):
            checkpoint(k, steps, 0.1 * (k + 1), lambda env: baselines.make("zero", env))

    monkeypatch.setitem(trainers.TRAINERS, "ppo", fake)
    return calls


def test_runner_logs_every_checkpoint_and_resumes(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    run = G.Run("platoon-pereira2023", "ppo", False, 0, str(log), budget_override=5000)
    out = runner.run_one(run)
    assert [r["checkpoint"] for r in out["records"]] == list(range(G.CHECKPOINTS))
    assert len(runner.read_log(log)) == G.CHECKPOINTS
    assert runner.done_runs([run], log) == {run}
    # a second run writes nothing new
    runner.run_one(run)
    assert len(log.read_text().splitlines()) == G.CHECKPOINTS
    # killed mid-line: the torn line is set aside, the run is no longer done, a resume writes only it
    lines = log.read_text().splitlines()
    log.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])
    with pytest.warns(UserWarning, match="torn or corrupt"):
        runner.read_log(log, repair=True)
    assert runner.done_runs([run], log) == set()
    out = runner.run_one(run)
    assert [r["checkpoint"] for r in out["records"]] == [G.CHECKPOINTS - 1]
    assert runner.done_runs([run], log) == {run}


def test_results_from_the_log(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    for algo in ("controller", "ppo"):
        runner.run_one(G.Run("platoon-pereira2023", algo, False, 0, str(log), budget_override=5000))
    data = results.build_results(runner.read_log(log))
    assert set(data["controllers"]) == {"platoon-pereira2023"}
    (rec,) = data["records"]
    assert [p[0] for p in rec["curve"]] == G.Run("platoon-pereira2023", "ppo", budget_override=5000).checkpoints
    # the zero policy against the DMPC: success 0, and its delta-v ratio on matched episodes is 0
    assert rec["test"]["success_rate"] == 0.0
    if rec["test"]["matched_seeds"]:
        assert rec["test"]["delta_v_ratio"] == 0.0
    page = render.render_page(data)
    assert "platoon, pereira2023" in page and "No success on any seed at the budget: PPO (SB3)" in page


def test_a_longer_budget_is_its_own_run_and_row(tmp_path, zero_trainer):
    log = tmp_path / "log.jsonl"
    short, longer = (G.Run("platoon-pereira2023", "ppo", False, 0, str(log), budget_override=b) for b in (5000, 10000))
    runner.run_one(short)
    assert runner.done_runs([short, longer], log) == {short}
    runner.run_one(longer)
    assert runner.done_runs([short, longer], log) == {short, longer}
    data = results.build_results(runner.read_log(log))
    assert sorted(r["budget_agent_steps"] for r in data["records"]) == [5000, 10000]
    assert {r["command"].split("--budget ")[-1] for r in data["records"]} == {"5000", "10000"}
    page = render.render_page(data)
    assert "PPO (SB3), 5,000 agent-steps" in page and "PPO (SB3), 10,000 agent-steps" in page
    # the grid's own budget needs no --budget
    assert "--budget" not in results.command("platoon-pereira2023", "ppo", False, 0, G.BUDGET_AGENT_STEPS["platoon-pereira2023"])


def test_grid_covers_the_targets():
    runs = G.grid(list(G.BUDGET_AGENT_STEPS), G.DEFAULT_ALGORITHMS, [0, 1, 2])
    systems = {r.system for r in runs}
    assert len(systems) == 6
    for s in systems:
        algos = {r.algorithm for r in runs if r.system == s and not r.filter}
        assert {"ppo", "mappo", "masac", "dagger", "controller"} <= algos
        assert len({r.seed for r in runs if r.system == s and r.algorithm == "ppo"}) >= 3
    assert {r.system for r in runs if r.filter} == set(G.FILTER_SYSTEMS)


def test_bad_run_fields_are_errors():
    with pytest.raises(G.LearningError, match="algorithm"):
        G.Run("platoon-pereira2023", "dqn")
    with pytest.raises(G.LearningError, match="seed"):
        G.Run("platoon-pereira2023", "ppo", seed=-1)
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


@pytest.mark.parametrize("args, field", [
    (["--budget", "-5"], "argument --budget: expected an int >= 0, got '-5'"), (["--seeds", "x"], "--seeds 'x'"),
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
