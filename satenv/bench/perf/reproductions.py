"""The ``reproductions`` section: wall times of the paper reproductions against their targets."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable

REPRODUCTION_TARGETS_S: dict[str, tuple[list[str], float]] = {
    "li2022 --case 1": (["li2022", "--case", "1", "--variant", "ours", "--no-ablation"], 120.0),
    "pereira2022-servicing": (["pereira2022-servicing", "--variant", "ours"], 20.0),
}
"""The reproduction commands (``satenv.bench.reproduce`` arguments; our variant only, without the
as-published rows and the ablation) and wall-time targets [s]: li2022 case 1 <= 120 s,
servicing <= 20 s."""


def reproduction_times(log: Callable[[str], None] = print) -> dict[str, dict]:
    """Wall time of each command of :data:`REPRODUCTION_TARGETS_S`, run as a subprocess (JSON to a
    temporary folder; its exit status is recorded, a claim not met does not stop the section)."""
    import subprocess
    import tempfile

    out = {}
    for name, (args, target) in REPRODUCTION_TARGETS_S.items():
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "satenv.bench.reproduce", *args, "--out",
                                   os.path.join(tmp, "out.json")], capture_output=True, text=True)
            wall = time.perf_counter() - start
        out[name] = {"wall_s": wall, "target_s": target, "exit_status": proc.returncode}
        log(f"reproduce {name}: {wall:.0f} s (target {target:.0f} s, exit status {proc.returncode})")
    return out
