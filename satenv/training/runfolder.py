"""Crash-safe writes of a run folder: a kill at any moment leaves the previous consistent state.

Every file is written to a temporary name beside it, flushed to disk (``fsync``) and renamed into
place (:func:`write_bytes`, :func:`write_text`, :func:`write_json`, :func:`save_with`); a folder
of several files (a policy folder, a checkpoint) is written whole under a temporary name and
swapped in (:func:`replace_folder`; :func:`recover_folder` finishes or undoes a swap a kill
interrupted). A run writes its own record of progress (e.g. ``history.json``) last in each step, so
that resume reads what the last complete step wrote and never counts files. The scoreboard's
append-only episode log (:class:`satenv.bench.scoreboard.runner.EpisodeLog`) is the same idea for
one growing file.

Crash windows, for tests: every write boundary (a file written but not yet in place, a file in
place, a folder swap half done) calls :func:`boundary`. With the environment variable
``SATENV_CRASH_AT_WRITE=k`` the process ends with ``os._exit(CRASH_EXIT_CODE)`` at its ``k``-th
boundary (1-based), exactly as a ``kill -9`` there would leave the disk; with
``SATENV_WRITE_LOG=<file>`` each boundary appends its label to that file (how many there are, for
a harness that kills at each one).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["CRASH_EXIT_CODE", "RunFolderError", "boundary", "crash", "latest_checkpoint", "read_json",
           "recover_folder", "replace_folder", "resumable", "resume_checkpoint", "reset_boundaries", "save_with",
           "staging", "write_bytes", "write_json", "write_text"]

CRASH_EXIT_CODE = 86
"""Exit status of a process ended at a write boundary by ``SATENV_CRASH_AT_WRITE``."""
CRASH_ENV = "SATENV_CRASH_AT_WRITE"
LOG_ENV = "SATENV_WRITE_LOG"
_TMP = ".tmp"
_OLD = ".old"
_count = [0]


class RunFolderError(ValueError):
    """A run folder's file is missing, torn or malformed: the message names the file and what resume
    expected (a ``ValueError``)."""


def boundary(label: str) -> None:
    """A write boundary (module docstring): count it, log it, and end the process here if asked."""
    _count[0] += 1
    log = os.environ.get(LOG_ENV)
    if log:
        with open(log, "a") as fh:
            fh.write(f"{_count[0]} {label}\n")
    at = os.environ.get(CRASH_ENV)
    if at and at.strip().isdigit() and int(at) == _count[0]:
        crash()


def crash() -> None:
    """End the process at once, as ``kill -9`` would (no cleanup, no flush); a test may replace it
    (e.g. by raising an exception that unwinds without cleanup code, to crash in-process)."""
    os._exit(CRASH_EXIT_CODE)


def reset_boundaries() -> None:
    """Count write boundaries from 0 again (a new run in the same process)."""
    _count[0] = 0


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:   # some filesystems do not sync directories
        pass
    finally:
        os.close(fd)


def _tmp_name(path: Path) -> Path:
    # the suffix kept (writers that infer a format from it); one writer per run folder: a killed
    # leftover is overwritten
    return path.with_name(f".{path.stem}{_TMP}{path.suffix}")


def save_with(path: str | Path, write: Callable[[Path], Any]) -> Path:
    """``write(tmp)`` writes the file's content to the temporary path ``tmp``; it is then synced
    and renamed to ``path`` (a kill leaves the old file or the new one, never a torn one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_name(path)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        boundary(f"written {path.name}")
        os.replace(tmp, path)
    except Exception:     # an error, not a kill (a kill leaves the temporary file, overwritten next time)
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)
    boundary(f"in place {path.name}")
    return path


def write_bytes(path: str | Path, data: bytes) -> Path:
    """``data`` to ``path`` atomically (:func:`save_with`)."""
    return save_with(path, lambda tmp: tmp.write_bytes(data))


def write_text(path: str | Path, text: str) -> Path:
    """``text`` to ``path`` atomically (:func:`save_with`)."""
    return write_bytes(path, text.encode())


def write_json(path: str | Path, data: Any, *, indent: int | None = 1, **dumps: Any) -> Path:
    """``data`` as JSON (one trailing newline) to ``path`` atomically (:func:`save_with`)."""
    return write_text(path, json.dumps(data, indent=indent, **dumps) + "\n")


