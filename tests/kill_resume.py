"""Kill the scoreboard with SIGKILL many times, resume each time, count lost/duplicated episodes
(not a pytest module; ``tests/test_scoreboard.py`` has the single-kill test).

    python tests/kill_resume.py [--kills 17] [--seeds 0-149] [--seed 0]
    python tests/kill_resume.py --target dagger     # or safe, train, datasets, safety:
                                                    # a real kill at every write boundary
    python tests/kill_resume.py --target safety --random 5   # five SIGKILLs at random moments, then the same command

``--target dagger`` / ``--target safe`` / ``--target train`` run the tiny DAgger, safe-imitation
(:mod:`satenv.training.imitation` with a warm start flown with the filter) and PPO runs of
``tests/test_crash_windows.py``, ``--target datasets`` / ``--target safety`` the tiny Minari dataset
and ``satenv safety-alone`` runs of ``tests/test_kill_writers.py``, in fresh interpreters: once
uninterrupted (counting its write boundaries, :mod:`satenv.training.runfolder`), then, for every
boundary ``k``, one run ended there by ``os._exit`` (``SATENV_CRASH_AT_WRITE=k``: the disk as a
``kill -9`` leaves it) and one resume to the end; it prints the runs that could not finish, the
rounds / evaluations lost or duplicated and how many resumed runs equal the uninterrupted one
(timings aside).

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


RUN_SCRIPTS = {
    "dagger": """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from test_crash_windows import tiny_dagger
run, cfg = tiny_dagger(lambda obj, name, value: setattr(obj, name, value))
run(cfg, Path({out!r}))
""",
    "safe": """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from test_crash_windows import tiny_safe
run, cfg = tiny_safe(lambda obj, name, value: setattr(obj, name, value))
run(cfg, Path({out!r}))
""",
    "train": """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from test_crash_windows import tiny_train_config
from satenv.training.train import train
train(tiny_train_config(Path({out!r})), resume=True)   # always --resume: a folder without a checkpoint starts fresh
""",
    "datasets": """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from test_kill_writers import write_dataset
write_dataset(Path({out!r}))
""",
    "safety": """
import sys
sys.path.insert(0, {tests!r})
from pathlib import Path
from test_kill_writers import _safety
_safety(Path({out!r}))
""",
}


def _results(target: str):
    """``(result of a finished run folder, the rounds / evaluations it holds)`` of ``target``."""
    if target in ("dagger", "safe"):
        from test_crash_windows import dagger_result
        return dagger_result, lambda got: [h["round"] for h in json.loads(got[0])]
    if target == "train":
        from test_crash_windows import train_result
        return train_result, lambda got: got[0]
    from test_kill_writers import _safety_result, dataset_result
    return (dataset_result if target == "datasets" else _safety_result), lambda got: []


def sweep(target: str) -> int:
    """Kill ``target`` at every write boundary in a subprocess, resume, compare (module docstring)."""
    from satenv.training import runfolder

    tmp = Path(tempfile.mkdtemp(prefix=f"kill_{target}_"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS)]),
           "OMP_NUM_THREADS": "1", "SATENV_CACHE_DIR": str(tmp / "cache")}

    def go(out: Path, **extra: str) -> int:
        code = RUN_SCRIPTS[target].format(tests=str(TESTS), out=str(out))
        return subprocess.run([sys.executable, "-c", code], env={**env, **extra}, cwd=TESTS.parent,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=900).returncode

    rounds = target in ("dagger", "safe")
    result, held = _results(target)
    log = tmp / "boundaries.log"
    assert go(tmp / "ref", **{runfolder.LOG_ENV: str(log)}) == 0
    labels = log.read_text().splitlines()
    reference = result(tmp / "ref")
    ref_steps = held(reference)
    kills = unfinished = lost = duplicated = equal = 0
    for k in range(1, len(labels) + 1):
        out = tmp / f"k{k}"
        kills += go(out, **{runfolder.CRASH_ENV: str(k)}) == runfolder.CRASH_EXIT_CODE
        if go(out) != 0:
            unfinished += 1
            print(f"boundary {labels[k - 1]}: the resume did not finish", flush=True)
            continue
        got = result(out)
        steps = held(got)
        lost += len(set(ref_steps) - set(steps))
        duplicated += len(steps) - len(set(steps))
        same = got == reference
        equal += same
        print(f"boundary {labels[k - 1]}: resumed, {'equal to' if same else 'differs from'} the uninterrupted run",
              flush=True)
    print(f"{target}: {kills} kills at {len(labels)} write boundaries; {unfinished} runs could not finish, "
          f"{lost} {'rounds' if rounds else 'evaluations'} lost, {duplicated} duplicated; "
          f"{equal} of {len(labels)} resumed runs equal to the uninterrupted one")
    return 0 if (kills == len(labels) and unfinished == lost == duplicated == 0
                 and equal == len(labels)) else 1


def random_kills(target: str, kills: int, seed: int) -> int:
    """``target`` killed with SIGKILL from outside at ``kills`` random moments of one run folder
    (each a fresh start of the same command, killed after a uniform delay within the uninterrupted
    run's wall time), then the same command to the end: equal to the uninterrupted run?"""
    rng = np.random.default_rng(seed)
    tmp = Path(tempfile.mkdtemp(prefix=f"kill_random_{target}_"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS)]),
           "OMP_NUM_THREADS": "1", "SATENV_CACHE_DIR": str(tmp / "cache")}

    def start(out: Path) -> subprocess.Popen:
        code = RUN_SCRIPTS[target].format(tests=str(TESTS), out=str(out))
        return subprocess.Popen([sys.executable, "-c", code], env=env, cwd=TESTS.parent,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

    result, _ = _results(target)
    t0 = time.perf_counter()
    ref = start(tmp / "ref")
    assert ref.wait(timeout=1800) == 0, ref.stderr.read().decode()[-2000:]
    wall = time.perf_counter() - t0
    reference = result(tmp / "ref")
    run, killed = tmp / "run", 0
    for k in range(kills):
        proc = start(run)
        delay = float(rng.uniform(0.1, 0.6) * wall)   # a resumed start is shorter than the whole run
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
        killed += proc.returncode == -signal.SIGKILL
        print(f"round {k + 1}: killed after {delay:.1f} s: {proc.returncode == -signal.SIGKILL}", flush=True)
    final = start(run)
    finished = final.wait(timeout=1800) == 0
    same = finished and result(run) == reference
    print(f"{target}: {killed} SIGKILLs at random moments of {kills} starts (uninterrupted run {wall:.0f} s); "
          f"the same command then {'finished' if finished else 'failed'}, "
          f"{'equal to' if same else 'different from'} the uninterrupted run")
    return 0 if same else 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=17)
    ap.add_argument("--seeds", default="0-149")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--target", choices=("scoreboard", *RUN_SCRIPTS), default="scoreboard")
    ap.add_argument("--random", type=int, default=0, metavar="N",
                    help="with a --target other than scoreboard: N SIGKILLs at random moments instead of the sweep")
    args = ap.parse_args(argv)
    if args.target != "scoreboard":
        return random_kills(args.target, args.random, args.seed) if args.random else sweep(args.target)
    from test_scoreboard import _board, _strip

    from satenv.bench.scoreboard import EPISODES_FILE, read_episodes

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
