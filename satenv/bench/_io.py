"""Small I/O helpers shared by the benchmark and reproduction scripts."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def write_json(path: str | Path, result: Any) -> Path:
    """Write ``result`` as indented JSON to ``path`` (creating its folder); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(result, indent=2))
    return path


def progress(message: str) -> None:
    """One progress line of a long run on stderr (the table and JSON stay on stdout / --out)."""
    print(message, file=sys.stderr, flush=True)
