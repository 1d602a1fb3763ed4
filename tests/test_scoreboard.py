"""The scoreboard (benchmarks.scoreboard / registry): files and schema, resume, workers, bad input."""

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from benchmarks import registry
from benchmarks.registry import POLICIES, PolicySpec, ScenarioSpec, ScoreboardError, Unavailable
from benchmarks.scoreboard import (
    EPISODES_FILE,
    METRICS,
    TIMING_FIELDS,
    aggregate,
    main,
    parse_seeds,
    rank,
    read_episodes,
    run_scoreboard,
)

TESTS = Path(__file__).resolve().parent
# the toy env of tests/test_env_base.py (importable as ``test_env_base``: tests/ is on sys.path)
TOY = {"toy": ScenarioSpec("toy", ("test_env_base:ToyEnv",), {}, "3 double integrators to the origin")}
TWO = {k: POLICIES[k] for k in ("zero", "random")}


class WrongObsPolicy:
    """A 'learned' policy trained on another observation size."""

    obs_shape = (5,)

    def __init__(self, env):
        self.info = {}

    def reset(self, seed=None):
        pass

    def act(self, observations):
        return {a: np.zeros(3) for a in observations}


def _board(out, **kw):
    kw.setdefault("scenario_registry", TOY)
    kw.setdefault("policy_registry", TWO)
    kw.setdefault("progress", False)
    kw.setdefault("plots", False)
    return run_scoreboard(out, **kw)


def _strip(records):
    """Records without the measured times (the only fields allowed to differ between runs)."""
    return sorted(json.dumps({k: v for k, v in r.items() if k not in TIMING_FIELDS}, sort_keys=True)
                  for r in records)


def test_end_to_end_files_and_schema(tmp_path):
    board = _board(tmp_path, seeds="0-1", plots=True)
    lines = (tmp_path / EPISODES_FILE).read_text().splitlines()
    assert len(lines) == 4
    for line in lines:
        rec = json.loads(line)
        assert {"scenario", "policy", "seed", "env", "error", "wall_s", *METRICS} <= set(rec)
        assert rec["env"] == "toy_v0" and rec["error"] is None and rec["steps"] == 20
    data = json.loads((tmp_path / "scoreboard.json").read_text())
    assert set(data) == {"header", "ranking", "aggregates", "episodes"}
    h = data["header"]
    assert h["seeds"] == [0, 1] and h["env_versions"] == ["toy_v0"] and h["satenv_version"]
    assert {"cpu", "cpus", "platform", "python"} <= set(h["machine"])
    assert data["ranking"] == {"toy": board.ranking["toy"]} and sorted(board.ranking["toy"]) == ["random", "zero"]
    for pol in ("zero", "random"):
        agg = data["aggregates"]["toy"][pol]
        assert agg["n"] == 2 and agg["errors"] == 0
        for m in METRICS:
            assert set(agg[m]) == {"mean", "ci95", "n"}
    # zero thrust spends nothing; random thrust does
    assert data["aggregates"]["toy"]["zero"]["delta_v"]["mean"] == 0.0
    assert data["aggregates"]["toy"]["random"]["delta_v"]["mean"] > 0.0
    md = (tmp_path / "scoreboard.md").read_text()
    assert "## toy (toy_v0)" in md and "| 1 |" in md and "| 2 |" in md and "seeds 0–1" in md
    csv_rows = (tmp_path / "scoreboard.csv").read_text().splitlines()
    assert len(csv_rows) == 3 and csv_rows[0].startswith("scenario,rank,policy,n,errors,success_mean")
    assert len((tmp_path / "episodes.csv").read_text().splitlines()) == 5
    assert (tmp_path / "plots" / "rmse.png").stat().st_size > 0
    assert len(list((tmp_path / "plots" / "trajectories").glob("*.png"))) == 2


def test_resume_after_an_exception_gives_exactly_the_uninterrupted_episodes(tmp_path):
    reference = _board(tmp_path / "ref", seeds="0-2")

    def boom(rec, count=[0]):  # noqa: B006 - a counter
        count[0] += 1
        if count[0] == 2:
            raise RuntimeError("injected crash")

    with pytest.raises(RuntimeError, match="injected"):
        _board(tmp_path / "run", seeds="0-2", on_record=boom)
    log = tmp_path / "run" / EPISODES_FILE
    assert len(read_episodes(log)) == 2
    with open(log, "a") as fh:               # a torn line, as if killed in the middle of a write
        fh.write('{"scenario": "toy", "pol')
    with pytest.raises(ScoreboardError, match="--resume"):
        _board(tmp_path / "run", seeds="0-2")
    resumed = _board(tmp_path / "run", seeds="0-2", resume=True)
    lines = log.read_text().splitlines()
    assert len(lines) == 6 and len({(json.loads(x)["policy"], json.loads(x)["seed"]) for x in lines}) == 6
    assert _strip(resumed.records) == _strip(reference.records)
    again = _board(tmp_path / "run", seeds="0-2", resume=True)   # nothing left to do
    assert len(log.read_text().splitlines()) == 6 and _strip(again.records) == _strip(reference.records)


