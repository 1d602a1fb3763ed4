"""A smoke run of the speed benchmark (tiny sizes; no timing assertions)."""

import json

import pytest

from satenv.bench import perf


def test_perf_smoke_writes_figures_and_ratios(tmp_path):
    out = tmp_path / "perf.json"
    result = perf.main(["--out", str(out), "--batches", "1,2", "--min-time", "0.002", "--api-time", "0.01",
                        "--sections", "api,mpe2,batched,vmas,solvers", "--solvers", "dmpc",
                        "--solver-scale", "0.05"])
    data = json.loads(out.read_text())
    assert data["config"]["batches"] == [1, 2]
    rows = data["batched"]
    assert {(r["kind"], r["model"], r["batch"]) for r in rows if r["kind"] == "dynamics"} == {
        ("dynamics", m, b) for m in ("cw", "j2") for b in (1, 2)}
    for r in rows:
        assert r["agent_steps_per_s"] > 0
        if r["kind"] == "dynamics":
            assert 0 < r["ratio_to_limit"] == r["agent_steps_per_s"] / r["memory_limit_agent_steps_per_s"]
    assert data["api"]["agent_steps_per_s"] > 0 and data["api"]["agents"] == 4
    if "skipped" not in data["mpe2"]:
        assert data["ratios"]["api_vs_mpe2"] == data["api"]["agent_steps_per_s"] / data["mpe2"]["agent_steps_per_s"]
    if "skipped" not in data["vmas"]:
        assert [r["batch"] for r in data["vmas"]["rows"]] == [1, 2]
        assert set(data["ratios"]["core_cw_vs_vmas_by_batch"]) == {"1", "2"}
    assert data["ratios"]["cw_best_batch"] in (1, 2)
    dmpc = data["solvers"]["dmpc@platoon-PLF-cw"]
    assert "skipped" in dmpc or (dmpc["decisions"] >= 1 and dmpc["act_ms_median"] > 0)
    names = {t["name"] for t in data["targets"]}
    assert any(n.startswith("(b) cw") for n in names) and all(isinstance(t["met"], bool) for t in data["targets"])
    assert result["ratios"] == json.loads(json.dumps(result["ratios"]))  # JSON round trip


def test_perf_opt_in_sections_smoke(tmp_path):
    """The sections folded in from the former bench_cgmres / bench_training scripts."""
    import pytest

    pytest.importorskip("casadi")
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "perf.json"
    perf.main(["--out", str(out), "--sections", "cgmres_ipopt,training", "--solver-scale", "0.003"])
    data = json.loads(out.read_text())
    rows = data["cgmres_ipopt"]
    assert [r["scenario"] for r in rows] == ["kannan2022-position", "kannan2022-collision"]
    assert all(r["ipopt_solves"] >= 1 and r["cgmres_update_ms_median"] > 0 for r in rows)
    train = data["training"]
    assert train["satenv"]["learn_env_steps_per_s"] > 0 and train["dummy"]["raw_env_steps_per_s"] > 0
    assert train["ratio_raw_env_steps_per_s"] == (train["satenv"]["raw_env_steps_per_s"]
                                                  / train["dummy"]["raw_env_steps_per_s"])


def test_perf_guard_section_smoke():
    out = perf.guard_cost(0.01, [1, 2], log=lambda line: None)
    pz = out["pettingzoo"]
    assert pz["step_us"] > 0 and pz["check_us"] > 0
    assert pz["check_share"] == pytest.approx(pz["check_us"] / pz["step_us"], rel=1e-12)
    assert [r["batch"] for r in out["make_vec"]] == [1, 2] and isinstance(out["met"], bool)


def test_perf_reproductions_section_smoke(tmp_path, monkeypatch):
    """Issue 17's reproduction wall times, on the one-second pereira2023 reproduction: a row with
    its time, target and exit status, and a target flag that can fail."""
    monkeypatch.setattr(perf.reproductions, "REPRODUCTION_TARGETS_S",
                        {"pereira2023": (["pereira2023", "--no-analysis"], 1e-3)})
    out = tmp_path / "perf.json"
    perf.main(["--out", str(out), "--sections", "reproductions"])
    data = json.loads(out.read_text())
    row = data["reproductions"]["pereira2023"]
    assert row["wall_s"] > 0 and row["target_s"] == 1e-3 and row["exit_status"] in (0, 1)   # 1: a claim not met
    flag = [t for t in data["targets"] if t["name"] == "(f) reproduce pereira2023 wall time [s]"]
    assert flag and flag[0]["met"] is False


def test_perf_scaling_section_smoke(tmp_path, monkeypatch):
    """The swarm table of issue 19 at tiny sizes, through the command line: JSON, targets, plot."""
    from satenv.bench.perf import scaling

    monkeypatch.setattr(scaling, "SIZES", (2, 3))
    monkeypatch.setattr(scaling, "COPIES", 2)
    monkeypatch.setattr(scaling, "TUBE_MAX", 0)
    out = tmp_path / "perf.json"
    perf.main(["--out", str(out), "--sections", "scaling", "--min-time", "0.002", "--solver-scale", "0.2"])
    data = json.loads(out.read_text())["scaling"]
    for key, baselines in (("platoon", {"dmpc"}), ("cluster", {"apf"})):
        rows = data[key]["rows"]
        assert [r["n"] for r in rows] == [2, 3]
        assert all(r["core_agent_steps_per_s"] > 0 and r["core_memory_mib"] > 0 for r in rows)
        assert {"pettingzoo", "core"} | baselines <= set(data[key]["growth_exponent"])
    assert all(r["allocation_ms"] >= 0 for r in data["cluster"]["rows"])
    names = [t["name"] for t in json.loads(out.read_text())["targets"]]
    assert any("(cluster, cw)" in n for n in names) and any("(platoon, cw)" in n for n in names)
    png = tmp_path / "perf_scaling.png"
    assert data["plot"] == str(png) and png.read_bytes().startswith(b"\x89PNG")


