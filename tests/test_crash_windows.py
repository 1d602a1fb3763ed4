"""Crash windows of the run folders (:mod:`satenv.training.runfolder`): a run killed at each write
boundary, then resumed to the end, finishes with exactly the rounds / results of an uninterrupted
run with the same seed (none lost, none duplicated; weights bitwise equal).

The boundaries are counted by :func:`satenv.training.runfolder.boundary` (``SATENV_WRITE_LOG``) in an
uninterrupted run; run ``k`` is then ended at boundary ``k`` (``SATENV_CRASH_AT_WRITE=k``). The
default tests crash in-process (:class:`Killed`, raised where ``os._exit`` would end the process,
unwinding without the error clean-up of a write, so the disk is left as a kill leaves it); the
``slow`` ones kill real subprocesses with ``os._exit`` at every boundary.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from satenv.training import runfolder

TESTS = Path(__file__).resolve().parent
TIMING_KEYS = ("collect_s", "fit_s", "session_wall_s", "compute_ms_per_agent", "compute_ms_per_decision",
               "train_wall_s_this_session", "wall_s")
"""Measured times: the only entries a resumed run may differ in."""


def canonical(data) -> str:
    """``data`` as sorted JSON text: equal data, equal text (NaN included, which ``==`` never equals)."""
    return json.dumps(data, sort_keys=True)


def untimed(data):
    """``data`` (JSON) without its :data:`TIMING_KEYS`, at any depth."""
    if isinstance(data, dict):
        return {k: untimed(v) for k, v in data.items() if k not in TIMING_KEYS}
    if isinstance(data, list):
        return [untimed(v) for v in data]
    return data


class Killed(BaseException):
    """An in-process stand-in for ``kill -9`` at a write boundary."""


def _raise_killed() -> None:
    raise Killed


# ------------------------------------------------------------------------ the writer itself
def test_a_write_is_whole_or_absent_and_a_folder_swap_recovers(tmp_path, monkeypatch):
    monkeypatch.setattr(runfolder, "crash", _raise_killed)
    path = tmp_path / "h.json"
    runfolder.write_json(path, [1])
    for k in (1, 2):                                    # before and after the rename
        runfolder.reset_boundaries()
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        with pytest.raises(Killed):
            runfolder.write_json(path, [1, 2])
        assert json.loads(path.read_text()) == ([1] if k == 1 else [1, 2])
        runfolder.write_json(path, [1])
    folder = tmp_path / "best"
    for k in range(1, 4):                               # staged, moved aside, in place
        runfolder.reset_boundaries()
        monkeypatch.delenv(runfolder.CRASH_ENV)
        tmp = runfolder.staging(folder)
        (tmp / "a").write_text("old")
        runfolder.replace_folder(tmp, folder)
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        runfolder.reset_boundaries()
        tmp = runfolder.staging(folder)
        (tmp / "a").write_text("new")
        with pytest.raises(Killed):
            runfolder.replace_folder(tmp, folder)
        assert runfolder.recover_folder(folder) == folder
        assert (folder / "a").read_text() == ("new" if k == 3 else "old")
        assert sorted(p.name for p in tmp_path.iterdir()) == ["best", "h.json"]
    with pytest.raises(runfolder.RunFolderError, match="h.json: not valid JSON .* expected a list"):
        (tmp_path / "h.json").write_text('[{"round": 0')
        runfolder.read_json(tmp_path / "h.json", "a list")


# ------------------------------------------------------------------------ DAgger
def tiny_dagger(monkeypatch_setattr, **overrides) -> tuple:
    """An imitation run of seconds (:mod:`satenv.training.imitation`): the platoon (pereira2022)
    cut to 12 steps and a proportional expert (deterministic); returns ``(run, config)``."""
    import satenv
    from satenv.training.imitation import plot, run, setup, system_config

    def make_envs(env_id, env_kwargs, eval_env_kwargs, task, system, through_collisions):
        make = satenv.make
        kw = {"preset": "pereira2022", "max_steps": 12}
        return setup.Envs(make("platoon_v0", randomize=True, terminate_on_collision=False, **kw),
                          make("platoon_v0", terminate_on_collision=False, **kw),
                          make("platoon_v0", randomize=True, **kw), make("platoon_v0", **kw))

    class Expert:
        def __init__(self, env):
            self.env = env

        def reset(self, seed=None):
            pass

        def act(self, obs):
            return {a: np.clip(-0.05 * np.asarray(o[:3], dtype=np.float64), -1, 1).astype(np.float32)
                    for a, o in obs.items()}

    monkeypatch_setattr(setup, "make_envs", make_envs)
    monkeypatch_setattr(setup, "make_expert", lambda name, env, options: Expert(env))
    # the learning curve is drawn by matplotlib (seconds per round on a busy machine); its write
    # boundaries stay, its picture is a stub
    monkeypatch_setattr(plot, "plot_curve", lambda history, path: Path(path).write_bytes(b"curve"))
    cfg = system_config("platoon-pereira2022", **{"rounds": 2, "round0_episodes": 2, "episodes_per_round": 1,
                                                  "eval_seeds": (700_000,), "net_arch": (16,), "epochs": 1,
                                                  "batch_size": 64, "paper_start_share": 0.3, "expert_options": {},
                                                  "final_eval": False, **overrides})
    return run, cfg


SAFE_WARM_START = str(TESTS.parent / "satenv" / "training" / "policies" / "platoon_pereira2022_dagger_shield")


def tiny_safe(monkeypatch_setattr) -> tuple:
    """The safe variant of :func:`tiny_dagger`: the shipped platoon network flies (alone and behind
    its filter in turn), labelled by the expert through the filter, fitted on the safe loss."""
    return tiny_dagger(monkeypatch_setattr, warm_start=SAFE_WARM_START, fly="mixed", label="filtered",
                       shield_seeds=1, paper_start_share=0.0, lr=1e-4)


def dagger_result(run_dir: Path) -> tuple[str, dict[str, bytes]]:
    """What a finished run leaves: its history (timings aside) and its files' bytes (the labels'
    arrays, the rounds' weights and normalisation)."""
    rounds = untimed(json.loads((run_dir / "history.json").read_text()))
    history = canonical(rounds)
    files = {}
    for k in range(len(rounds)):
        with np.load(run_dir / "labels" / f"round_{k:04d}.npz") as d:
            files[f"labels {k}"] = b"".join(d[name].tobytes() for name in sorted(d.files))
        for name in ("weights.safetensors", "obs_norm.json"):
            files[f"round {k} {name}"] = (run_dir / "rounds" / f"{k:04d}" / name).read_bytes()
    return history, files


