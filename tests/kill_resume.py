"""Kill the scoreboard with SIGKILL many times, resume each time, count lost/duplicated episodes
(not a pytest module; ``tests/test_scoreboard.py`` has the single-kill test).

    python tests/kill_resume.py [--kills 17] [--seeds 0-149] [--seed 0]

Each round starts ``run_scoreboard(..., resume=True)`` on the toy board of
``tests/test_scoreboard.py`` (platoon, 20 steps, ``zero`` and ``random``) in a fresh interpreter
and kills it with SIGKILL: on even rounds from inside right after its k-th new record, on odd
rounds from outside after a random delay (possibly mid-write). Then one resume runs to the end,
and its records are compared with an uninterrupted run: exit status 0 only when none is lost,
none is duplicated and every record equals the reference (times aside).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections import Counter
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parent
sys.path.insert(0, str(TESTS))


def round_script(out: Path, seeds: str, kill_after: int | None) -> str:
    return textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(TESTS)!r})
        from test_scoreboard import _board
        n = [0]
        def hook(rec):
            n[0] += 1
            if n[0] == {kill_after!r}:
                os.kill(os.getpid(), signal.SIGKILL)
        _board({str(out)!r}, seeds={seeds!r}, resume=True, on_record=hook)
    """)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=17)
    ap.add_argument("--seeds", default="0-149")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    from test_scoreboard import _board, _strip

    from benchmarks.scoreboard import EPISODES_FILE, read_episodes

    rng = np.random.default_rng(args.seed)
    tmp = Path(tempfile.mkdtemp(prefix="kill_resume_"))
    run = tmp / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS)])}
    kills = 0
    for k in range(args.kills):
        inside = k % 2 == 0
        script = round_script(run, args.seeds, int(rng.integers(1, 4)) if inside else None)
        proc = subprocess.Popen([sys.executable, "-c", script], cwd=TESTS.parent, env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        if not inside:
            time.sleep(float(rng.uniform(2.0, 6.0)))
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=600)
        kills += proc.returncode == -signal.SIGKILL
        done = len(read_episodes(run / EPISODES_FILE)) if (run / EPISODES_FILE).exists() else 0
        print(f"round {k + 1}: {'inside' if inside else 'outside'} kill, rc {proc.returncode}, "
              f"{done} episodes on disk", flush=True)
    resumed = _board(run, seeds=args.seeds, resume=True)
    reference = _board(tmp / "ref", seeds=args.seeds)
    keys = Counter(json.dumps([r["scenario"], r["policy"], r["seed"]]) for r in resumed.records)
    ref_keys = {json.dumps([r["scenario"], r["policy"], r["seed"]]) for r in reference.records}
    lost = len(ref_keys - set(keys))
    duplicated = sum(c - 1 for c in keys.values())
    same = _strip(resumed.records) == _strip(reference.records)
    print(f"{kills} SIGKILLs; {len(reference.records)} episodes expected, {lost} lost, {duplicated} duplicated, "
          f"records equal to the uninterrupted run: {same}")
    return 0 if (lost == 0 and duplicated == 0 and same) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
