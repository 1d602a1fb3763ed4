"""satenv.training.benchmarl_train: a tiny BenchMARL MAPPO run exports a policy the scoreboard ranks."""

import json
from importlib.util import find_spec

import numpy as np
import pytest

from satenv import training
from satenv.training.benchmarl_train import BenchMARLConfig, main

pytestmark = pytest.mark.skipif(find_spec("benchmarl") is None,
                                reason="benchmarl not installed (pip install -c constraints.txt -e '.[marl]')")


@pytest.fixture(autouse=True)
def _private_baseline_cache(tmp_path_factory, monkeypatch):
    """Baseline results are cached on disk (satenv.training.evaluate.cache_dir): one cache per test session."""
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "satenv_cache"))


def test_mappo_tiny_run_exports_a_rankable_policy(tmp_path):
    out = tmp_path / "mappo"
    main(["--algorithm", "mappo", "--env-id", "platoon_v0", "--env-kwargs", '{"max_steps": 20}',
          "--max-frames", "400", "--frames-per-batch", "200", "--num-envs", "4", "--minibatch-size", "100",
          "--minibatch-iters", "1", "--net-arch", "16", "--test-seeds", "1", "--out-dir", str(out)])
    assert list((out / "benchmarl").rglob("*.csv")), "no BenchMARL logs"
    assert list((out / "benchmarl").rglob("checkpoint_*.pt")), "no BenchMARL checkpoint"
    policy = training.load(out / "final")
    assert policy.actor.spec["hidden"] == [16] and json.loads((out / "final" / "env.json").read_text())["step"] == 400
    ev = json.loads((out / "final" / "eval.json").read_text())
    assert ev["test_seeds"] == [1] and {"learned", "zero", "dmpc"} <= set(ev["aggregate"])
    import satenv

    env = satenv.make("platoon_v0", max_steps=20)
    obs, _ = env.reset(seed=0)
    assert all(np.all(np.abs(a) <= 1) for a in policy.act(obs).values())
    from satenv.bench.scoreboard import main as scoreboard

    board = tmp_path / "board"
    scoreboard(["--scenarios", "platoon-PLF-cw", "--policies", "zero", "--policy", str(out / "final"), "--seeds", "0",
                "--out", str(board), "--no-plots", "--no-progress", "--workers", "1"])
    assert "user:mappo" in (board / "scoreboard.md").read_text()


def test_budget_is_rounded_visibly_and_saved():
    cfg = BenchMARLConfig(max_frames=3000, frames_per_batch=6000, num_envs=7)
    planned = cfg.planned()  # one batch of whole env steps of 7 copies: 3003 frames, not 6000
    assert (planned.frames_per_batch, planned.max_frames) == (3003, 3003)
    assert BenchMARLConfig(max_frames=400, frames_per_batch=200, num_envs=4).planned().max_frames == 400


def test_config_errors(tmp_path, capsys):
    with pytest.raises(ValueError, match="algorithm"):
        BenchMARLConfig(algorithm="qmix")
    with pytest.raises(ValueError, match="max_frames"):
        BenchMARLConfig(max_frames=0)
    with pytest.raises(SystemExit) as exit_:
        main(["--env-id", "nope_v0", "--max-frames", "10", "--out-dir", str(tmp_path / "x")])
    assert exit_.value.code == 2 and "'nope_v0' is not registered" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_yaml_task_configs_load_through_benchmarl_apis():
    from pathlib import Path

    import benchmarl
    from benchmarl.environments import task_config_registry
    from benchmarl.hydra_config import load_task_config_from_hydra
    from hydra import compose, initialize_config_dir

    import satenv
    from satenv.training.benchmarl_task import CONF_DIR, SatenvTask

    assert {f"{t.name.lower()}_v0" for t in SatenvTask} == set(satenv.ENV_IDS)
    for t in SatenvTask:  # BenchMARL's Task.get_from_yaml(), as for VMAS tasks
        task = t.get_from_yaml()
        assert task_config_registry[f"satenv/{t.name.lower()}"] is t and isinstance(task.config["env_kwargs"], dict)
        satenv.make(task.env_id, **task.config["env_kwargs"])
    assert SatenvTask.SERVICING.get_from_yaml().config == {"env_kwargs": {"preset": "pereira2022-rl"}}
    conf = str(Path(benchmarl.__file__).parent / "conf")
    with initialize_config_dir(config_dir=conf, version_base=None):  # BenchMARL's Hydra config tree
        cfg = compose("config", overrides=["algorithm=mappo", "task=satenv/platoon", "+task.env_kwargs.max_steps=9",
                                           f"hydra.searchpath=[file://{CONF_DIR}]"])
    task = load_task_config_from_hydra(cfg.task, "satenv/platoon")
    assert task.config == {"env_kwargs": {"max_steps": 9}}


@pytest.mark.slow
def test_benchmarl_hydra_runner_trains_a_satenv_task(tmp_path):
    import subprocess
    import sys

    overrides = ["algorithm=mappo", "task=satenv/platoon", "+task.env_kwargs.max_steps=10",
                 "experiment.max_n_frames=200", "experiment.on_policy_collected_frames_per_batch=100",
                 "experiment.on_policy_n_envs_per_worker=2", "experiment.on_policy_minibatch_size=50",
                 "experiment.on_policy_n_minibatch_iters=1", "experiment.loggers=[csv]", "experiment.evaluation=false",
                 "experiment.render=false", "experiment.checkpoint_at_end=false",
                 f"experiment.save_folder={tmp_path}", f"hydra.run.dir={tmp_path / 'hydra'}"]
    subprocess.run([sys.executable, "-m", "satenv.training.benchmarl_task", *overrides], check=True, cwd=tmp_path,
                   env={**__import__("os").environ, "PYTHONPATH": str(__import__("pathlib").Path(__file__).parents[1])})
    assert list(tmp_path.rglob("collection_reward_reward_min.csv"))