def boundaries(run, tmp_path: Path, monkeypatch) -> list[str]:
    """The write boundaries of an uninterrupted ``run()`` (labels in order)."""
    log = tmp_path / "boundaries.log"
    monkeypatch.setenv(runfolder.LOG_ENV, str(log))
    runfolder.reset_boundaries()
    run()
    monkeypatch.delenv(runfolder.LOG_ENV)
    return log.read_text().splitlines()


def kill_and_resume(run, k: int, monkeypatch) -> None:
    """``run()`` killed at boundary ``k``, then resumed to the end."""
    monkeypatch.setattr(runfolder, "crash", _raise_killed)
    monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
    runfolder.reset_boundaries()
    with pytest.raises(Killed):
        run()
    monkeypatch.delenv(runfolder.CRASH_ENV)
    runfolder.reset_boundaries()
    run()


def _dagger_sweep(tmp_path, monkeypatch, last_round_only: bool, tiny=tiny_dagger) -> None:
    run, cfg = tiny(monkeypatch.setattr)
    ref = tmp_path / "ref"
    labels = boundaries(lambda: run(cfg, ref), tmp_path, monkeypatch)
    reference = dagger_result(ref)
    rounds = cfg.rounds
    assert [h["round"] for h in json.loads(reference[0])] == list(range(rounds))
    per_round = (len(labels) - 2) // rounds                # config.json, then the same writes per round
    assert per_round >= 8 and len(labels) == 2 + rounds * per_round, labels
    first = len(labels) - per_round + 1 if last_round_only else 1
    lost = duplicated = differ = 0
    for k in range(first, len(labels) + 1):
        out = tmp_path / f"k{k}"
        kill_and_resume(lambda: run(cfg, out), k, monkeypatch)   # noqa: B023 - called at once
        history, files = dagger_result(out)
        done = [h["round"] for h in json.loads(history)]
        lost += len(set(range(rounds)) - set(done))
        duplicated += len(done) - len(set(done))
        differ += (history, files) != reference
        assert (history, files) == reference, f"killed at boundary {k} ({labels[k - 1]})"
    assert (lost, duplicated, differ) == (0, 0, 0)


