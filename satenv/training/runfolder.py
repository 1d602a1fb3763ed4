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
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["CRASH_EXIT_CODE", "RunFolderError", "boundary", "crash", "read_json", "recover_folder",
           "replace_folder", "reset_boundaries", "save_with", "staging", "write_bytes", "write_json", "write_text"]

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
