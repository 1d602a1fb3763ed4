"""Kills and resumes of the writers outside the imitation engine: the Minari datasets, safety_alone,
the reference grid's log and ``satenv train`` under an "always --resume" loop.

Each writer is killed in-process at a write boundary (:mod:`satenv.training.runfolder`, the
``Killed`` stand-in of ``tests/test_crash_windows.py``) or after its k-th appended log line (the
scoreboard's :class:`~satenv.bench.scoreboard.runner.EpisodeLog`, a torn half line included), then
the same command runs again and must end equal to an uninterrupted run (measured times aside).
Real ``kill -9`` runs of the datasets writer: ``python tests/kill_resume.py --target datasets``
(the slow test here).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_crash_windows import (
    Killed,
    _raise_killed,
    boundaries,
    canonical,
    kill_and_resume,
    untimed,
)

from satenv.training import runfolder

TESTS = Path(__file__).resolve().parent
SYSTEM = "platoon-pereira2023"   # the DMPC flies an episode in a fraction of a second


def _labels(run, tmp_path: Path, monkeypatch) -> list[str]:
    """The write boundaries of an uninterrupted ``run()``, without their counts."""
    return [label.split(" ", 1)[1] for label in boundaries(run, tmp_path, monkeypatch)]


def _kill_after_appends(monkeypatch, n: int, torn: bool) -> None:
    """The scoreboard's log killed at its ``n``-th append: the line written whole (or half, ``torn``)."""
    from satenv.bench.scoreboard import runner

    real, count = runner.EpisodeLog.append, [0]

    def append(self, record):
        count[0] += 1
        if count[0] == n:
            if torn:
                os.write(self._fd, json.dumps(record).encode()[:40])
            else:
                real(self, record)
            raise Killed
        real(self, record)

    monkeypatch.setattr(runner.EpisodeLog, "append", append)


# ------------------------------------------------------------------------ Minari datasets
def _dataset(root: Path) -> str:
    """What a written dataset holds (every episode's arrays and infos, the card), as text."""
    import minari

    from satenv.bench.learning import datasets

    os.environ["MINARI_DATASETS_PATH"] = str(root)
    ds = minari.load_dataset(datasets.dataset_id(SYSTEM))
    eps = [{"id": int(e.id), "obs": np.asarray(e.observations).tobytes().hex(),
            "act": np.asarray(e.actions).tobytes().hex(), "rew": np.asarray(e.rewards).tobytes().hex(),
            "state": np.asarray(e.infos["state"]).tobytes().hex()} for e in ds.iterate_episodes()]
    return canonical({"episodes": eps, "card": ds.storage.metadata.get("description"),
                      "seeds": [datasets.episode_seed(ds, e["id"]) for e in eps]})


def _manifest(path: Path) -> str:
    entries = json.loads(path.read_text())
    return canonical({k: {f: v for f, v in e.items() if f != "wall_s"} for k, e in entries.items()})


def _write(tmp_path: Path, name: str):
    from satenv.bench.learning import datasets

    def go():
        os.environ["MINARI_DATASETS_PATH"] = str(tmp_path / name)
        datasets.write(SYSTEM, 2, progress=False, manifest=tmp_path / f"{name}.json", cache=tmp_path / f"{name}-cache")
    return go


def write_dataset(out: Path) -> None:
    """The tiny dataset (2 episodes) written into ``out`` (Minari's root, cache and manifest there)."""
    _write(out, "root")()


def dataset_result(out: Path) -> tuple[str, str]:
    """What :func:`write_dataset` left in ``out``: the dataset and the manifest (wall time aside)."""
    return _dataset(out / "root"), _manifest(out / "root.json")


