"""Crash windows of the run folders (:mod:`training.runfolder`): a run killed at each write
boundary, then resumed to the end, finishes with exactly the rounds / results of an uninterrupted
run with the same seed (none lost, none duplicated; weights bitwise equal).

The boundaries are counted by :func:`training.runfolder.boundary` (``SATENV_WRITE_LOG``) in an
uninterrupted run; run ``k`` is then ended at boundary ``k`` (``SATENV_CRASH_AT_WRITE=k``). The
default tests crash in-process (:class:`Killed`, raised where ``os._exit`` would end the process,
unwinding without the error clean-up of a write, so the disk is left as a kill leaves it); the
``slow`` ones kill real subprocesses with ``os._exit`` at every boundary.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from training import runfolder

TESTS = Path(__file__).resolve().parent
TIMING_KEYS = ("collect_s", "fit_s", "session_wall_s", "compute_ms_per_agent", "compute_ms_per_decision",
               "train_wall_s_this_session", "wall_s")
"""Measured times: the only entries a resumed run may differ in."""


def untimed(data):
    """``data`` (JSON) without its :data:`TIMING_KEYS`, at any depth."""
    if isinstance(data, dict):
        return {k: untimed(v) for k, v in data.items() if k not in TIMING_KEYS}
    if isinstance(data, list):
        return [untimed(v) for v in data]
    return data


class Killed(BaseException):
    """An in-process stand-in for ``kill -9`` at a write boundary."""


def _raise_killed() -> None:
    raise Killed


# ------------------------------------------------------------------------ the writer itself
def test_a_write_is_whole_or_absent_and_a_folder_swap_recovers(tmp_path, monkeypatch):
    monkeypatch.setattr(runfolder, "crash", _raise_killed)
    path = tmp_path / "h.json"
    runfolder.write_json(path, [1])
    for k in (1, 2):                                    # before and after the rename
        runfolder.reset_boundaries()
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        with pytest.raises(Killed):
            runfolder.write_json(path, [1, 2])
        assert json.loads(path.read_text()) == ([1] if k == 1 else [1, 2])
        runfolder.write_json(path, [1])
    folder = tmp_path / "best"
    for k in range(1, 4):                               # staged, moved aside, in place
        runfolder.reset_boundaries()
        monkeypatch.delenv(runfolder.CRASH_ENV)
        tmp = runfolder.staging(folder)
        (tmp / "a").write_text("old")
        runfolder.replace_folder(tmp, folder)
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        runfolder.reset_boundaries()
        tmp = runfolder.staging(folder)
        (tmp / "a").write_text("new")
        with pytest.raises(Killed):
            runfolder.replace_folder(tmp, folder)
        assert runfolder.recover_folder(folder) == folder
        assert (folder / "a").read_text() == ("new" if k == 3 else "old")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["best", "h.json"]
    with pytest.raises(runfolder.RunFolderError, match="h.json: not valid JSON .* expected a list"):
        (tmp_path / "h.json").write_text('[{"round": 0')
        runfolder.read_json(tmp_path / "h.json", "a list")


# ------------------------------------------------------------------------ DAgger
def tiny_dagger(monkeypatch_setattr) -> tuple:
    """A DAgger run of seconds: the platoon (pereira2022) cut to 12 steps and a proportional
    expert (deterministic); returns ``(run, config)``."""
    import satenv
    from training.recipes import dagger

    def make_envs(system):
        make = satenv.make
        kw = {"preset": "pereira2022", "max_steps": 12}
        return (make("platoon_v0", randomize=True, terminate_on_collision=False, **kw),
                make("platoon_v0", terminate_on_collision=False, **kw),
                make("platoon_v0", randomize=True, **kw), make("platoon_v0", **kw))

    class Expert:
        def __init__(self, env):
            self.env = env

        def reset(self, seed=None):
            pass

        def act(self, obs):
            return {a: np.clip(-0.05 * np.asarray(o[:3], dtype=np.float64), -1, 1).astype(np.float32)
                    for a, o in obs.items()}

    monkeypatch_setattr(dagger, "make_envs", make_envs)
    monkeypatch_setattr(dagger, "make_expert", lambda system, env, options: Expert(env))
    cfg = dagger.DaggerConfig(system="platoon-pereira2022", rounds=2, round0_episodes=2, episodes_per_round=1,
                              val_seeds=(700_000,), net_arch=(16,), epochs=1, batch_size=64,
                              paper_start_share=0.3, expert_options={})
    return dagger.run, cfg


def dagger_result(run_dir: Path) -> tuple[list, dict[str, bytes]]:
    """What a finished run leaves: its history (timings aside) and its files' bytes (the labels'
    arrays, the rounds' weights and normalisation)."""
    history = untimed(json.loads((run_dir / "history.json").read_text()))
    files = {}
    for k in range(len(history)):
        with np.load(run_dir / "labels" / f"round_{k:04d}.npz") as d:
            files[f"labels {k}"] = b"".join(d[name].tobytes() for name in sorted(d.files))
        for name in ("weights.safetensors", "obs_norm.json"):
            files[f"round {k} {name}"] = (run_dir / "rounds" / f"{k:04d}" / name).read_bytes()
    return history, files


