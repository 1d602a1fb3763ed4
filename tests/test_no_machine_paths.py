"""No tracked text file names the machine that wrote it: no absolute path under the roots a machine
keeps its work in (``/work``, ``/root``, ``/home``, ``/tmp``). Writers record repository-relative
paths (or none).

Files whose bytes a ``manifest.json`` beside them pins (a shipped policy's ``config.json``) cannot
change without breaking their hash; they are listed here by name, so a new one fails the test."""

import json
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
ROOTS = ("work", "root", "home", "tmp")
MACHINE_PATH = re.compile(r"(?:^|(?<=[\s\"'`(=:\[,]))/(?:" + "|".join(ROOTS) + r")/")
"""An absolute path under one of :data:`ROOTS`, at the start of a token (not inside a URL)."""
PINNED_WITH_MACHINE_PATHS = {
    "satenv/training/policies/platoon_tplf_ppo/config.json",
    "satenv/training/policies/platoon_tplf_ppo_shield/config.json",
    "satenv/training/policies/platoon_tplf_safe_distill/config.json",
    "studies/runs/platoon_tplf30_safe_distill/rounds/0012/config.json",
    "studies/runs/platoon_tplf30_safe_distill/rounds/0020/config.json",
}
"""Manifest-pinned files that hold a training run's ``out_dir`` as written (their hash is shipped)."""


def _tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [f for f in out.stdout.decode().split("\0") if f]


def _pinned(files: list[str]) -> set[str]:
    """Files listed in the ``sha256`` table of a tracked ``manifest.json`` beside them."""
    out = set()
    for f in files:
        if Path(f).name == "manifest.json":
            names = json.loads((ROOT / f).read_text()).get("sha256", {})
            out |= {(Path(f).parent / n).as_posix() for n in names}
    return out


def machine_paths(text: str) -> list[str]:
    """The lines of ``text`` holding a machine path (:data:`MACHINE_PATH`)."""
    return [line.strip()[:160] for line in text.splitlines() if MACHINE_PATH.search(line)]


def test_the_pattern_finds_machine_paths_and_spares_urls_and_relative_paths():
    assert machine_paths('{"out": "/' + 'tmp/run1"}') and machine_paths("cd /" + "home/me/x")
    assert machine_paths("--run-dir /" + "work/runs/p22")
    assert not machine_paths("https://example.org/home/page and docs/work/notes, tmp/x, studies/runs")


def test_no_tracked_text_file_holds_a_machine_path():
    files = _tracked()
    pinned = _pinned(files)
    found = {}
    for f in files:
        path = ROOT / f
        if f in pinned or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue                                     # binary
        hits = machine_paths(data.decode("utf-8", errors="replace"))
        if hits:
            found[f] = hits[:3]
    assert not found, found


def test_pinned_files_with_machine_paths_are_the_listed_ones():
    """A pinned file cannot be rewritten; any new one holding a machine path must be named here."""
    files = _tracked()
    pinned = _pinned(files) & set(files)
    holding = {f for f in pinned if (ROOT / f).is_file()
               and b"\0" not in (ROOT / f).read_bytes()[:8192]
               and machine_paths((ROOT / f).read_text(errors="replace"))}
    assert holding <= PINNED_WITH_MACHINE_PATHS, holding - PINNED_WITH_MACHINE_PATHS