def _datasets_sweep(tmp_path, monkeypatch, pick) -> int:
    pytest.importorskip("minari")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))   # restored after the test
    _write(tmp_path, "ref")()                         # a dataset already there: a kill keeps it or the new one
    labels = _labels(_write(tmp_path, "ref"), tmp_path, monkeypatch)
    reference = _dataset(tmp_path / "ref"), _manifest(tmp_path / "ref.json")
    assert [label for label in labels if label.endswith("/")] == [f"{w} dmpc-v0/" for w in
                                                                   ("staged", "moved aside", "in place")], labels
    swept = 0
    for k in pick(labels):
        name = f"k{k}"
        shutil.copytree(tmp_path / "ref", tmp_path / name)
        shutil.copyfile(tmp_path / "ref.json", tmp_path / f"{name}.json")
        kill_and_resume(_write(tmp_path, name), k, monkeypatch)
        assert (_dataset(tmp_path / name), _manifest(tmp_path / f"{name}.json")) == reference, \
            f"killed at boundary {k} ({labels[k - 1]})"
        swept += 1
    return swept


def test_datasets_killed_at_the_folder_swap_resume_to_the_same_dataset(tmp_path, monkeypatch, capsys):
    """The windows of the swap (staged, the old dataset moved aside) and the manifest's write (every
    boundary: the slow test)."""
    def pick(labels):
        return [i for i, label in enumerate(labels, 1) if label in ("staged dmpc-v0/", "moved aside dmpc-v0/",
                                                                       "written ref.json")]
    assert _datasets_sweep(tmp_path, monkeypatch, pick) == 3
    capsys.readouterr()


@pytest.mark.slow
def test_datasets_killed_at_every_write_boundary_resume_to_the_same_dataset(tmp_path, monkeypatch, capsys):
    _datasets_sweep(tmp_path, monkeypatch, lambda labels: range(1, len(labels) + 1))
    capsys.readouterr()


def test_a_kill_inside_minari_leaves_the_old_dataset_and_the_next_write_finishes(tmp_path, monkeypatch, capsys):
    """A kill inside ``minari.create_dataset_from_buffers`` (after it made the dataset's folder, before
    its metadata) used to block every later write; now the half-written copy is in the staging root,
    the old dataset stays readable, and the next write removes the leftover, says so and finishes."""
    minari = pytest.importorskip("minari")
    import minari.utils as mu

    from satenv.bench.learning import datasets

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "root"))
    go = _write(tmp_path, "root")
    go()
    before = _dataset(tmp_path / "root")

    def killed(*args, **kwargs):
        raise Killed
    real = mu._generate_dataset_metadata
    monkeypatch.setattr(mu, "_generate_dataset_metadata", killed)
    with pytest.raises(Killed):
        go()
    staged = tmp_path / "root" / datasets.STAGING / datasets.dataset_id(SYSTEM)
    assert staged.is_dir() and not (staged / "data" / "metadata.json").exists()
    assert _dataset(tmp_path / "root") == before                 # the old dataset, whole
    assert datasets.dataset_id(SYSTEM) in minari.list_local_datasets()
    monkeypatch.setattr(mu, "_generate_dataset_metadata", real)
    capsys.readouterr()
    go()
    assert "incomplete dataset folder" in capsys.readouterr().err
    assert not staged.exists() and _dataset(tmp_path / "root") == before


def test_an_incomplete_dataset_folder_in_place_is_named_and_removed(tmp_path, monkeypatch, capsys):
    """A folder an in-place writer left (``data/`` without ``metadata.json``) is removed, with a line."""
    pytest.importorskip("minari")
    from satenv.bench.learning import datasets

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "root"))
    torn = tmp_path / "root" / datasets.dataset_id(SYSTEM) / "data"
    torn.mkdir(parents=True)
    (torn / "episode_0").mkdir()
    _write(tmp_path, "root")()
    err = capsys.readouterr().err
    assert f"removed {torn.parent}" in err and "incomplete dataset folder" in err
    _write(tmp_path, "ref")()
    assert _dataset(tmp_path / "root") == _dataset(tmp_path / "ref")


@pytest.mark.slow
@pytest.mark.parametrize("args", [["--target", "datasets"], ["--target", "datasets", "--random", "4"],
                                  ["--target", "safety"], ["--target", "safety", "--random", "4"],
                                  ["--target", "train", "--random", "4"]])
def test_writers_killed_for_real_resume_to_the_uninterrupted_run(args):
    """``kill_resume.py``: a real process ended at every write boundary, or SIGKILLed at random
    moments, then the same command (``train``: always with ``--resume``) to the end."""
    done = subprocess.run([sys.executable, str(TESTS / "kill_resume.py"), *args], cwd=TESTS.parent,
                          capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]


