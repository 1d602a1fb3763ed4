"""Run-folder readers outside the imitation engine refuse links and cap what they read, before reading.

Hostile folders under ``tmp_path`` only: a member that is a link to ``/dev/zero`` (through a link in
``tmp_path``; no test points at a system file otherwise), a link out of the folder to a secret file,
a sparse file declaring a size past the cap. Each reader must refuse with a ``ValueError`` naming
the file, within seconds, with a small peak of traced memory, and never echo the outside content:
``satenv train`` (``--resume``'s ``config.json`` and ``eval_history.json``, ``--config``,
``--init-actor``), ``satenv.training.load`` of a folder that is itself a link out of its folder,
the datasets manifest and cached episodes, the scoreboard's episode log (``--policy`` loads through
``satenv.training.load``), safety_alone's entries and ``--folders-from``, the grid's log.
"""

from __future__ import annotations

import json
import os
import time
import tracemalloc
from pathlib import Path

import pytest

SECRET = "HOSTILE-SECRET-41c7"
PEAK = 2**24
"""Largest traced memory a refusal may take (16 MiB, far below what a read of the target would)."""
SECONDS = 5.0
"""Longest a refusal may take."""


@pytest.fixture
def zero(tmp_path) -> Path:
    """A link in ``tmp_path`` to ``/dev/zero`` (endless bytes)."""
    link = tmp_path / "zero"
    link.symlink_to("/dev/zero")
    return link


@pytest.fixture
def secret(tmp_path) -> Path:
    path = tmp_path / "outside" / "secret.json"
    path.parent.mkdir()
    path.write_text(json.dumps({"sha256": SECRET, "step": 1, "env_id": "platoon_v0"}))
    return path


def _hostile(kind: str, path: Path, zero: Path, secret: Path) -> None:
    """``path`` made hostile: a link to /dev/zero, a link out of its folder, or a sparse 3 GiB file."""
    if os.path.lexists(path):
        path.unlink()
    if kind == "zero":
        path.symlink_to(zero)
    elif kind == "outside":
        path.symlink_to(secret)
    else:
        with open(path, "wb") as f:
            f.truncate(3 * 2**30)


KINDS = ("zero", "outside", "huge")