def test_dagger_killed_at_each_write_of_a_round_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    """Every boundary of the last round (the writes of every round are the same)."""
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=True)
    capsys.readouterr()


@pytest.mark.slow
def test_dagger_killed_at_every_write_boundary_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=False)
    capsys.readouterr()


def test_safe_variant_killed_at_each_write_of_a_round_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    """The safe variant (a warm start flown with the filter, the safe loss): every boundary of the
    last round; the resumed run's labels, weights and history equal the uninterrupted run's (the
    fit's generator comes from (seed, round), not from the session)."""
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=True, tiny=tiny_safe)
    capsys.readouterr()


@pytest.mark.slow
def test_safe_variant_killed_at_every_write_boundary_resumes_to_the_same_rounds(tmp_path, monkeypatch, capsys):
    _dagger_sweep(tmp_path, monkeypatch, last_round_only=False, tiny=tiny_safe)
    capsys.readouterr()


def test_dagger_resume_reads_the_history_not_the_label_files(tmp_path, monkeypatch, capsys):
    """Labels of an unfinished round (written before the kill) are not a finished round."""
    run, cfg = tiny_dagger(monkeypatch.setattr)
    ref, out = tmp_path / "ref", tmp_path / "out"
    run(cfg, ref)
    from dataclasses import replace

    run(replace(cfg, rounds=1), out)
    (out / "labels" / "round_0001.npz").write_bytes(b"torn")      # an unfinished round's leftovers
    (out / "labels" / "round_0002.npz").write_bytes(b"torn")
    run(cfg, out)
    assert dagger_result(out) == dagger_result(ref)
    (out / "history.json").write_text('[{"round": 0}, {"rou')    # a torn history (not written by us)
    with pytest.raises(runfolder.RunFolderError, match="history.json: not valid JSON"):
        run(cfg, out)
    (out / "history.json").write_text('[{"round": 1}]')
    with pytest.raises(runfolder.RunFolderError, match="expected a list of rounds 0, 1"):
        run(cfg, out)
    (out / "history.json").write_text('[{"round": 0}]')
    (out / "labels" / "round_0000.npz").write_bytes(b"PK")
    with pytest.raises(runfolder.RunFolderError, match="round_0000.npz: cannot be read as the labels of round 0"):
        run(cfg, out)
    from satenv.training.imitation.cli import main

    capsys.readouterr()
    assert main(["--run-dir", str(out)]) == 2                     # the CLI: one line, no traceback
    err = capsys.readouterr().err
    assert "round_0000.npz" in err and "Traceback" not in err


