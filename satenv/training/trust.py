"""Reading untrusted data: policy folders, checkpoints and replayed configs (one home for the rules).

A policy folder, a run's checkpoint and a ``config.json`` handed to ``--config`` may come from a
stranger. Everything here reads them as data:

* **Inside the folder only.** A member is a plain file name; it must be a regular file in the
  folder itself — a symbolic link (even one pointing inside), a directory, a FIFO or a device is
  refused (``lstat`` before ``open``, ``O_NOFOLLOW``, and the opened file must be the one that
  was checked).
* **Sizes before reading.** A member larger than its cap (:data:`MAX_JSON_BYTES`,
  :data:`MAX_HEADER_BYTES` plus the tensor data a spec allows) is refused from its ``stat``; the
  read stops at the cap whatever the file does meanwhile. Tensor shapes and dtypes come from the
  safetensors header (:func:`safetensors_arrays`) and are checked against the expected ones
  before any tensor is built; the arrays are views of the bytes read.
* **No code.** JSON and safetensors only; nothing named in a file is imported or called:
  :func:`check_replayed_config` admits only registered env ids and baseline names, and a
  ``module:callable`` env id only with the caller's explicit ``allow_code_env_id=True``.
* **Errors name the file, never its content** (:class:`UntrustedDataError`, a
  :class:`satenv.errors.SatenvError`).
* **Hashes in chunks** (:func:`sha256_file`), so a manifest of any size costs O(1) memory.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from satenv.errors import SatenvError

__all__ = ["CODE_FLAG", "MAX_CHECKPOINT_BYTES", "MAX_HEADER_BYTES", "MAX_JSON_BYTES", "MAX_ZIP_ENTRIES",
           "UntrustedDataError", "check_replayed_config", "member", "npz_headers", "read_json", "read_member",
           "safetensors_arrays", "sha256_file", "stored_zip"]

MAX_JSON_BYTES = 2 * 2**20
"""Cap on one JSON member (``policy.json``, ``obs_norm.json``, ``env.json``, ``config.json``,
``manifest.json``, a replayed ``config.json``): 2 MiB; parsed, it holds at most ~20x that."""
MAX_HEADER_BYTES = 2**20
"""Cap on a safetensors header (the JSON that lists the tensors): 1 MiB."""
MAX_CHECKPOINT_BYTES = 2**33
"""Cap on one file of a run's checkpoint (``--resume``): 8 GiB (a SAC replay buffer can be large)."""
CHUNK = 2**20
"""Bytes read (and hashed) at a time."""
MAX_ZIP_ENTRIES = 100_000
"""Cap on the entries of a checkpoint zip (``torch.save`` writes one per tensor, ``np.savez`` one
per array)."""


class UntrustedDataError(SatenvError):
    """A file of an untrusted folder or config is refused (the message names the file)."""


def member(root: str | Path, name: str, cap: int) -> tuple[Path, os.stat_result]:
    """``root / name`` after checking it is a regular file directly in ``root`` (no symlink,
    no ``..``, no directory, FIFO or device) of at most ``cap`` bytes; returns it and its stat."""
    if not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name \
            or "\0" in name:
        raise UntrustedDataError(f"member name must be a plain file name, got {name!r:.80}")
    base = Path(root).resolve()
    path = base / name
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise UntrustedDataError(f"{path}: missing") from None
    except OSError as err:
        raise UntrustedDataError(f"{path}: cannot stat ({err.strerror})") from None
    if stat.S_ISLNK(st.st_mode):
        raise UntrustedDataError(f"{path}: is a symbolic link; a policy folder holds only regular "
                                 "files (links are refused so that nothing outside it is read)")
    if not stat.S_ISREG(st.st_mode):
        raise UntrustedDataError(f"{path}: is not a regular file")
    if path.parent != base:  # pragma: no cover - guarded by the name check above
        raise UntrustedDataError(f"{path}: is outside {base}")
    if st.st_size > cap:
        raise UntrustedDataError(f"{path}: {st.st_size} bytes, more than the cap of {cap}")
    return path, st


def read_member(root: str | Path, name: str, cap: int) -> bytearray:
    """The bytes of :func:`member` ``(root, name, cap)``, read through ``O_NOFOLLOW`` from the
    very file that was checked, never more than ``cap`` bytes."""
    path, st = member(root, name, cap)
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags)
    except OSError as err:
        raise UntrustedDataError(f"{path}: cannot open ({err.strerror})") from None
    with os.fdopen(fd, "rb", buffering=0) as f:
        now = os.fstat(fd)
        if (now.st_dev, now.st_ino) != (st.st_dev, st.st_ino) or not stat.S_ISREG(now.st_mode):
            raise UntrustedDataError(f"{path}: changed while being opened")
        buf = bytearray(min(now.st_size, cap) + 1)
        view, n = memoryview(buf), 0
        while n < len(buf):
            got = f.readinto(view[n:n + CHUNK])
            if not got:
                break
            n += got
    if n > cap:
        raise UntrustedDataError(f"{path}: grew past the cap of {cap} bytes while being read")
    del view
    del buf[n:]
    return buf