def test_resume_after_sigkill(tmp_path):
    script = textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(TESTS)!r})
        from test_scoreboard import _board
        n = [0]
        def kill(rec):
            n[0] += 1
            if n[0] == 3:
                os.kill(os.getpid(), signal.SIGKILL)
        _board({str(tmp_path / "run")!r}, seeds="0-2", on_record=kill)
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          cwd=TESTS.parent)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert len(read_episodes(tmp_path / "run" / EPISODES_FILE)) == 3
    resumed = _board(tmp_path / "run", seeds="0-2", resume=True)
    reference = _board(tmp_path / "ref", seeds="0-2")
    assert len((tmp_path / "run" / EPISODES_FILE).read_text().splitlines()) == 6
    assert _strip(resumed.records) == _strip(reference.records)


def test_two_workers_give_the_serial_results(tmp_path):
    serial = _board(tmp_path / "serial", seeds="0-3")
    pooled = _board(tmp_path / "pool", seeds="0-3", workers=2)
    assert len(pooled.records) == 8
    assert _strip(pooled.records) == _strip(serial.records)
    assert pooled.aggregates["toy"]["random"]["rmse"] == serial.aggregates["toy"]["random"]["rmse"]


def test_ray_backend_runs_locally(tmp_path, monkeypatch):
    ray = pytest.importorskip("ray")
    # Ray workers must import the toy env from tests/ too
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(TESTS), str(TESTS.parent),
                                                      os.environ.get("PYTHONPATH", "")]))
    try:
        board = _board(tmp_path / "ray", seeds="0-1", backend="ray", workers=2)
    finally:
        ray.shutdown()
    serial = _board(tmp_path / "serial", seeds="0-1")
    assert _strip(board.records) == _strip(serial.records)


@pytest.mark.parametrize("kwargs, match", [
    ({"policies": "zero,zeroo"}, "unknown policy 'zeroo'"),
    ({"scenarios": "toy,platoon-XYZ"}, "unknown scenario 'platoon-XYZ'"),
    ({"checkpoints": ["/nonexistent/policy"]}, "no such file"),
    ({"policy_registry": {"wrong": PolicySpec("wrong", ("test_scoreboard:WrongObsPolicy",), learned=True)},
      "policies": "wrong", "scenarios": "toy"}, r"expects observations of shape \(5,\)"),
    ({"seeds": "3-1"}, "--seeds"),
    ({"workers": 0}, "--workers"),
    ({"resume": True, "overwrite": True}, "contradict"),
])
def test_bad_input_fails_before_any_episode(tmp_path, kwargs, match):
    with pytest.raises(ScoreboardError, match=match):
        _board(tmp_path, **kwargs)
    assert not (tmp_path / EPISODES_FILE).exists()


def test_unreadable_checkpoint_is_a_clear_error(tmp_path):
    training = pytest.importorskip("training")
    if not callable(getattr(training, "load", None)):
        pytest.skip("training.load not available")
    bad = tmp_path / "ckpt"
    bad.mkdir()
    (bad / "model.zip").write_text("not a model")
    with pytest.raises(ScoreboardError, match="cannot load this checkpoint"):
        _board(tmp_path / "out", checkpoints=[str(bad)])


def test_cli_errors_and_list(capsys):
    assert main(["--scenarios", "no-such-scenario", "--no-progress"]) == 2
    assert "unknown scenario 'no-such-scenario'" in capsys.readouterr().err
    assert main(["--list"]) == 0
    assert "platoon-PLF-cw" in capsys.readouterr().out


def test_platoon_with_dmpc_through_the_board(tmp_path):
    try:
        POLICIES["dmpc"].factory()
        registry.SCENARIOS["platoon-PLF-cw"].factory()
    except Unavailable as why:
        pytest.skip(str(why))
    scen = registry.SCENARIOS["platoon-PLF-cw"]
    short = {"platoon-short": ScenarioSpec("platoon-short", scen.targets, {**scen.kwargs, "max_steps": 100})}
    board = _board(tmp_path, seeds="0", scenario_registry=short,
                   policy_registry={k: POLICIES[k] for k in ("zero", "dmpc")})
    assert board.ranking["platoon-short"] == ["dmpc", "zero"]   # closer to the formation than coasting
    assert all(r["error"] is None for r in board.records)