# ------------------------------------------------------------------------ real kills (slow)
SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
import pytest
from pathlib import Path
from test_crash_windows import {tiny}
run, cfg = {tiny}(lambda obj, name, value: setattr(obj, name, value))
run(cfg, Path({out!r}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("tiny", ["tiny_dagger", "tiny_safe"])
def test_imitation_killed_for_real_at_every_write_boundary(tmp_path, tiny):
    """``os._exit`` (no clean-up at all) at every boundary of a subprocess, then a resume."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS.parent), str(TESTS)]),
           "OMP_NUM_THREADS": "1"}

    def go(out: Path, **extra: str) -> int:
        code = textwrap.dedent(SCRIPT.format(tests=str(TESTS), out=str(out), tiny=tiny))
        return subprocess.run([sys.executable, "-c", code], env={**env, **extra}, cwd=TESTS.parent,
                              capture_output=True, timeout=600).returncode

    log = tmp_path / "log"
    assert go(tmp_path / "ref", **{runfolder.LOG_ENV: str(log)}) == 0
    reference = dagger_result(tmp_path / "ref")
    n = len(log.read_text().splitlines())
    for k in range(1, n + 1):
        out = tmp_path / f"k{k}"
        assert go(out, **{runfolder.CRASH_ENV: str(k)}) == runfolder.CRASH_EXIT_CODE
        assert go(out) == 0
        assert dagger_result(out) == reference, f"killed at boundary {k}"


# ------------------------------------------------------------------------ satenv.training.train
def tiny_train_config(out: Path):
    """A PPO run of seconds on the toy env (tests/test_env_base.py): 4 rollouts, an evaluation
    and a checkpoint every rollout."""
    from satenv.training.config import TrainConfig

    return TrainConfig(env_id="test_env_base:ToyEnv", env_kwargs={"max_steps": 10}, num_envs=2,
                       total_timesteps=192, n_steps=8, batch_size=48, n_epochs=1, net_arch=(8,),
                       eval_every=48, checkpoint_every=48, eval_seeds=(1,), test_seeds=(3,),
                       eval_baselines=("zero",), out_dir=str(out), progress=False)


def train_result(out: Path) -> tuple[list[int], str, bytes, dict]:
    """What a finished training run leaves: its evaluation steps, the final folder's evaluation
    (times aside) and weights, and ``best/``'s step (the folders are loaded: whole and consistent)."""
    from satenv import training
    for name in ("final", "best"):
        training.load(out / name)
    steps = [h["step"] for h in json.loads((out / "eval_history.json").read_text())]
    final = untimed(json.loads((out / "final" / "eval.json").read_text()))
    final.pop("table", None)
    final = canonical(final)
    best = json.loads((out / "best" / "env.json").read_text())["step"]
    return steps, final, (out / "final" / "weights.safetensors").read_bytes(), {"best_step": best}


def _train_sweep(tmp_path, monkeypatch, picks) -> dict[str, int]:
    from satenv.training.train import latest_checkpoint, train

    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))
    ref = tmp_path / "ref"
    labels = boundaries(lambda: train(tiny_train_config(ref)), tmp_path, monkeypatch)
    reference = train_result(ref)
    assert reference[0] == [48, 96, 144, 192]
    last_ckpt = _first(labels, "in place step_192/")
    counts = {"kills": 0, "unfinished": 0, "lost": 0, "duplicated": 0, "bitwise_equal": 0, "after_last_checkpoint": 0}
    for k in picks(labels):
        out = tmp_path / f"k{k}"
        cfg = tiny_train_config(out)
        monkeypatch.setattr(runfolder, "crash", _raise_killed)
        monkeypatch.setenv(runfolder.CRASH_ENV, str(k))
        runfolder.reset_boundaries()
        with pytest.raises(Killed):
            train(cfg)
        counts["kills"] += 1
        monkeypatch.delenv(runfolder.CRASH_ENV)
        try:   # the user's next command: --resume from the last checkpoint (a new run if none was written)
            train(cfg, resume=latest_checkpoint(out) is not None)
            steps, final, weights, best = train_result(out)
        except Exception:                              # noqa: BLE001 - counted, then reported below
            counts["unfinished"] += 1
            continue
        counts["lost"] += len(set(reference[0]) - set(steps))
        counts["duplicated"] += len(steps) - len(set(steps))
        same = (steps, final, weights, best) == reference
        counts["bitwise_equal"] += same
        counts["after_last_checkpoint"] += k > last_ckpt
        # the checkpoint holds the episodes in flight and the random states: the resumed run
        # trains on exactly as the uninterrupted one did
        assert same, f"killed at boundary {k} ({labels[k - 1]})"
    assert (counts["unfinished"], counts["lost"], counts["duplicated"]) == (0, 0, 0), counts
    return counts


