"""The scoreboard (satenv.bench.scoreboard): files and schema, resume, workers, bad input."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from satenv.bench.scoreboard import (
    EPISODES_FILE,
    METRICS,
    POLICIES,
    TIMING_FIELDS,
    PolicySpec,
    ScoreboardError,
    ScoreboardWarning,
    TaskSpec,
    Unavailable,
    aggregate,
    main,
    parse_seeds,
    rank,
    read_episodes,
    registry,
    run_scoreboard,
    specs,
    user_policy_name,
)

TESTS = Path(__file__).resolve().parent
# a cheap scenario: the default platoon, 20 steps
TOY = {"toy": TaskSpec("toy", "platoon_v0", {"max_steps": 20}, "4 followers, 20 steps")}
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
    kw.setdefault("task_registry", TOY)
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
        filter_only = {"safety_interventions", "interventions_per_agent_step", "safety_mean_du", "safety_infeasible"}
        assert {"scenario", "policy", "seed", "env", "error", "wall_s", *METRICS} - filter_only <= set(rec)
        assert not filter_only & set(rec)            # the one record: the filter's fields only behind it
        assert rec["env"] == "platoon_v0" and rec["error"] is None and rec["steps"] == 20
    data = json.loads((tmp_path / "scoreboard.json").read_text())
    assert set(data) == {"header", "ranking", "aggregates", "summary", "episodes"}
    h = data["header"]
    assert h["seeds"] == [0, 1] and h["env_versions"] == ["platoon_v0"] and h["satenv_version"]
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
    assert "## toy (platoon_v0)" in md and "| 1 |" in md and "| 2 |" in md and "seeds 0–1" in md
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
    with pytest.warns(ScoreboardWarning, match="1 torn or corrupt line"):
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
    ({"scenarios": "toy,platoon-XYZ"}, "unknown task 'platoon-XYZ'"),
    ({"checkpoints": ["/nonexistent/policy"]}, "no such file"),
    ({"policy_registry": {"wrong": PolicySpec("wrong", "test_scoreboard:WrongObsPolicy", learned=True)},
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
    training = pytest.importorskip("satenv.training")
    if not callable(getattr(training, "load", None)):
        pytest.skip("satenv.training.load not available")
    bad = tmp_path / "ckpt"
    bad.mkdir()
    (bad / "model.zip").write_text("not a model")
    with pytest.raises(ScoreboardError, match="cannot load this checkpoint"):
        _board(tmp_path / "out", checkpoints=[str(bad)])


def test_cli_errors_and_list(capsys):
    assert main(["--scenarios", "no-such-scenario", "--no-progress"]) == 2
    assert "unknown task 'no-such-scenario'" in capsys.readouterr().err
    assert main(["--list"]) == 0
    assert "platoon-PLF-cw" in capsys.readouterr().out


def test_platoon_with_dmpc_through_the_board(tmp_path):
    try:
        POLICIES["dmpc"].check_available()
    except Unavailable as why:
        pytest.skip(str(why))
    scen = registry.TASKS["platoon-PLF-cw"]
    short = {"platoon-short": TaskSpec("platoon-short", scen.env_id, {**scen.kwargs, "max_steps": 100})}
    board = _board(tmp_path, seeds="0", task_registry=short,
                   policy_registry={k: POLICIES[k] for k in ("zero", "dmpc")})
    assert board.ranking["platoon-short"] == ["dmpc", "zero"]   # closer to the formation than coasting
    assert all(r["error"] is None for r in board.records)
    summary = board.summary["policies"]                          # across scenarios: 0 = zero, 1 = dmpc
    assert summary["zero"]["iqm"] == 0.0 and summary["dmpc"]["iqm"] == 1.0
    assert summary["zero"]["p_improvement"] == 0.0 and summary["dmpc"]["p_improvement"] is None
    assert "## Across tasks" in board.markdown and "| dmpc | 1 | 1 | 1.00 [1.00, 1.00] | – |" in board.markdown


def test_only_a_missing_optional_dependency_makes_an_entry_unavailable(tmp_path, monkeypatch):
    with pytest.raises(Unavailable, match="optional dependency"):
        specs.resolve("satenv.baselines.base:ZeroPolicy", requires=("no_such_dependency_xyz",))
    with pytest.raises(ScoreboardError, match="has no attribute 'Nope'"):
        specs.resolve("satenv.baselines.base:Nope")
    with pytest.raises(ModuleNotFoundError):          # no "not landed yet" tolerance
        specs.resolve("satenv.envs.not_landed_yet_xyz:parallel_env")
    assert specs.resolve("satenv.baselines.base:ZeroPolicy") is POLICIES["zero"].factory()
    with pytest.raises(ScoreboardError, match="env_id must be one of"):
        TaskSpec("x", "no_such_env_v0")
    with pytest.raises(ScoreboardError, match="'module:attribute'"):
        PolicySpec("x", ("satenv.baselines:DMPC",))


def test_policy_fits_by_env_id():
    envs = {i: specs.TaskSpec("s", i).make() for i in ("platoon_v0", "cluster_v0")}
    fits = {(name, i) for name, spec in POLICIES.items() for i, env in envs.items()
            if specs.policy_fits(spec, env)}
    assert fits == {("zero", "platoon_v0"), ("zero", "cluster_v0"), ("random", "platoon_v0"),
                    ("random", "cluster_v0"), ("dmpc", "platoon_v0"), ("tube_rdmpc", "cluster_v0"),
                    ("tube_rdmpc_rti", "cluster_v0"), ("apf", "cluster_v0")}
    trained = registry.discover_trained_policies()
    for spec in trained.values():                          # each fits the env of its env.json only
        assert spec.env_ids and all(specs.policy_fits(spec, env) == (i in spec.env_ids) for i, env in envs.items())
    shipped = trained["trained:platoon_tplf_ppo"]          # its scoreboard.json: its own scenario only
    assert shipped.ranked_on("platoon-tplf30-random-cw") and not shipped.ranked_on("platoon-PLF-cw")


def test_aggregate_intervals_and_ranking():
    recs = [{"scenario": "s", "policy": "a", "seed": i, "error": None, "success": i < 3,
             **{m: float(i + 1) for m in METRICS if m != "success"}} for i in range(3)]
    recs += [{"scenario": "s", "policy": "b", "seed": 0, "error": "RuntimeError: x", "success": False}]
    agg = aggregate(recs)
    rmse = agg["s"]["a"]["rmse"]
    assert rmse["mean"] == 2.0 and rmse["n"] == 3
    lo, hi = rmse["ci95"]                              # percentile bootstrap of the mean of 1, 2, 3
    assert 1.0 <= lo < 2.0 < hi <= 3.0
    lo, hi = agg["s"]["a"]["success"]["ci95"]           # Wilson interval of 3/3
    assert agg["s"]["a"]["success"]["mean"] == 1.0
    assert lo == pytest.approx(0.4385, abs=1e-4) and hi == pytest.approx(1.0)
    assert agg["s"]["b"]["errors"] == 1 and agg["s"]["b"]["rmse"]["mean"] is None
    assert rank(agg["s"]) == ["a", "b"]


def test_intervals_stay_inside_the_metric_range():
    """A separation of 5, 10 and 47.7 m has no negative interval (Student t gave 20.9 +- 54.7)."""
    recs = [{"scenario": "s", "policy": "a", "seed": i, "error": None, "success": i == 0,
             **{m: v for m in METRICS if m != "success"}} for i, v in enumerate([5.0, 10.0, 47.7])]
    agg = aggregate(recs)["s"]["a"]
    lo, hi = agg["min_separation_m"]["ci95"]
    assert 5.0 <= lo and hi <= 47.7
    lo, hi = agg["success"]["ci95"]
    assert 0.0 <= lo < 1 / 3 < hi <= 1.0 and lo == pytest.approx(0.0615, abs=1e-4)  # Wilson, 1 of 3
    from satenv.bench.scoreboard.report import _cell

    assert _cell(agg["success"], "success") == "33 % [6, 79]"
    assert _cell(agg["min_separation_m"], "min_separation_m").startswith("20.9 [")


def test_rliable_style_summary_has_known_answers():
    from satenv.bench.scoreboard.report import summarize

    def recs(pol, values, scen="s"):
        return [{"scenario": scen, "policy": pol, "seed": i, "error": None, "rmse": v} for i, v in enumerate(values)]

    records = recs("zero", [10.0] * 4) + recs("dmpc", [2.0] * 4) + recs("better", [1.0] * 4) \
        + recs("mixed", [2.0, 2.0, 10.0, 1.0]) + recs("zero", [5.0] * 2, "t") + [
            {"scenario": "s", "policy": "crash", "seed": 0, "error": "RuntimeError", "rmse": None}]
    out = summarize(records, {"s": "platoon_v0", "t": "platoon_v0"}, resamples=200)
    pol = out["policies"]
    assert out["reference"] == {"s": "dmpc"} and "t" in out["skipped"]   # t has no dmpc episodes
    assert pol["zero"]["iqm"] == 0.0 and pol["dmpc"]["iqm"] == 1.0 and pol["better"]["iqm"] == 1.125
    assert pol["better"]["p_improvement"] == 1.0 and pol["zero"]["p_improvement"] == 0.0
    assert pol["mixed"]["p_improvement"] == pytest.approx((0.5 + 0.5 + 0.0 + 1.0) / 4)
    assert pol["crash"]["iqm"] == 0.0                                     # an errored episode scores 0
    lo, hi = pol["mixed"]["iqm_ci95"]
    assert lo <= pol["mixed"]["iqm"] <= hi and pol["dmpc"]["p_improvement"] is None


def test_a_shipped_folder_given_with_policy_is_ranked_once():
    from satenv.bench.scoreboard.board import _user_specs

    reg = {**POLICIES, **registry.discover_trained_policies()}
    folder = TESTS.parent / "satenv" / "training" / "policies" / "platoon_tplf_ppo"
    if "trained:platoon_tplf_ppo" not in reg:
        pytest.skip("shipped policy not found")
    assert [s.name for s in _user_specs([str(folder), str(folder) + "/"], reg)] == ["trained:platoon_tplf_ppo"] * 2


def test_parse_seeds():
    assert parse_seeds("0-3,7, 2") == [0, 1, 2, 3, 7]
    for bad in ("", "a", "-1", "5-2"):
        with pytest.raises(ScoreboardError):
            parse_seeds(bad)
    with pytest.raises(ScoreboardError, match="more than"):   # the audit's 0-99999999999: capped
        parse_seeds("0-99999999999")


def test_quick_board_has_servicing_and_notes_say_where_a_baseline_applies():
    from satenv.bench.scoreboard.plan import _supported_envs
    from satenv.bench.scoreboard.registry import POLICIES, QUICK

    assert "servicing-pereira2022" in QUICK["scenarios"]
    for name in ("apf", "nmpc", "cgmres", "tube_rdmpc"):
        assert "any env" not in _supported_envs(POLICIES[name])[0]


def test_scenario_seed_caps(tmp_path):
    board = _board(tmp_path, seeds="0-2", scenario_seeds={"toy": [1, 7]})
    assert sorted({r["seed"] for r in board.records}) == [1]
    assert board.header["scenario_seeds"] == {"toy": [1]}


def test_board_presets_name_registered_entries():
    for preset in (registry.QUICK, registry.FULL):
        for name in preset.get("scenarios", []):
            assert name in registry.TASKS, name
        for name in preset.get("policies", []):
            assert name in registry.POLICIES or name.startswith("trained:"), name
        for name in preset["scenario_seeds"]:
            assert name in registry.TASKS, name


def test_user_checkpoint_runs_and_mismatch_is_rejected(tmp_path):
    pytest.importorskip("stable_baselines3")
    training = pytest.importorskip("satenv.training")
    if not callable(getattr(training, "load", None)):
        pytest.skip("satenv.training.load not available")
    run = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "satenv.training.train", "--total-timesteps", "256", "--num-envs", "2",
                           "--n-steps", "32", "--batch-size", "64", "--eval-every", "0", "--test-seeds", "0",
                           "--eval-baselines", "zero", "--checkpoint-every", "0", "--progress", "false",
                           "--env-id", "platoon_v0", "--env-kwargs", '{"randomize": true}', "--out-dir", str(run)],
                          capture_output=True, text=True, timeout=300, cwd=TESTS.parent)
    assert proc.returncode == 0, proc.stderr[-2000:]
    scen = registry.TASKS["platoon-random-cw"]
    reg = {"platoon-short": TaskSpec("platoon-short", scen.env_id, {**scen.kwargs, "max_steps": 20}),
           "platoon-2022": TaskSpec("platoon-2022", scen.env_id, {"preset": "pereira2022"})}  # 2 followers
    board = _board(tmp_path / "ok", seeds="0", task_registry=reg, policies="zero",
                   scenarios="platoon-short", checkpoints=[str(run / "final")])
    assert {r["policy"] for r in board.records} == {"zero", "user:run"}   # named after the run folder
    assert all(r["error"] is None for r in board.records)
    with pytest.raises(ScoreboardError, match=r"user:run cannot run on task platoon-2022.*\(36,\)"):
        _board(tmp_path / "bad", seeds="0", task_registry=reg, policies="zero",
               scenarios="platoon-2022", checkpoints=[str(run / "final")])
    assert not (tmp_path / "bad" / EPISODES_FILE).exists()


# ----------------------------------------------------------------------------------------------
# --policy names, a corrupt log, dying workers, a dying parent.
# ----------------------------------------------------------------------------------------------
def test_user_policy_names_come_from_the_run_folder(tmp_path):
    assert user_policy_name(tmp_path / "runs" / "a" / "final") == "user:a"
    assert user_policy_name(tmp_path / "runs" / "b" / "best") == "user:b"
    assert user_policy_name(tmp_path / "runs" / "c" / "checkpoint-4096") == "user:c"
    assert user_policy_name(tmp_path / "runs" / "my_ppo") == "user:my_ppo"


def _shipped_copy(dst: Path) -> str:
    import shutil

    shutil.copytree(registry.SHIPPED_POLICY_DIR / "platoon_tplf_ppo", dst)
    return str(dst)


def test_two_run_folders_get_two_names_and_a_clash_is_an_error(tmp_path):
    pytest.importorskip("stable_baselines3")
    a = _shipped_copy(tmp_path / "runs" / "a" / "final")
    b = _shipped_copy(tmp_path / "runs" / "b" / "final")
    scen = registry.TASKS["platoon-tplf30-random-cw"]
    reg = {"short": TaskSpec("short", scen.env_id, {**scen.kwargs, "max_steps": 10})}
    board = _board(tmp_path / "ok", seeds="0", task_registry=reg, policies="zero", checkpoints=[a, b])
    assert {r["policy"] for r in board.records} == {"zero", "user:a", "user:b"}
    assert all(r["error"] is None for r in board.records)
    c = _shipped_copy(tmp_path / "other" / "a" / "final")
    with pytest.raises(ScoreboardError, match="both named 'user:a'.*rename"):
        _board(tmp_path / "clash", seeds="0", task_registry=reg, policies="zero", checkpoints=[a, c])


def test_resume_quarantines_torn_and_corrupt_lines(tmp_path):
    reference = _board(tmp_path / "ref", seeds="0-2")
    run = tmp_path / "run"
    _board(run, seeds="0-2")
    log = run / EPISODES_FILE
    lines = log.read_text().splitlines(keepends=True)
    lines[2] = '{"scenario": "toy", "garbage\n'               # corrupt in the middle
    log.write_text("".join(lines) + '{"scenario": "toy", "pol')  # and torn at the end
    with pytest.warns(ScoreboardWarning, match=r"2 torn or corrupt line\(s\) \(line 3, 7\)"):
        resumed = _board(run, seeds="0-2", resume=True)
    assert _strip(resumed.records) == _strip(reference.records)
    assert len(log.read_text().splitlines()) == 6                 # 5 kept + the one re-run
    assert (run / (EPISODES_FILE + ".corrupt")).read_text().splitlines() == [
        '{"scenario": "toy", "garbage', '{"scenario": "toy", "pol']


class SlowPolicy:
    """Zero thrust, 20 ms per decision; with ``die_on_seed`` its process SIGKILLs itself in the
    first decision of that seed (every time, or with ``once`` only the first time)."""

    die_on_seed: int | None = None
    once: str | None = None     # a marker file: die only if it does not exist yet

    def __init__(self, env):
        self.info = {}
        self.seed = None

    def reset(self, seed=None):
        self.seed = seed
        marker = os.environ.get("SCOREBOARD_TEST_STARTED")
        if marker:
            Path(marker, f"{os.getpid()}").touch()

    def act(self, observations):
        import time

        if self.seed == self.die_on_seed:
            if self.once is None or not Path(self.once).exists():
                if self.once is not None:
                    Path(self.once).touch()
                os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.02)
        return {a: np.zeros(3) for a in observations}


class DiesOnSeed1(SlowPolicy):
    die_on_seed = 1


def test_a_worker_that_dies_costs_only_its_episode(tmp_path):
    pols = {"dies": PolicySpec("dies", "test_scoreboard:DiesOnSeed1", dry_run=False)}
    board = _board(tmp_path, seeds="0-3", workers=2, policy_registry=pols,
                   task_registry={"toy": TaskSpec("toy", "platoon_v0", {"max_steps": 5})})
    errors = {r["seed"]: r["error"] for r in board.records}
    assert sorted(errors) == [0, 1, 2, 3]
    assert errors[1].startswith("WorkerDied") and [errors[s] for s in (0, 2, 3)] == [None] * 3
    assert board.aggregates["toy"]["dies"]["errors"] == 1


def test_a_worker_killed_once_is_retried(tmp_path, monkeypatch):
    marker = tmp_path / "killed"
    # the workers import this module afresh: the marker goes through the environment
    monkeypatch.setenv("SCOREBOARD_TEST_ONCE", str(marker))
    pols = {"once": PolicySpec("once", "test_scoreboard:DiesOnceViaEnv", dry_run=False)}
    scen = {"toy": TaskSpec("toy", "platoon_v0", {"max_steps": 5})}
    board = _board(tmp_path / "run", seeds="0-3", workers=2, policy_registry=pols, task_registry=scen)
    assert marker.exists()                                          # a worker did die
    assert all(r["error"] is None for r in board.records) and len(board.records) == 4


class DiesOnceViaEnv(SlowPolicy):
    die_on_seed = 1

    @property
    def once(self):
        return os.environ["SCOREBOARD_TEST_ONCE"]


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            if int(stat.read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(stat.parent.name))
        except (OSError, ValueError, IndexError):
            pass
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_die_with_a_killed_parent(tmp_path):
    started = tmp_path / "started"
    started.mkdir()
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(TESTS)!r})
        from test_scoreboard import _board, PolicySpec, TaskSpec
        _board({str(tmp_path / "run")!r}, seeds="0-9", workers=2,
               policy_registry={{"slow": PolicySpec("slow", "test_scoreboard:SlowPolicy", dry_run=False)}},
               task_registry={{"toy": TaskSpec("toy", "platoon_v0", {{"max_steps": 200}})}})
    """)
    env = dict(os.environ, SCOREBOARD_TEST_STARTED=str(started))
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=TESTS.parent, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while len(list(started.iterdir())) < 2 and time.monotonic() < deadline:   # both workers busy
            time.sleep(0.05)
        children = _children(proc.pid)
        assert len(children) >= 2, children                 # two workers (+ the resource tracker)
        proc.kill()
        proc.wait(10)
        deadline = time.monotonic() + 10
        while any(_alive(c) for c in children) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not [c for c in children if _alive(c)]
    finally:
        proc.kill()