def read_json(path: str | Path, what: str) -> Any:
    """The JSON in ``path``, a regular file of at most :data:`satenv.training.trust.MAX_JSON_BYTES`
    (a link or a bigger file is refused before reading: :func:`satenv.training.trust.read_json`);
    a missing, torn or malformed file is a :class:`RunFolderError` naming it and ``what`` it should
    hold (never a raw ``JSONDecodeError``)."""
    from satenv.training import trust

    path = Path(path)
    if not os.path.lexists(path):
        raise RunFolderError(f"{path}: missing; expected {what}")
    try:
        return trust.read_json(path.parent, path.name)
    except trust.UntrustedDataError as err:
        raise RunFolderError(f"{err}; expected {what}") from None


def staging(folder: str | Path) -> Path:
    """An empty temporary folder beside ``folder`` to write its new content into, then
    :func:`replace_folder` (a leftover one from a killed write is removed first)."""
    folder = Path(folder)
    tmp = folder.with_name(folder.name + _TMP)
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    return tmp


def replace_folder(tmp: str | Path, folder: str | Path) -> Path:
    """Swap the complete folder ``tmp`` (from :func:`staging`) in as ``folder``: its files are
    synced, the old folder renamed aside, ``tmp`` renamed into place, the old one removed. A kill in
    between is finished or undone by :func:`recover_folder` (the old content or the new, whole)."""
    tmp, folder = Path(tmp), Path(folder)
    for f in tmp.rglob("*"):
        if f.is_file() and not f.is_symlink():
            with open(f, "rb+") as fh:
                os.fsync(fh.fileno())
    _fsync_dir(tmp)
    boundary(f"staged {folder.name}/")
    old = folder.with_name(folder.name + _OLD)
    if old.exists():
        shutil.rmtree(old)
    if folder.exists():
        folder.rename(old)
        boundary(f"moved aside {folder.name}/")
    tmp.rename(folder)
    _fsync_dir(folder.parent)
    boundary(f"in place {folder.name}/")
    if old.exists():
        shutil.rmtree(old)
    return folder


def recover_folder(folder: str | Path) -> Path | None:
    """Finish or undo a :func:`replace_folder` a kill interrupted: the folder if it exists (a
    leftover aside or staging copy removed), else the old content put back, else ``None``."""
    folder = Path(folder)
    old, tmp = folder.with_name(folder.name + _OLD), folder.with_name(folder.name + _TMP)
    if not folder.exists() and old.exists():
        old.rename(folder)
    for leftover in (old, tmp):
        if leftover.exists():
            shutil.rmtree(leftover)
    return folder if folder.exists() else None


def latest_checkpoint(out: str | Path, marker: str) -> tuple[int, Path] | None:
    """``(steps, folder)`` of the newest complete ``out/checkpoints/step_<N>`` (one holding the file
    ``marker``), or ``None``; a checkpoint swap a kill interrupted is finished or undone first."""
    checkpoints = Path(out) / "checkpoints"
    for p in checkpoints.glob("step_*"):
        if p.name.endswith((_OLD, _TMP)):
            recover_folder(p.with_name(p.name.removesuffix(_OLD).removesuffix(_TMP)))
    found = [(int(p.name[5:]), p) for p in checkpoints.glob("step_*")
             if p.name[5:].isdigit() and (p / marker).is_file()]
    return max(found) if found else None


def resume_checkpoint(out: str | Path, resume: bool, marker: str) -> tuple[int, Path] | None:
    """The checkpoint a trainer's run continues from (:func:`latest_checkpoint`), the one resume
    rule: ``--resume`` on a folder without a checkpoint starts the run fresh and says so on stderr
    (a loop that always passes ``--resume`` is never stuck); without ``--resume``, a folder that has
    checkpoints is refused (nothing is overwritten)."""
    ckpt = latest_checkpoint(out, marker)
    if resume and ckpt is None:
        print(f"--resume: no checkpoint under {Path(out) / 'checkpoints'}: starting the run fresh", file=sys.stderr,
              flush=True)
    if not resume and ckpt is not None:
        raise RunFolderError(f"{out} already has checkpoints; pass --resume to continue or choose another --out-dir")
    return ckpt if resume else None


def resumable(out: str | Path) -> bool:
    """Whether ``--resume`` finds the run's ``config.json`` in ``out``; without it (no run yet, or one
    killed before writing it) the run starts fresh from the flags given, and says so on stderr."""
    if os.path.lexists(Path(out) / "config.json"):
        return True
    print(f"--resume: {Path(out) / 'config.json'} does not exist (no run, or one stopped before writing it): "
          "starting the run fresh from the flags given", file=sys.stderr, flush=True)
    return False