def _first(labels: list[str], text: str, after: int = 0) -> int:
    """The 1-based index of the first boundary label ending with ``text`` after boundary ``after``."""
    return next(i for i, label in enumerate(labels, 1) if i > after and label.endswith(text))


def test_train_killed_at_the_unrecoverable_windows_resumes_to_the_end(tmp_path, monkeypatch, capsys):
    """The windows that blocked every resume (a torn eval_history.json, best/ half written) and a
    checkpoint half swapped, then every kind of write after the last checkpoint (nothing left to
    train: the result must be bitwise the uninterrupted run's)."""
    def picks(labels):
        ckpt = _first(labels, "in place step_48/")
        last = _first(labels, "in place step_192/")
        return [_first(labels, "written eval_history.json", ckpt), _first(labels, "moved aside best/", ckpt),
                _first(labels, "staged step_192/"), _first(labels, "staged final/", last),
                _first(labels, "written eval.json", last)]

    counts = _train_sweep(tmp_path, monkeypatch, picks)
    assert counts["kills"] == 5 and counts["after_last_checkpoint"] == 2
    capsys.readouterr()


@pytest.mark.slow
def test_train_killed_at_every_write_boundary_resumes_to_the_end(tmp_path, monkeypatch, capsys):
    counts = _train_sweep(tmp_path, monkeypatch, lambda labels: range(1, len(labels) + 1))
    print(counts)


def test_bad_training_input_is_a_named_value_error(tmp_path, monkeypatch, capsys):
    """Accepted-then-fatal inputs are refused up front; --resume on a malformed folder names the file."""
    from satenv.training.config import MAX_LAYER_WIDTH, TrainConfig
    from satenv.training.train import main, train

    with pytest.raises(ValueError, match="lr must be a finite number"):
        TrainConfig(lr=float("inf"))
    with pytest.raises(ValueError, match=f"wider than MAX_LAYER_WIDTH = {MAX_LAYER_WIDTH}"):
        TrainConfig(net_arch=(100_000_000, 100_000_000))
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "run"
    cfg = tiny_train_config(out).replace(total_timesteps=48, eval_every=0)
    train(cfg)
    ckpt = out / "checkpoints" / "step_48"
    args = ["--out-dir", str(out), "--resume", "--allow-code-env-id"]
    state = (ckpt / "sb3_state.pt").read_bytes()
    for name, data, match in [("sb3_state.pt", b"\x80\x04garbage", "checkpoint .*step_48 is malformed"),
                              ("sb3_state.pt", state[: len(state) // 2], "checkpoint .*step_48 is malformed"),
                              ("vecnormalize.json", b'{"obs_rms": {}}', "vecnormalize.json: obs_rms must hold"),
                              ("vecnormalize.json", b'{"obs_rms": ', "vecnormalize.json")]:
        original = (ckpt / name).read_bytes()
        (ckpt / name).write_bytes(data)
        with pytest.raises(SystemExit, match=match):
            main(args)
        (ckpt / name).write_bytes(original)
    (out / "eval_history.json").write_text('[{"step": 48, "aggr')
    with pytest.raises(SystemExit, match="eval_history.json: not valid JSON"):
        main(args)
    capsys.readouterr()


def final_result(run_dir: Path) -> tuple:
    """A finished run's ``final/``: its ``eval.json`` (timings and the table of them aside) and weights."""
    ev = untimed(json.loads((run_dir / "final" / "eval.json").read_text()))
    ev.pop("table")
    return json.dumps(ev, sort_keys=True), (run_dir / "final" / "weights.safetensors").read_bytes()


def test_dagger_killed_while_writing_final_resumes_to_the_same_final(tmp_path, monkeypatch, capsys):
    """The held-out stage after the last round: a kill at each of its write boundaries, then the same
    command, leaves the ``final/`` (and ``eval.json``) of an uninterrupted run, and no leftover."""
    from dataclasses import replace

    run, cfg = tiny_dagger(monkeypatch.setattr)
    cfg = replace(cfg, final_eval=True, eval_baselines=("zero",), test_seeds=(900_000, 900_001), workers=1,
                  progress=False)
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))
    ref = tmp_path / "ref"
    labels = boundaries(lambda: run(cfg, ref), tmp_path, monkeypatch)
    last_round = max(i for i, label in enumerate(labels, 1) if "learning_curve" in label)
    final_stage = range(last_round + 1, len(labels) + 1)
    assert len(final_stage) >= 2 and all("final" in labels[k - 1] for k in final_stage), labels[last_round:]
    reference = final_result(ref)
    for k in final_stage:
        out = tmp_path / f"k{k}"
        kill_and_resume(lambda: run(cfg, out), k, monkeypatch)   # noqa: B023 - called at once
        assert final_result(out) == reference, f"killed at boundary {k} ({labels[k - 1]})"
        assert sorted(p.name for p in out.iterdir() if p.name.startswith("final")) == ["final"]
    capsys.readouterr()