def test_cli_shares_the_training_grammar():
    """``--out-dir`` and ``--address`` as in every training CLI (the old names still work)."""
    from satenv.bench.scoreboard.cli import build_parser

    parse = build_parser().parse_args
    assert parse(["--out-dir", "a"]).out == parse(["--out", "a"]).out == "a"
    assert parse(["--address", "h:1"]).ray_address == parse(["--ray-address", "h:1"]).ray_address == "h:1"


def test_perturbed_scenarios_run_and_fill_the_robustness_table(tmp_path):
    """``<task>@<perturbation>`` selects the task under each of its perturbations that match; the
    board's robustness section lists them beside the nominal task."""
    from satenv import tasks
    from satenv.bench.scoreboard.report import robustness

    name = "platoon-pereira2022-random"
    task = tasks.get(name)
    reg = {name: TaskSpec(name, task.env_id, {**task.env_kwargs, "max_steps": 5})}
    board = _board(tmp_path / "b", seeds="900000-900001", task_registry=reg, policies="zero",
                   scenarios=f"{name},{name}@nav-*,{name}@thrust-80")
    table = robustness(board)[name]["zero"]
    assert set(table) == {"nominal", "nav-0.1m", "nav-1m", "thrust-80"}
    assert all(cell["n"] == 2 for cell in table.values())
    assert "## Robustness" in board.markdown and f"{name}@nav-1m" in board.aggregates
    assert all("@" not in s for s in board.summary.get("reference", {}))   # perturbed ones stay out