# ------------------------------------------------------------------------ safety_alone
POLICY = "satenv/training/policies/platoon_tplf_safe_distill"


def _safety(out: Path) -> None:
    from satenv.bench import safety_alone

    safety_alone.main(["--entry", f"{SYSTEM}={POLICY}", "--seeds", "2", "--controller-seeds", "1", "--out", str(out)])


def _safety_result(out: Path) -> str:
    res = json.loads((out / "safety_alone.json").read_text())
    res.pop("command")
    return canonical(untimed(res))


@pytest.fixture(scope="module")
def safety_reference(tmp_path_factory):
    pytest.importorskip("torch")
    out = tmp_path_factory.mktemp("safety_ref")
    runfolder.reset_boundaries()
    _safety(out)
    return _safety_result(out)


@pytest.mark.parametrize("n, torn", [(1, True), (3, False), (4, True)])
def test_safety_alone_killed_between_episodes_resumes_to_the_same_json(tmp_path, monkeypatch, safety_reference,
                                                                        n, torn):
    """Killed at the n-th cached episode (its line whole or torn): the same command ends equal."""
    with monkeypatch.context() as m:
        _kill_after_appends(m, n, torn)
        with pytest.raises(Killed):
            _safety(tmp_path)
    assert not (tmp_path / "safety_alone.json").exists()
    with pytest.warns(UserWarning, match="torn") if torn else contextlib.nullcontext():
        _safety(tmp_path)
    assert _safety_result(tmp_path) == safety_reference


def _safety_sweep(tmp_path, monkeypatch, safety_reference, picks) -> None:
    labels = _labels(lambda: _safety(tmp_path / "ref"), tmp_path, monkeypatch)
    assert [label.split()[-1] for label in labels] == ["safety_alone.json"] * 2 + ["safety_alone.png"] * 2, labels
    for k in picks:
        out = tmp_path / f"k{k}"
        kill_and_resume(lambda: _safety(out), k, monkeypatch)   # noqa: B023 - called at once
        assert _safety_result(out) == safety_reference, f"killed at {labels[k - 1]}"
        assert (out / "safety_alone.png").stat().st_size > 0
        assert not list(out.glob(".*.tmp*"))


def test_safety_alone_killed_while_writing_its_json_and_plot_resumes_to_the_same_json(tmp_path, monkeypatch,
                                                                                     safety_reference):
    """Killed with each file written aside, not yet in place (every boundary: the slow test)."""
    _safety_sweep(tmp_path, monkeypatch, safety_reference, (1, 3))


@pytest.mark.slow
def test_safety_alone_killed_at_each_write_boundary_resumes_to_the_same_json(tmp_path, monkeypatch, safety_reference):
    _safety_sweep(tmp_path, monkeypatch, safety_reference, range(1, 5))


# ------------------------------------------------------------------------ the reference grid's log
def _grid(monkeypatch):
    """One grid run on the zero policy at every checkpoint (as tests/test_reference_results.py)."""
    from satenv.bench.learning import grid as G
    from satenv.bench.learning import trainers

    def fake(run, checkpoint, finish):
        from satenv import baselines
        for k, steps in enumerate(run.checkpoints):
            checkpoint(k, steps, 0.1 * (k + 1), lambda env: baselines.make("zero", env))
        finish()

    monkeypatch.setattr(trainers, "train", fake)
    monkeypatch.setattr(G, "FINAL_TEST_SEEDS", 2)
    monkeypatch.setattr(G, "CURVE_TEST_SEEDS", 1)
    monkeypatch.setattr(G, "VALIDATION_SEEDS", 1)
    return lambda log: G.Run(SYSTEM, "ppo", False, 0, str(log), budget_override=5000, rung="platoon-tplf30-rung1-near")


GRID_TIMES = ("wall_s", "eval_s", "load_avg_1m")


