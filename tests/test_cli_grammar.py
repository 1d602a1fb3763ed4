"""One grammar for every trainer: ``--budget`` in agent-steps, ``--algo``, canonical names first
in ``--help``; the old flags still work (renamed, with a ``FutureWarning``)."""

from __future__ import annotations

import re

import pytest

from satenv.training.benchmarl_train import BenchMARLConfig
from satenv.training.config import DEPRECATED_FLAGS, TrainConfig, canonical_flags, parse_args
from satenv.training.rllib_train import RLlibConfig

TRAINERS = [(TrainConfig, "python -m satenv.training.train"),
            (BenchMARLConfig, "python -m satenv.training.benchmarl_train"),
            (RLlibConfig, "python -m satenv.training.rllib_train")]


def _help(cls, prog, capsys) -> str:
    with pytest.raises(SystemExit):
        parse_args(["--help"], cls=cls, prog=prog)
    return capsys.readouterr().out


@pytest.mark.parametrize(("cls", "prog"), TRAINERS)
def test_every_trainer_has_budget_and_algo_and_lists_only_canonical_flags(cls, prog, capsys):
    text = _help(cls, prog, capsys)
    options = re.findall(r"^\W*(--[a-z-]+)", text, flags=re.M)     # the option column, in order
    assert "--budget" in options
    assert "--algo" in options or cls is RLlibConfig           # RLlib runs PPO only
    assert not set(options) & set(DEPRECATED_FLAGS)            # old names only in the note
    assert "Old flags still accepted" in text


def test_old_flags_are_renamed_with_a_future_warning():
    with pytest.warns(FutureWarning, match="--total-timesteps is deprecated: use --budget"):
        cfg, _ = parse_args(["--total-timesteps", "4096"])
    assert cfg.total_timesteps == 4096
    with pytest.warns(FutureWarning, match="--algorithm is deprecated: use --algo"):
        cfg, _ = parse_args(["--algorithm=ippo"], cls=BenchMARLConfig)
    assert cfg.algorithm == "ippo"
    with pytest.warns(FutureWarning, match="--ray-address is deprecated"):
        cfg, _ = parse_args(["--ray-address", "h:1", "--num-envs-per-env-runner", "3"], cls=RLlibConfig)
    assert (cfg.address, cfg.num_envs) == ("h:1", 3)
    with pytest.warns(FutureWarning, match="old budget flag"):
        cfg, _ = parse_args(["--max-frames", "600"], cls=BenchMARLConfig)
    assert cfg.max_frames == 600 and cfg.budget is None


def test_two_budget_flags_are_an_error():
    with pytest.raises(SystemExit, match="one budget flag"), pytest.warns(FutureWarning):
        canonical_flags(["--budget", "10", "--iterations", "2"])
    with pytest.raises(SystemExit, match="one budget flag"), pytest.warns(FutureWarning):
        canonical_flags(["--total-timesteps", "10", "--budget=3"])


def test_the_budget_is_agent_steps_in_every_trainer():
    cfg, _ = parse_args(["--budget", "4096"])
    assert cfg.total_timesteps == 4096
    bm = BenchMARLConfig(budget=4001, frames_per_batch=600, num_envs=10)
    planned = bm.planned(n_agents=4)              # 1001 frames -> whole batches of 600
    assert planned.max_frames == 1200 and planned.max_frames * 4 >= 4001
    assert bm.planned(4) == planned.planned(4)    # replaying the saved config plans the same run
    with pytest.raises(ValueError, match="agent-steps"):
        bm.planned()
    rl = RLlibConfig(budget=50_000, train_batch_size=4000)
    assert rl.planned(n_agents=4).iterations == 4 and RLlibConfig().planned(4).iterations == 20
    with pytest.raises(ValueError, match="budget"):
        BenchMARLConfig(budget=0)


def test_the_scoreboard_booleans_are_in_the_trainers_style():
    from satenv.bench.scoreboard.cli import build_parser

    parser = build_parser()
    args = parser.parse_args(["--plots", "false", "--progress", "true"])
    assert (args.plots, args.progress) == (False, True)
    args = parser.parse_args(["--no-plots", "--no-progress"])          # the former style still works
    assert (args.plots, args.progress) == (False, False)
    assert (parser.parse_args([]).plots, parser.parse_args([]).progress) == (True, True)
    assert "--no-plots" not in parser.format_help()