def _refused(call, match: str) -> str:
    """``call()`` raises a ValueError (or exits with an error) matching ``match``, fast and small."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises((ValueError, SystemExit)) as info:
            call()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    message = str(info.value)
    assert time.perf_counter() - t0 < SECONDS and peak < PEAK, (time.perf_counter() - t0, peak)
    assert SECRET not in message
    import re
    assert re.search(match, message), message
    return message


REFUSAL = r"symbolic link|not a regular file|more than the cap|bytes, more than"


# ------------------------------------------------------------------------ satenv train
@pytest.mark.parametrize("kind", KINDS)
def test_train_resume_refuses_a_hostile_config_json(tmp_path, zero, secret, kind):
    from satenv.training.config import parse_args

    run = tmp_path / "run"
    run.mkdir()
    _hostile(kind, run / "config.json", zero, secret)
    _refused(lambda: parse_args(["--resume", "--out-dir", str(run)], resume=True), "config.json: .*(" + REFUSAL + ")")


@pytest.mark.parametrize("kind", KINDS)
def test_train_config_refuses_a_hostile_file(tmp_path, zero, secret, kind):
    from satenv.training.config import parse_args

    path = tmp_path / "config.json"
    _hostile(kind, path, zero, secret)
    _refused(lambda: parse_args(["--config", str(path)], resume=True), "--config: .*(" + REFUSAL + ")")


@pytest.mark.parametrize("kind", KINDS)
def test_train_resume_refuses_a_hostile_eval_history(tmp_path, zero, secret, kind):
    """``eval_history.json`` is read through :func:`satenv.training.runfolder.read_json`."""
    from satenv.training import runfolder
    from satenv.training.train import _read_history

    _hostile(kind, tmp_path / "eval_history.json", zero, secret)
    _refused(lambda: _read_history(tmp_path / "eval_history.json", 10), "eval_history.json: .*(" + REFUSAL + ")")
    assert issubclass(runfolder.RunFolderError, ValueError)


def test_init_actor_and_load_refuse_a_policy_folder_linked_out_of_its_folder(tmp_path):
    pytest.importorskip("torch")
    from audit_inputs import good_policy_folder

    from satenv import training
    from satenv.training.config import TrainConfig
    from satenv.training.train import init_policy

    good_policy_folder(tmp_path / "outside" / "policy")
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "policy").symlink_to(tmp_path / "outside" / "policy")
    _refused(lambda: training.load(runs / "policy"), "symbolic link out of its folder")
    cfg = TrainConfig(init_actor=str(runs / "policy"), net_arch=(8,), out_dir=str(tmp_path / "run"))
    _refused(lambda: init_policy(cfg), "init_actor: .*symbolic link out of its folder")
    (runs / "latest").symlink_to("policy")            # runs/latest -> runs/x stays followed ...
    with pytest.raises(training.PolicyLoadError, match="out of its folder"):
        training.load(runs / "latest")                # ... but not when x itself leads out
    good_policy_folder(runs / "x")
    (runs / "x-latest").symlink_to(runs / "x")
    training.load(runs / "x-latest")


# ------------------------------------------------------------------------ datasets
@pytest.mark.parametrize("kind", KINDS)
def test_datasets_manifest_is_refused_when_hostile(tmp_path, zero, secret, kind, capsys):
    from satenv.bench.learning import datasets

    path = tmp_path / "datasets.json"
    _hostile(kind, path, zero, secret)
    _refused(lambda: datasets._read_manifest(path), "--manifest: .*(" + REFUSAL + ")")
    _refused(lambda: datasets.main(["write", "--systems", "platoon-pereira2023", "--manifest", str(path),
                                    "--root", str(tmp_path / "root"), "--cache", str(tmp_path / "cache")]), "2")
    err = capsys.readouterr().err    # one error line, before any episode is recorded
    assert "argument --manifest" in err and SECRET not in err and not (tmp_path / "cache").exists()


@pytest.mark.parametrize("kind", ("zero", "huge"))
def test_a_hostile_cached_episode_is_refused_before_reading(tmp_path, zero, secret, kind):
    pytest.importorskip("minari")
    from satenv.bench.learning import datasets

    path = datasets._episode_path(tmp_path, "platoon-pereira2023", 0)
    path.parent.mkdir(parents=True)
    path.touch()
    _hostile(kind, path, zero, secret)
    _refused(lambda: datasets.load_episode(path), REFUSAL)
    assert datasets.drop_stale("platoon-pereira2023", [0], tmp_path) == [0]   # removed (the link, not its target)
    assert not os.path.lexists(path) and zero.exists()


# ------------------------------------------------------------------------ the scoreboard's and the grid's logs
@pytest.mark.parametrize("kind", KINDS)
def test_an_episode_log_is_refused_when_hostile(tmp_path, zero, secret, kind):
    from satenv.bench.learning import runner
    from satenv.bench.scoreboard.runner import MAX_LOG_BYTES, read_episodes

    assert MAX_LOG_BYTES < 3 * 2**30
    log = tmp_path / "episodes.jsonl"
    log.touch()
    _hostile(kind, log, zero, secret)
    _refused(lambda: read_episodes(log), REFUSAL)
    _refused(lambda: runner.read_log(log), REFUSAL)


# ------------------------------------------------------------------------ safety_alone
def test_safety_alone_refuses_a_linked_entry_and_a_hostile_folders_from(tmp_path, zero, secret, capsys):
    pytest.importorskip("torch")
    from audit_inputs import good_policy_folder

    from satenv.bench import safety_alone

    good_policy_folder(tmp_path / "outside" / "policy")
    (tmp_path / "policy").symlink_to(tmp_path / "outside" / "policy")
    _refused(lambda: safety_alone.main(["--entry", f"platoon-pereira2023={tmp_path / 'policy'}",
                                        "--out", str(tmp_path / "out")]), "2")
    assert "symbolic link" in capsys.readouterr().err
    for kind in KINDS:
        path = tmp_path / "earlier.json"
        path.touch()
        _hostile(kind, path, zero, secret)
        _refused(lambda: safety_alone.main(["--folders-from", str(path)]), "2")   # noqa: B023 - called at once
        err = capsys.readouterr().err
        assert "--folders-from" in err and SECRET not in err
