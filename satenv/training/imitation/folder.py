"""The run folder of imitation: where each file lives, and reading it as untrusted data.

``config.json``, ``labels/round_NNNN.npz`` (one round's rows), ``rounds/NNNN/`` (the round's
policy folder), ``history.json`` (written last in a round: the run's record of progress), and
``final/``. Writes go through :mod:`satenv.training.runfolder` (whole or absent). Every reader here
refuses a symbolic link (the run folder, ``labels/``, ``rounds/``, a round folder, a file), caps
the size from ``lstat`` before reading (:mod:`satenv.training.trust`), checks a label file's
array headers (no object arrays, sizes inside the file) before an array is built, and reports a
malformed file as a :class:`satenv.training.runfolder.RunFolderError` naming it.
"""

from __future__ import annotations

import os
import stat
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from satenv.training.runfolder import RunFolderError
from satenv.training.trust import UntrustedDataError, member, npz_headers, read_json

__all__ = ["MAX_HISTORY_BYTES", "MAX_LABEL_BYTES", "MAX_PICTURE_BYTES", "check_folder", "label_path", "read_history",
           "read_labels", "read_run_json", "round_folder", "save_labels"]

MAX_HISTORY_BYTES = 64 * 2**20
"""Cap on ``history.json`` (a round's entry is a few kB with its flown episodes)."""
MAX_LABEL_BYTES = 2**28
"""Cap on one label file, on disk and as its arrays declare them (256 MiB; a round of the largest
system writes a few MiB)."""
MAX_PICTURE_BYTES = 16 * 2**20
"""Cap on the learning curve copied into a policy folder."""
MAX_LABEL_ARRAYS = 32
"""Cap on the arrays of one label file (a round's rows have at most 14 columns)."""


def label_path(run: Path, k: int) -> Path:
    """Where round ``k``'s rows are saved."""
    return run / "labels" / f"round_{k:04d}.npz"


def round_folder(run: Path, k: int) -> Path:
    """Round ``k``'s policy folder."""
    return run / "rounds" / f"{k:04d}"


def check_folder(path: Path, what: str = "run folder") -> Path:
    """``path`` if it is a real folder (or absent); a symbolic link, or a file where a folder
    belongs, is a :class:`RunFolderError`."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as err:
        raise RunFolderError(f"{path}: cannot stat the {what} ({err.strerror})") from None
    if stat.S_ISLNK(st.st_mode):
        raise RunFolderError(f"{path}: the {what} is a symbolic link; links are refused so that nothing "
                             "outside the folder is read or written")
    if not stat.S_ISDIR(st.st_mode):
        raise RunFolderError(f"{path}: the {what} is not a folder")
    return path


def read_run_json(folder: Path, name: str, what: str, cap: int) -> Any:
    """The JSON of ``folder / name`` (a regular file of at most ``cap`` bytes, ``folder`` itself
    no link); any refusal is a :class:`RunFolderError` naming the file and ``what`` it holds."""
    check_folder(folder)
    try:
        return read_json(folder, name, cap)
    except UntrustedDataError as err:
        raise RunFolderError(f"{err}; expected {what}") from None


def read_history(run: Path) -> list[dict[str, Any]]:
    """The complete rounds of a run (``[]`` for a new run): a list of objects with ``round`` 0, 1, ..."""
    check_folder(run)
    if not os.path.lexists(run / "history.json"):
        return []
    history = read_run_json(run, "history.json", "a list of finished rounds", MAX_HISTORY_BYTES)
    if not isinstance(history, list) or any(not isinstance(h, dict) or h.get("round") != k
                                            for k, h in enumerate(history)):
        raise RunFolderError(f"{run / 'history.json'}: expected a list of rounds 0, 1, ... (objects with "
                             f"'round'), got {str(history)[:80]}")
    return history


def save_labels(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    """A round's rows to ``path``, whole or absent."""
    from satenv.training import runfolder

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:     # a file object: numpy adds no ".npz" to the temporary name
            np.savez_compressed(fh, **arrays)

    return runfolder.save_with(path, write)


def read_labels(path: Path, what: str = "a round's labels") -> dict[str, np.ndarray]:
    """The arrays of a label file, after checking (module docstring) that it is a regular file
    of at most :data:`MAX_LABEL_BYTES`, holding at most :data:`MAX_LABEL_ARRAYS` numeric arrays
    with one row count, whose declared sizes fit inside :data:`MAX_LABEL_BYTES`."""
    check_folder(path.parent, "labels folder")
    try:
        member(path.parent, path.name, MAX_LABEL_BYTES)
        with zipfile.ZipFile(path) as zf:
            entries = {e.filename.removesuffix(".npy"): e for e in zf.infolist()}
        if len(entries) > MAX_LABEL_ARRAYS:
            raise RunFolderError(f"{path}: {len(entries)} arrays, more than {MAX_LABEL_ARRAYS}")
        if sum(e.file_size for e in entries.values()) > MAX_LABEL_BYTES:
            raise RunFolderError(f"{path}: its arrays declare more than {MAX_LABEL_BYTES} bytes")
        headers = npz_headers(path)
    except (UntrustedDataError, zipfile.BadZipFile, OSError, ValueError, EOFError) as err:
        raise RunFolderError(f"{path}: cannot be read as {what} ({type(err).__name__}: {str(err)[:120]})") from None
    rows = set()
    for name, (shape, dtype) in headers.items():
        if dtype.hasobject or dtype.kind not in "biuf":
            raise RunFolderError(f"{path}: array {name!r:.40} has dtype {dtype}; {what} hold numbers only")
        if int(np.prod(shape, dtype=np.int64)) * dtype.itemsize > entries[name].file_size:
            raise RunFolderError(f"{path}: array {name!r:.40} declares {shape}, more than its entry holds")
        rows.add(shape[0] if shape else -1)
    if len(rows) > 1 or -1 in rows:
        raise RunFolderError(f"{path}: the arrays of {what} must share one row count, got {sorted(rows)}")
    try:
        with np.load(path, allow_pickle=False) as d:
            return {k: d[k] for k in d.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise RunFolderError(f"{path}: cannot be read as {what} ({type(err).__name__}: {str(err)[:120]})") from None