def boundaries(run, tmp_path: Path, monkeypatch) -> list[str]:
    """The write boundaries of an uninterrupted ``run()`` (labels in order)."""
    log = tmp_path / "boundaries.log"
    monkeypatch.setenv(runfolder.LOG_ENV, str(log))
    runfolder.reset_boundaries()
    run()
    monkeypatch.delenv(runfolder.LOG_ENV)
    return log.read_text().splitlines()


def kill_and_resume(run, k: int, monkeypatch) -> None:
    """``run()`` killed at boundary ``k``, then resumed to the end."""
    monkeypatch.setattr(runfolder, "crash", _raise_killed)
    monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
    runfolder.reset_boundaries()
    with pytest.raises(Killed):
        run()
    monkeypatch.delenv(runfolder.CRASH_ENV)
    runfolder.reset_boundaries()
    run()


def _dagger_sweep(tmp_path, monkeypatch, last_round_only: bool) -> None:
    run, cfg = tiny_dagger(monkeypatch.setattr)
    ref = tmp_path / "ref"
    labels = boundaries(lambda: run(cfg, ref), tmp_path, monkeypatch)
    reference = dagger_result(ref)
    rounds = cfg.rounds
    assert [h["round"] for h in reference[0]] == list(range(rounds))
    per_round = (len(labels) - 2) // rounds                # config.json, then the same writes per round
    assert per_round >= 8 and len(labels) == 2 + rounds * per_round, labels
    first = len(labels) - per_round + 1 if last_round_only else 1
    lost = duplicated = differ = 0
    for k in range(first, len(labels) + 1):
        out = tmp_path / f"k{k}"
        kill_and_resume(lambda: run(cfg, out), k, monkeypatch)   # noqa: B023 - called at once
        history, files = dagger_result(out)
        done = [h["round"] for h in history]
        lost += len(set(range(rounds)) - set(done))
        duplicated += len(done) - len(set(done))
        differ += (history, files) != reference
        assert (history, files) == reference, f"killed at boundary {k} ({labels[k - 1]})"
    assert (lost, duplicated, differ) == (0, 0, 0)


def test_dagger_killed_at_each_write_of_a_round_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    """Every boundary of the last round (the writes of every round are the same)."""
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=True)
    capsys.readouterr()


@pytest.mark.slow
def test_dagger_killed_at_every_write_boundary_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=False)
    capsys.readouterr()


def test_dagger_resume_reads_the_history_not_the_label_files(tmp_path, monkeypatch, capsys):
    """Labels of an unfinished round (written before the kill) are not a finished round."""
    run, cfg = tiny_dagger(monkeypatch.setattr)
    ref, out = tmp_path / "ref", tmp_path / "out"
    run(cfg, ref)
    from dataclasses import replace

    run(replace(cfg, rounds=1), out)
    (out / "labels" / "round_0001.npz").write_bytes(b"torn")      # an unfinished round's leftovers
    (out / "labels" / "round_0002.npz").write_bytes(b"torn")
    run(cfg, out)
    assert dagger_result(out) == dagger_result(ref)
    (out / "history.json").write_text('[{"round": 0}, {"rou')    # a torn history (not written by us)
    with pytest.raises(runfolder.RunFolderError, match="history.json: not valid JSON"):
        run(cfg, out)
    capsys.readouterr()


# ------------------------------------------------------------------------ real kills (slow)
SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
import pytest
from pathlib import Path
from test_crash_windows import tiny_dagger
run, cfg = tiny_dagger(lambda obj, name, value: setattr(obj, name, value))
run(cfg, Path({out!r}))
"""


@pytest.mark.slow
def test_dagger_killed_for_real_at_every_write_boundary(tmp_path):
    """``os._exit`` (no clean-up at all) at every boundary of a subprocess, then a resume."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS)]),
           "OMP_NUM_THREADS": "1"}

    def go(out: Path, **extra: str) -> int:
        code = textwrap.dedent(SCRIPT.format(tests=str(TESTS), out=str(out)))
        return subprocess.run([sys.executable, "-c", code], env={**env, **extra}, cwd=TESTS.parent,
                              capture_output=True, timeout=600).returncode

    log = tmp_path / "log"
    assert go(tmp_path / "ref", **{runfolder.LOG_ENV: str(log)}) == 0
    reference = dagger_result(tmp_path / "ref")
    n = len(log.read_text().splitlines())
    for k in range(1, n + 1):
        out = tmp_path / f"k{k}"
        assert go(out, **{runfolder.CRASH_ENV: str(k)}) == runfolder.CRASH_EXIT_CODE
        assert go(out) == 0
        assert dagger_result(out) == reference, f"killed at boundary {k}"