def _grid_result(log: Path, out: Path) -> str:
    from satenv.bench.learning import results

    results.write_results(log, out)
    data = json.loads(out.read_text())

    def strip(v):
        if isinstance(v, dict):
            return {k: strip(x) for k, x in v.items() if k not in GRID_TIMES and k not in ("compute_ms_per_agent",
                                                                                          "compute_ms_per_decision")}
        if isinstance(v, list):
            return [strip(x) for x in v]
        return v
    return canonical(strip(data))


@pytest.mark.parametrize("n, torn", [(1, False), (3, True), (5, True), (5, False), (6, True)])
def test_grid_killed_between_evaluations_resumes_to_the_same_results(tmp_path, monkeypatch, n, torn):
    from satenv.bench.learning import grid as G
    from satenv.bench.learning import runner

    run = _grid(monkeypatch)
    ref_log = tmp_path / "ref.jsonl"
    runner.run_one(run(ref_log))
    reference = _grid_result(ref_log, tmp_path / "ref.json")
    log = tmp_path / "log.jsonl"
    with monkeypatch.context() as m:
        _kill_after_appends(m, n, torn)
        with pytest.raises(Killed):
            runner.run_one(run(log))
    with pytest.warns(UserWarning, match="torn") if torn else contextlib.nullcontext():
        runner.read_log(log, repair=True)                       # what the same `satenv results run` does first
    runner.run_one(run(log))
    assert runner.done_runs([run(log)], log) == {run(log)}
    assert len(runner.read_log(log)) == G.CHECKPOINTS + 1   # each checkpoint and the selected one
    assert _grid_result(log, tmp_path / "results.json") == reference


def test_results_json_is_whole_or_absent(tmp_path, monkeypatch):
    from satenv.bench.learning import runner

    run = _grid(monkeypatch)
    log = tmp_path / "log.jsonl"
    runner.run_one(run(log))
    out = tmp_path / "results.json"
    reference = _grid_result(log, out)
    for k in (1, 2):     # written aside, then in place
        out.write_text("old\n")
        monkeypatch.setattr(runfolder, "crash", _raise_killed)
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        runfolder.reset_boundaries()
        with pytest.raises(Killed):
            _grid_result(log, out)
        monkeypatch.delenv(runfolder.CRASH_ENV)
        if k == 1:
            assert out.read_text() == "old\n"                  # the old file, whole
        else:
            assert isinstance(json.loads(out.read_text()), dict)   # the new one, whole
        assert _grid_result(log, out) == reference


# ------------------------------------------------------------------------ satenv train, always --resume
def test_train_resume_before_config_json_starts_fresh_and_says_so(tmp_path, capsys):
    """An "always --resume" loop on a folder a kill left without config.json (or a new one)."""
    from satenv.training.config import parse_args

    cfg, opts = parse_args(["--resume", "--out-dir", str(tmp_path / "run"), "--budget", "96"], resume=True)
    assert opts.resume and cfg.out_dir == str(tmp_path / "run") and cfg.total_timesteps == 96
    assert "does not exist" in capsys.readouterr().err


def test_train_killed_before_its_first_checkpoint_resumes_with_resume_to_the_end(tmp_path, monkeypatch, capsys):
    """Killed before config.json is in place and before the first checkpoint, ``train(resume=True)``
    (the same command with ``--resume``) starts fresh and ends bitwise equal to the uninterrupted run."""
    from test_crash_windows import tiny_train_config, train_result

    from satenv.training.train import train

    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))
    labels = _labels(lambda: train(tiny_train_config(tmp_path / "ref")), tmp_path, monkeypatch)
    reference = train_result(tmp_path / "ref")
    config = next(i for i, label in enumerate(labels, 1) if label == "written config.json")
    first_ckpt = next(i for i, label in enumerate(labels, 1) if label.startswith("staged step_"))
    for k in (config, first_ckpt):
        out = tmp_path / f"k{k}"
        monkeypatch.setattr(runfolder, "crash", _raise_killed)
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        runfolder.reset_boundaries()
        with pytest.raises(Killed):
            train(tiny_train_config(out))
        monkeypatch.delenv(runfolder.CRASH_ENV)
        capsys.readouterr()
        train(tiny_train_config(out), resume=True)
        assert "starting the run fresh" in capsys.readouterr().err
        assert train_result(out) == reference, f"killed at {labels[k - 1]}"
