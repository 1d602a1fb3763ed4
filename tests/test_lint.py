"""The code keeps the project's lint rules: ``ruff check`` with ``[tool.ruff]`` of ``pyproject.toml``
(its line length included) finds nothing in ``satenv``, ``tests`` and ``docs``."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINE_LENGTH = 120   # ``line-length`` of ``[tool.ruff]``


def _ruff() -> str:
    try:
        from ruff.__main__ import find_ruff_bin
        return str(find_ruff_bin())
    except (ImportError, FileNotFoundError):
        found = shutil.which("ruff")
        if found is None:
            pytest.skip("ruff is not installed (it is in the dev extra: pip install -e .[dev])")
        return found


def _check(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([_ruff(), "check", "--no-cache", "--output-format", "concise", *args], cwd=ROOT,
                          input=stdin, capture_output=True, text=True, timeout=120)


def test_ruff_finds_nothing():
    proc = _check("satenv", "tests", "docs")
    assert proc.returncode == 0, f"ruff check satenv tests docs:\n{proc.stdout}{proc.stderr}"


@pytest.mark.parametrize("width, flagged", [(LINE_LENGTH, False), (LINE_LENGTH + 1, True)])
def test_the_line_length_is_checked(width, flagged):
    """The project's config flags a line one character over the limit, not one at it."""
    line = "x = " + repr("a" * (width - 6)) + "\n"
    assert len(line) == width + 1
    proc = _check("--config", str(ROOT / "pyproject.toml"), "--stdin-filename", "satenv/_width.py", "-", stdin=line)
    assert ("E501" in proc.stdout) == flagged, proc.stdout + proc.stderr