def test_registry_skips_only_the_missing_module(tmp_path, monkeypatch):
    with pytest.raises(Unavailable, match="not_landed_yet_xyz"):
        registry.resolve(("satenv.envs.not_landed_yet_xyz:parallel_env",))
    with pytest.raises(Unavailable, match="has no Nope"):
        registry.resolve(("baselines.base:Nope",))
    with pytest.raises(Unavailable, match="optional dependency"):
        registry.resolve(("baselines.base:ZeroPolicy",), requires=("no_such_dependency_xyz",))
    # an existing module whose own import is broken is a bug: it must propagate
    pkg = tmp_path / "brokenpkg_xyz"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "env.py").write_text("import no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError, match="no_such_dependency_xyz"):
        registry.resolve(("brokenpkg_xyz.env:parallel_env",))
    assert registry.resolve(("nope_xyz:f", "baselines.base:ZeroPolicy")) is POLICIES["zero"].factory()


def test_aggregate_intervals_and_ranking():
    recs = [{"scenario": "s", "policy": "a", "seed": i, "error": None, "success": i < 3,
             **{m: float(i + 1) for m in METRICS if m != "success"}} for i in range(3)]
    recs += [{"scenario": "s", "policy": "b", "seed": 0, "error": "RuntimeError: x", "success": False}]
    agg = aggregate(recs)
    rmse = agg["s"]["a"]["rmse"]
    assert rmse["mean"] == 2.0 and rmse["n"] == 3
    half = 4.302652729911275 / math.sqrt(3)          # t_{0.975, 2} * s / sqrt(n), s = 1
    assert rmse["ci95"] == pytest.approx([2.0 - half, 2.0 + half])
    lo, hi = agg["s"]["a"]["success"]["ci95"]           # Wilson interval of 3/3
    assert agg["s"]["a"]["success"]["mean"] == 1.0 and lo == pytest.approx(0.4385, abs=1e-4) and hi == pytest.approx(1.0)
    assert agg["s"]["b"]["errors"] == 1 and agg["s"]["b"]["rmse"]["mean"] is None
    assert rank(agg["s"]) == ["a", "b"]


def test_parse_seeds():
    assert parse_seeds("0-3,7, 2") == [0, 1, 2, 3, 7]
    for bad in ("", "a", "-1", "5-2"):
        with pytest.raises(ScoreboardError):
            parse_seeds(bad)


def test_scenario_seed_caps(tmp_path):
    board = _board(tmp_path, seeds="0-2", scenario_seeds={"toy": [1, 7]})
    assert sorted({r["seed"] for r in board.records}) == [1]
    assert board.header["scenario_seeds"] == {"toy": [1]}


def test_board_presets_name_registered_entries():
    for preset in (registry.QUICK, registry.FULL):
        for name in preset.get("scenarios", []):
            assert name in registry.SCENARIOS, name
        for name in preset.get("policies", []):
            assert name in registry.POLICIES or name.startswith("trained:"), name
        for name in preset["scenario_seeds"]:
            assert name in registry.SCENARIOS, name


def test_user_checkpoint_runs_and_mismatch_is_rejected(tmp_path):
    pytest.importorskip("stable_baselines3")
    training = pytest.importorskip("training")
    if not callable(getattr(training, "load", None)):
        pytest.skip("training.load not available")
    try:
        registry.SCENARIOS["platoon-random-cw"].factory()
    except Unavailable as why:
        pytest.skip(str(why))
    run = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "training.train", "--total-timesteps", "256", "--n-copies", "2",
                           "--n-steps", "32", "--batch-size", "64", "--eval-every", "0", "--test-seeds", "0",
                           "--eval-baselines", "zero", "--checkpoint-every", "0", "--progress", "false",
                           "--env-kwargs", '{"randomize": true}', "--out-dir", str(run)],
                          capture_output=True, text=True, timeout=300, cwd=TESTS.parent)
    assert proc.returncode == 0, proc.stderr[-2000:]
    scen = registry.SCENARIOS["platoon-random-cw"]
    reg = {"platoon-short": ScenarioSpec("platoon-short", scen.targets, {**scen.kwargs, "max_steps": 20}),
           "platoon-2022": ScenarioSpec("platoon-2022", scen.targets, {"preset": "pereira2022"})}  # 2 followers
    board = _board(tmp_path / "ok", seeds="0", scenario_registry=reg, policies="zero",
                   scenarios="platoon-short", checkpoints=[str(run / "final")])
    assert {r["policy"] for r in board.records} == {"zero", "user:final"}
    assert all(r["error"] is None for r in board.records)
    with pytest.raises(ScoreboardError, match=r"user:final cannot run on scenario platoon-2022.*\(36,\)"):
        _board(tmp_path / "bad", seeds="0", scenario_registry=reg, policies="zero",
               scenarios="platoon-2022", checkpoints=[str(run / "final")])
    assert not (tmp_path / "bad" / EPISODES_FILE).exists()