def test_fast_solver_targets_are_flagged_against_issue_17():
    from satenv.bench.perf import FAST_SOLVER_TARGETS_MS, _ratios

    rows = {key: {"fast_ms_per_agent_decision_median": goal * factor, "speedup": 2.0, "target_ms": goal}
            for (key, goal), factor in zip(FAST_SOLVER_TARGETS_MS.items(), (0.5, 3.0), strict=True)}
    ratios, targets = _ratios({"solvers": {"fast_vs_ipopt": rows}})
    flags = {t["name"]: (t["met"], t["op"]) for t in targets}
    assert flags == {"(e) tube_rdmpc@cluster-case1 fast solver ms per agent decision": (True, "<="),
                     "(e) nmpc@servicing-pereira2022 fast solver ms per agent decision": (False, "<=")}
    assert ratios["tube_rdmpc@cluster-case1_fast_vs_ipopt_speedup"] == 2.0


def test_perf_envs_section_smoke():
    """The envs comparisons at tiny sizes: each target is the ratio of two figures of the run."""
    from satenv.bench.perf import envs

    out = envs.env_speed(0.002, 0.01, batch=2, swarm_sizes=(4, 8), log=lambda line: None)
    rates = out["ring_swarm"]["agent_steps_per_s"]
    ratio = out["ratios"]["ring swarm core x64: per-agent rate N=8 / N=4"]
    assert ratio == rates["8"] / rates["4"] > 0
    names = {t["name"]: t for t in out["targets"]}
    assert all(isinstance(t["met"], bool) and t["op"] == ">=" for t in names.values())
    if "skipped" not in out["pettingzoo"]:
        pz = out["pettingzoo"]
        t = names["(envs) cluster_v0 PettingZoo / mpe2 simple_spread, per agent-step"]
        assert t["value"] == pz["cluster_v0"]["agent_steps_per_s"] / pz["mpe2"]["agent_steps_per_s"]
        assert t["target"] == 5.0 and names["(envs) servicing_v0 PettingZoo / mpe2 simple_spread, per agent-step"][
            "target"] == 1.0
    shares = out["make_vec_profile"]["shares"]
    assert set(shares) == {"truth kernel", "separations", "graph and observation", "rest"}
    assert abs(sum(shares.values()) - 1.0) < 1e-9 and min(shares.values()) >= 0
    if "vmas_agent_steps_per_s" in out["make_vec"]:
        assert out["make_vec"]["satenv_agent_steps_per_s"] > 0
    # the report collects a section's own targets
    from satenv.bench.perf import _ratios

    assert _ratios({"envs": out})[1] == out["targets"]


def test_perf_package_has_no_import_cycle_and_runs_as_a_module():
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = ("import satenv.bench.perf.scaling, satenv.bench.perf.envs; import satenv.bench.perf as p; "
            "print(len(p.REGISTRY))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root)
    assert int(proc.stdout.strip()) >= 7
    proc = subprocess.run([sys.executable, "-m", "satenv.bench.perf", "--help"], capture_output=True, text=True,
                          check=True, cwd=root)
    assert "--sections" in proc.stdout and "envs" in proc.stdout


def test_perf_learning_loop_section_smoke(monkeypatch):
    """Lean PPO and SB3 PPO with the same settings on each training task, the lean/SB3 ratio and
    the targets (tiny sizes; no timing assertions)."""
    from satenv import tasks
    from satenv.bench.perf import learning, learning_loop

    assert learning_loop.sb3_config(learning_loop.SAME) == learning.FAST_CONFIGS["sb3_ppo"]
    tiny = {**learning_loop.SAME, "num_envs": 2, "n_steps": 4, "minibatch_size": 40}
    monkeypatch.setattr(learning_loop, "env_alone", lambda task, n, min_time=0.5: 1.0)
    out = learning_loop.learning_loop(agent_steps=1, repeats=1, same=tiny, log=lambda _: None)
    assert set(out["tasks"]) == {tasks.training_task(s).name for s in learning_loop.TASKS}
    for row in out["tasks"].values():
        lean, sb3 = row["lean_ppo"], row["sb3_ppo"]
        assert lean["config"]["minibatch_size"] == 40 and lean["agent_steps"] >= 8
        assert sb3["config"]["batch_size"] == 40
        assert row["vs_sb3"] == lean["agent_steps_per_s"] / sb3["agent_steps_per_s"]
        assert 0 < lean["env_share"] and 0 < lean["learner_share"] and lean["env_share"] + lean["learner_share"] < 1
    names = [t["name"] for t in out["targets"]]
    assert len(names) == 3 and sum("env share" in n for n in names) == 1
    assert "learning_loop" in perf.EXTRA_SECTIONS and perf.REGISTRY["learning_loop"] is learning_loop.run