def read_json(root: str | Path, name: str, cap: int = MAX_JSON_BYTES) -> Any:
    """The JSON value of member ``name`` (:func:`read_member`); errors name the file only."""
    return parse_json(read_member(root, name, cap), Path(root) / name)


def parse_json(data: bytes | bytearray, where: Any) -> Any:
    """``json.loads`` of ``data``; a failure names ``where`` and the position, not the content."""
    try:
        text = bytes(data).decode("utf-8")
    except UnicodeDecodeError as err:
        raise UntrustedDataError(f"{where}: not UTF-8 text (byte {err.start})") from None
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as err:
        raise UntrustedDataError(f"{where}: not valid JSON ({err.msg} at line {err.lineno} column "
                                 f"{err.colno})") from None
    except (RecursionError, ValueError) as err:
        raise UntrustedDataError(f"{where}: not valid JSON ({type(err).__name__}: nesting or "
                                 "number too large)") from None


def _no_constant(name: str) -> float:
    if name in ("NaN", "Infinity", "-Infinity"):
        return float(name.replace("Infinity", "inf"))
    raise ValueError(name)  # pragma: no cover - json only passes these three


def sha256_file(path: str | Path) -> str:
    """The sha256 of a file, read in :data:`CHUNK` pieces (O(1) memory)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(CHUNK):
            h.update(chunk)
    return h.hexdigest()


_DTYPES = {"F32": np.dtype("<f4")}
"""safetensors dtypes a policy may hold (the actor is float32)."""


def safetensors_arrays(data: bytearray, expected: Mapping[str, tuple[int, ...]],
                       where: Any) -> dict[str, np.ndarray]:
    """The float32 arrays of a safetensors file ``data``, after checking from its header that it
    holds exactly the ``expected`` tensor names and shapes, as ``F32``, packed back to back and
    filling the file; the arrays are views of ``data`` (nothing is allocated for them)."""
    def bad(why: str) -> UntrustedDataError:
        return UntrustedDataError(f"{where}: not a valid safetensors file of the expected tensors ({why})")

    if len(data) < 8:
        raise bad("shorter than its 8-byte header length")
    n = int.from_bytes(data[:8], "little")
    if n > MAX_HEADER_BYTES or 8 + n > len(data):
        raise bad(f"header of {n} bytes; at most {MAX_HEADER_BYTES} and within the file")
    header = parse_json(data[8:8 + n], f"{where} (header)")
    if not isinstance(header, dict):
        raise bad("the header is not a JSON object")
    meta = header.pop("__metadata__", {})
    if not isinstance(meta, dict) or not all(isinstance(v, str) for v in meta.values()):
        raise bad("__metadata__ must map names to strings")
    if set(header) != set(expected):
        missing, extra = sorted(set(expected) - set(header)), sorted(set(header) - set(expected))
        raise bad(f"missing tensors {missing[:8]}, unexpected {len(extra)} other(s)")
    body, spans = len(data) - 8 - n, []
    for name, shape in expected.items():
        entry = header[name]
        if not isinstance(entry, dict) or set(entry) != {"dtype", "shape", "data_offsets"}:
            raise bad(f"tensor {name}: expected dtype, shape and data_offsets")
        if entry["dtype"] not in _DTYPES:
            raise bad(f"tensor {name}: dtype must be one of {sorted(_DTYPES)}")
        if entry["shape"] != list(shape):
            raise bad(f"tensor {name}: shape differs from the expected {list(shape)}")
        offsets = entry["data_offsets"]
        size = _DTYPES[entry["dtype"]].itemsize * int(np.prod(shape, dtype=np.int64))
        if (not isinstance(offsets, list) or len(offsets) != 2
                or not all(isinstance(o, int) and not isinstance(o, bool) for o in offsets)
                or not 0 <= offsets[0] <= offsets[1] <= body or offsets[1] - offsets[0] != size):
            raise bad(f"tensor {name}: data_offsets do not hold {size} bytes inside the file")
        spans.append((offsets[0], offsets[1], name, shape))
    spans.sort()
    if [s[0] for s in spans] != [0, *(s[1] for s in spans[:-1])] or (spans[-1][1] if spans else 0) != body:
        raise bad("the tensors do not fill the data section back to back")
    return {name: np.frombuffer(data, dtype=_DTYPES["F32"], count=(b - a) // 4, offset=8 + n + a).reshape(shape)
            for a, b, name, shape in spans}


def stored_zip(root: str | Path, name: str, cap: int) -> Path:
    """Member ``name`` of ``root`` (:func:`member`, at most ``cap`` bytes) after checking, from its
    zip central directory and before anything is read from the entries, that it is what
    ``torch.save`` and ``np.savez`` write: at most :data:`MAX_ZIP_ENTRIES` entries, every one
    stored without compression, with plain names and sizes inside the file. So nothing inflates:
    reading it costs at most its size on disk (a 4 MiB zip that inflates to 4 GiB is refused)."""
    import zipfile

    path, st = member(root, name, cap)
    try:
        with zipfile.ZipFile(path) as zf:
            entries = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as err:
        raise UntrustedDataError(f"{path}: not a readable zip ({type(err).__name__})") from None
    if len(entries) > MAX_ZIP_ENTRIES:
        raise UntrustedDataError(f"{path}: {len(entries)} zip entries, more than {MAX_ZIP_ENTRIES}")
    total = 0
    for i, e in enumerate(entries):
        if e.compress_type != zipfile.ZIP_STORED or e.file_size != e.compress_size:
            raise UntrustedDataError(f"{path}: entry {i} is compressed; a "
                                     "checkpoint's entries are stored as written (torch.save, np.savez), so "
                                     "a compressed one is refused before it is inflated")
        if e.filename.startswith("/") or ".." in e.filename.split("/"):
            raise UntrustedDataError(f"{path}: an entry name leaves the archive")
        total += e.file_size
    if total > st.st_size:
        raise UntrustedDataError(f"{path}: its entries declare {total} bytes, more than the file's {st.st_size}")
    return path


def npz_headers(path: str | Path) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """``{array name: (shape, dtype)}`` of an ``np.savez`` file, read from each ``.npy`` header
    only (no array is built); call :func:`stored_zip` first."""
    import zipfile

    from numpy.lib import format as npy

    out: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for entry in zf.infolist():
                with zf.open(entry) as f:
                    version = npy.read_magic(f)
                    read = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                    shape, _, dtype = read(f, max_header_size=MAX_HEADER_BYTES)
                out[entry.filename.removesuffix(".npy")] = (tuple(shape), dtype)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, SyntaxError) as err:
        raise UntrustedDataError(f"{path}: an .npy header is malformed ({type(err).__name__})") from None
    return out


CODE_FLAG = "--allow-code-env-id"
"""The command-line flag that admits a ``module:callable`` env id in a replayed config."""


def check_replayed_config(data: Any, *, allow_code_env_id: bool = False, source: str = "config") -> None:
    """Raise :class:`UntrustedDataError` unless a replayed run config ``data`` names only
    registered things: ``env_id`` one of ``satenv.ENV_IDS`` and every baseline name (``expert``,
    ``eval_baselines``) one of ``satenv.baselines.BASELINES`` (or ``"auto"``).

    A ``"package.module:callable"`` env id imports that module and calls the callable (any code);
    it passes only with ``allow_code_env_id=True`` (the CLI flag :data:`CODE_FLAG`). Call this
    before anything of the config is imported, built or run; it imports nothing it names.
    """
    import satenv
    from satenv.baselines.experts import EXPERTS
    from satenv.baselines.registry import BASELINES

    if not isinstance(allow_code_env_id, bool):
        raise UntrustedDataError(f"allow_code_env_id must be a bool, got {allow_code_env_id!r:.40}")
    if not isinstance(data, Mapping):
        raise UntrustedDataError(f"{source}: expected a JSON object of config fields, got "
                                 f"{type(data).__name__}")
    env_id = data.get("env_id", satenv.ENV_IDS[0])
    if not isinstance(env_id, str):
        raise UntrustedDataError(f"{source}: env_id must be a string, one of {list(satenv.ENV_IDS)}; "
                                 f"got a {type(env_id).__name__}")
    if env_id not in satenv.ENV_IDS:
        if ":" not in env_id:
            raise UntrustedDataError(f"{source}: env_id {env_id!r:.80} is not registered; expected one "
                                     f"of {list(satenv.ENV_IDS)}")
        if not allow_code_env_id:
            raise UntrustedDataError(
                f"{source}: env_id {env_id!r:.80} is a 'module:callable' id: replaying it would import "
                f"that module and run that callable (any code). Pass {CODE_FLAG} only for a config "
                f"you wrote or trust, or use one of {list(satenv.ENV_IDS)}")
    names = list(data.get("eval_baselines", ()) or ()) if isinstance(data.get("eval_baselines", ()),
                                                                    list | tuple) else None
    if names is None:
        raise UntrustedDataError(f"{source}: eval_baselines must be a list of baseline names")
    expert = data.get("expert")
    if "expert" in data and not (isinstance(expert, str) and expert in EXPERTS):  # DAgger's experts: names too
        names.append(data["expert"])
    for name in names:
        if not isinstance(name, str) or (name not in BASELINES and name != "auto"):
            shown = repr(name)[:40] if isinstance(name, str) else f"a {type(name).__name__}"
            raise UntrustedDataError(f"{source}: baseline {shown} is not registered; expected names of "
                                     f"{sorted(BASELINES)} (or 'auto')")