def test_dagger_starts_for_every_system_name(tmp_path, capsys):
    """``--system platoon-tplf30`` crashed at start-up (an env keyword given twice): every system,
    old names included, builds its envs and experts (a run of 0 rounds)."""
    import warnings

    from satenv.training.imitation.cli import main
    from satenv.training.recipes import LEGACY_SYSTEM_NAMES

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        for name in ("platoon-tplf30", *LEGACY_SYSTEM_NAMES.values()):
            assert main(["--run-dir", str(tmp_path / name), "--system", name, "--rounds", "0"]) == 0
            assert json.loads((tmp_path / name / "config.json").read_text())["rounds"] == 0
    capsys.readouterr()


@pytest.mark.parametrize("env_id,kwargs", [("platoon_v0", {"preset": "pereira2022", "randomize": True}),
                                           ("cluster_v0", {"randomize": True}), ("servicing_v0", {"randomize": True}),
                                           ("formation_v0", {"randomize": True})])
def test_a_training_env_state_resumes_its_episodes_bit_for_bit(env_id, kwargs):
    """:meth:`satenv.training.vec_env.SatVecEnv.get_state` holds everything the next steps read (every core,
    its generators, episodes ending and auto-resetting on the way)."""
    import satenv
    from satenv.training.vec_env import SatVecEnv

    def run(venv, actions):
        out = []
        for a in actions:
            obs, rew, done, _ = venv.step(a)
            out.append((obs.tobytes(), rew.tobytes(), done.tobytes()))
        return out

    a = SatVecEnv(satenv.make(env_id, max_steps=6, **kwargs), 2, seed=3)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (14, a.num_envs, a.action_space.shape[0]))
    a.reset()
    run(a, actions[:4])
    state = a.get_state()
    expected = run(a, actions[4:])                       # crosses episode ends (max_steps 6)
    b = SatVecEnv(satenv.make(env_id, max_steps=6, **kwargs), 2, seed=99)
    b.reset()
    b.set_state(state)
    assert run(b, actions[4:]) == expected
    with pytest.raises(ValueError, match="env state: .* does not match this env"):
        SatVecEnv(satenv.make("platoon_v0", max_steps=6), 3, seed=0).set_state(state)
