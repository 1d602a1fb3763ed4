"""training: config, smoke PPO/SAC runs, artefacts, load -> act, resume, gym view, RLlib smoke."""

import json
import re

import numpy as np
import pytest
from test_env_base import ToyEnv

from satenv import training
from satenv.rollout import rollout
from satenv.training.config import TrainConfig, config_from_json, parse_args
from satenv.training.policy import PolicyLoadError
from satenv.training.train import latest_checkpoint, main, train

TOY = "test_env_base:ToyEnv"


@pytest.fixture(autouse=True)
def _private_baseline_cache(tmp_path_factory, monkeypatch):
    """Baseline results are cached on disk (satenv.training.evaluate.cache_dir): one cache per test session."""
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "satenv_cache"))


def _cfg(tmp_path, **kw):
    base = dict(env_id=TOY, env_kwargs={"max_steps": 10}, num_envs=2, total_timesteps=192, n_steps=16,
                batch_size=48, n_epochs=1, net_arch=(16, 16), eval_every=96, checkpoint_every=96,
                eval_seeds=(1, 2), test_seeds=(3, 4, 5), eval_baselines=("zero",),
                out_dir=str(tmp_path / "run"), progress=False)
    base.update(kw)
    return TrainConfig(**base)


def _text(boxed: str) -> str:
    """A help or error text as one line of words."""
    return " ".join(boxed.split())


def test_config_validation_and_json_round_trip():
    cfg = TrainConfig(net_arch=[32, 32], eval_seeds=range(3))
    assert cfg.net_arch == (32, 32) and cfg.eval_seeds == (0, 1, 2)
    assert config_from_json(json.loads(json.dumps(cfg.to_json()))) == cfg
    for bad, match in [({"algo": "dqn"}, "algo"), ({"num_envs": 0}, "num_envs"),
                       ({"net_arch": ()}, "net_arch"), ({"gamma": 1.5}, "gamma"),
                       ({"env_kwargs": {"x": object()}}, "JSON"), ({"total_timesteps": 1.5}, "total_timesteps")]:
        with pytest.raises(ValueError, match=match):
            TrainConfig(**bad)
    with pytest.raises(ValueError, match="unknown TrainConfig"):
        config_from_json({"nope": 1})
    # a config.json written before the common grammar still replays (old keys mapped)
    assert config_from_json({"n_copies": 3, "learning_rate": 0.1}) == TrainConfig(num_envs=3, lr=0.1)
    with pytest.raises(ValueError, match="eval_seeds.*cap"):
        TrainConfig(eval_seeds=range(100_001))


def test_one_seeds_grammar_with_a_cap():
    from satenv.training.config import MAX_SEEDS, parse_seeds

    assert parse_seeds("0-4") == (0, 1, 2, 3, 4) and parse_seeds("7,3,7") == (7, 3)
    assert parse_seeds(["0-1", "9"]) == (0, 1, 9) and parse_seeds("5:8") == (5, 6, 7)
    assert len(parse_seeds(f"0-{MAX_SEEDS - 1}")) == MAX_SEEDS
    for bad in ("4-2", "-1", "x", "", f"0-{MAX_SEEDS}", "0-10000000000000"):
        with pytest.raises(ValueError, match="seeds"):
            parse_seeds(bad)


def _default_task_kwargs() -> dict:
    from satenv import tasks
    from satenv.training.config import DEFAULT_TASK

    return dict(tasks.get(DEFAULT_TASK).env_kwargs)


def test_cli_flags_parse_into_the_config(capsys):
    cfg, _ = parse_args(["--algo", "sac", "--net-arch", "32,32", "--env-kwargs", '{"randomize": true}',
                         "--eval-seeds", "5-7", "--progress", "false", "--gamma", "0.98", "--lr", "0.01",
                         "--num-envs", "4"])
    assert (cfg.algo, cfg.net_arch, cfg.env_kwargs, cfg.eval_seeds, cfg.progress, cfg.gamma, cfg.lr,
            cfg.num_envs) == ("sac", (32, 32), {**_default_task_kwargs(), "randomize": True}, (5, 6, 7), False,
                              0.98, 0.01, 4)
    assert cfg.task == "platoon-pereira2022-random"       # the default task, its kwargs under the flag's
    # the old spellings are deprecated aliases
    with pytest.warns(FutureWarning, match="--n-copies is deprecated: use --num-envs"):
        old, _ = parse_args(["--n-copies", "4", "--learning-rate", "0.01", "--eval-seeds", "5:8"])
    assert (old.num_envs, old.lr, old.eval_seeds) == (4, 0.01, (5, 6, 7))
    for argv, match in [(["--env-kwargs", "randomize"], "JSON object"), (["--num-envs", "many"], "num-envs"),
                        (["--algo", "dqn"], "ppo"),
                        (["--num-envs", "0"], "error: --num-envs must be an int >= 1, got 0"),
                        (["--test-seeds", "0-999999999"], "more than 100000 seeds"),
                        (["--env-kwargs", '{"nope": 1}'], "error: --env-kwargs: platoon_v0: unknown keyword argument"),
                        (["--eval-env-kwargs", '{"dt": -1}'], "error: --eval-env-kwargs: dt must be a finite number")]:
        with pytest.raises(SystemExit):
            parse_args(argv)
        assert match in _text(capsys.readouterr().err)


def test_task_flag_sets_the_env_and_the_splits_seeds(capsys):
    from satenv import tasks

    cfg, _ = parse_args(["--task", "cluster-case1-random", "--env-kwargs", '{"max_steps": 10}'])
    task = tasks.get("cluster-case1-random")
    assert (cfg.env_id, cfg.env_kwargs) == ("cluster_v0", {**task.env_kwargs, "max_steps": 10})
    assert set(cfg.test_seeds) <= set(task.seeds("test")) and len(set(cfg.test_seeds)) == 20
    assert set(cfg.eval_seeds) <= set(task.seeds("validation"))
    custom, _ = parse_args(["--env-id", "platoon_v0"])          # a deterministic env: one seed each
    assert (custom.task, custom.eval_seeds, custom.test_seeds) == (None, (700_000,), (900_000,))
    for argv in (["--task", "nope"], ["--task", "cluster-case1", "--env-id", "platoon_v0"]):
        with pytest.raises(SystemExit):
            parse_args(argv)
        assert "task" in _text(capsys.readouterr().err)


def test_cli_config_replay_and_readable_help(tmp_path, capsys):
    cfg = _cfg(tmp_path, seed=5, env_kwargs={"max_steps": 7})
    path = tmp_path / "config.json"
    path.write_text(json.dumps(cfg.to_json()))
    assert parse_args(["--config", str(path), "--allow-code-env-id"])[0] == cfg
    assert parse_args(["--config", str(path), "--allow-code-env-id", "--seed", "7"])[0] == cfg.replace(seed=7)
    with pytest.raises(ValueError, match="--config"):
        parse_args(["--config", str(tmp_path / "nope.json")])
    with pytest.raises(SystemExit):
        parse_args(["--help"], resume=True)
    out = _text(capsys.readouterr().out)
    assert out.count("(default: 32)") == 1 and "--resume" in out and "--config FILE" in out
    assert "(default: 900000-900019)" in out and "{ppo,sac}" in out and "{constant,linear}" in out
    assert "Scenario copies stepped together" in out  # the field's docstring is its help


def test_total_timesteps_round_up_to_whole_rollouts(tmp_path, capsys):
    from satenv.training.config import planned_timesteps

    cfg = _cfg(tmp_path, total_timesteps=100, eval_every=0, checkpoint_every=0, test_seeds=(3,))
    assert planned_timesteps(cfg, 3) == 192  # rollouts of 16 steps x 2 copies x 3 agents = 96
    final = train(cfg)
    assert json.loads((final / "env.json").read_text())["step"] == 192
    assert "total_timesteps 100 -> 192" in capsys.readouterr().err
    # the budget actually run is the one saved (replaying the run trains as long)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_timesteps"] == 192
    assert planned_timesteps(cfg.replace(algo="sac"), 3) == 102  # SAC: env steps of 6 rows


def test_ppo_smoke_artefacts_and_load_act_round_trip(tmp_path):
    cfg = _cfg(tmp_path)
    final = train(cfg)
    assert {p.name for p in final.iterdir()} - {"weights.pt", "weights.safetensors"} == {
        "policy.json", "obs_norm.json", "env.json", "config.json", "manifest.json", "eval.json", "learning_curve.png"}
    assert (final / "learning_curve.png").read_bytes().startswith(b"\x89PNG")
    meta = json.loads((final / "env.json").read_text())
    assert meta["env_id"] == TOY and meta["env_kwargs"] == {"max_steps": 10} and meta["observation_shape"] == [6]
    assert json.loads((final / "config.json").read_text()) == cfg.to_json()
    summary = json.loads((final / "eval.json").read_text())
    assert summary["test_seeds"] == [3, 4, 5] and set(summary["aggregate"]) == {"learned", "zero"}
    assert summary["aggregate"]["learned"]["episodes"] == 3
    run = tmp_path / "run"
    assert list((run / "tb").rglob("events.out.tfevents.*")), "no TensorBoard log"
    history = json.loads((run / "eval_history.json").read_text())
    assert [h["step"] for h in history] == [96, 192]
    assert (run / "best" / "manifest.json").is_file()
    assert not list(run.rglob("*.pkl")) and not list(run.rglob("*.zip")), "nothing pickled is written"

    # load -> act reproduces the in-memory model with the saved normalisation
    policy = training.load(final, env=ToyEnv(max_steps=10))
    env = ToyEnv(max_steps=10)
    obs, _ = env.reset(seed=0)
    act = policy.act(obs)
    assert set(act) == set(env.possible_agents)
    assert all(a.shape == (3,) and a.dtype == np.float32 and np.all(np.abs(a) <= 1) for a in act.values())
    stacked = np.stack([obs[a] for a in env.possible_agents])
    import torch

    with torch.no_grad():
        y = policy.actor(torch.as_tensor(policy.normalizer(stacked))).numpy()
    np.testing.assert_allclose(np.stack([act[a] for a in env.possible_agents]), np.clip(y, -1, 1))
    assert policy.actor.spec == {"type": "mlp", "obs_dim": 6, "act_dim": 3, "hidden": [16, 16],
                                 "activation": "tanh", "squash": False}
    assert policy.normalizer.mean is not None and not np.allclose(policy.normalizer.mean, 0)
    # usable where a baseline is
    traj = rollout(env, policy, seed=1)
    assert traj.steps == 10 and traj.policy_info == {"fallbacks": 0}
    # a second load gives the same actions (deterministic)
    again = training.load(final)
    np.testing.assert_array_equal(again.act(obs)["sat_1"], act["sat_1"])


def test_load_errors(tmp_path):
    with pytest.raises(PolicyLoadError, match="not a directory"):
        training.load(tmp_path / "missing")
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "weights.safetensors").write_bytes(b"junk")
    with pytest.raises(PolicyLoadError, match="missing"):
        training.load(tmp_path / "half")
    for name in ("policy.json", "obs_norm.json", "env.json", "config.json"):
        (tmp_path / "half" / name).write_text("{}")
    with pytest.raises(PolicyLoadError, match="manifest"):
        training.load(tmp_path / "half")
    with pytest.raises(PolicyLoadError, match="format"):
        training.load(tmp_path / "half", trusted=True)


def test_sac_smoke_and_space_mismatch(tmp_path):
    cfg = _cfg(tmp_path, algo="sac", learning_starts=48, buffer_size=1000, sac_batch_size=32,
               eval_every=0, checkpoint_every=0, total_timesteps=240)
    final = train(cfg)
    policy = training.load(final)
    assert policy.actor.spec["squash"] and policy.actor.spec["activation"] == "relu"
    env = ToyEnv()
    obs, _ = env.reset(seed=0)
    assert all(np.all(np.abs(a) <= 1) for a in policy.act(obs).values())
    from satenv.envs.platoon_v0 import parallel_env

    with pytest.raises(PolicyLoadError, match=r"expects observations \(6,\)"):
        training.load(final, env=parallel_env())
    with pytest.raises(PolicyLoadError, match="trained on shape"):
        policy.act({"sat_1": np.zeros(4)})


def test_resume_continues_the_step_count(tmp_path):
    cfg = _cfg(tmp_path, total_timesteps=96, checkpoint_every=48, eval_every=48, lr_schedule="linear")
    train(cfg)
    steps, folder = latest_checkpoint(tmp_path / "run")
    assert steps == 96
    with pytest.raises(SystemExit, match="already has checkpoints"):
        main(["--out-dir", cfg.out_dir, "--env-id", TOY])
    # resume via the CLI: the saved config, a larger budget
    with pytest.raises(SystemExit, match="--resume: .*module:callable"):  # the saved config is vetted too
        main(["--out-dir", cfg.out_dir, "--resume", "--total-timesteps", "192"])
    final = main(["--out-dir", cfg.out_dir, "--resume", "--allow-code-env-id", "--total-timesteps", "192"])
    meta = json.loads((final / "env.json").read_text())
    assert meta["step"] == 192
    steps_after, _ = latest_checkpoint(tmp_path / "run")
    assert steps_after == 192
    history = json.loads((tmp_path / "run" / "eval_history.json").read_text())
    assert [h["step"] for h in history] == [48, 96, 144, 192]
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_timesteps"] == 192


def test_centralised_gym_view_passes_check_env():
    from gymnasium.utils.env_checker import check_env

    from satenv.training.gym_view import CentralisedEnv

    env = CentralisedEnv(ToyEnv())
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (18,)
    _, r, term, trunc, info = env.step(np.zeros(9, dtype=np.float32))
    assert isinstance(r, float) and set(info["agents"]) == {"sat_1", "sat_2", "sat_3"}
    with pytest.raises(ValueError, match=r"shape \(9,\)"):
        env.step(np.zeros(3))
    env2 = CentralisedEnv("platoon_v0", randomize=True)
    assert env2.observation_space.shape == (4 * 36,)


def test_reward_shaping_terms_and_obs_features():
    from satenv.training.shaping import ObsFeatures, RewardShaping

    info = {"tracking_error": np.zeros((1, 2, 6)), "min_separation": np.array([[10.0, 6.75]]),
            "collision": np.array([[False, True]]), "delta_v": np.array([[0.0, 0.5]])}
    info["tracking_error"][0, 0, :3] = [3.0, 4.0, 0.0]  # |e_pos| = 5
    r = np.array([[-2.0, -4.0]])
    np.testing.assert_array_equal(RewardShaping()(r, info), r)
    assert not RewardShaping().active
    s = RewardShaping(env_weight=0.5, tracking=1.0, tracking_scale=5.0, precision=2.0, proximity=4.0,
                      proximity_distance=7.5, proximity_width=1.5, collision=10.0, effort=2.0)
    out = s(r, info)
    prec0 = 2.0 * (1 - np.log1p(5.0) / np.log1p(100.0))
    np.testing.assert_allclose(out[0, 0], -1.0 - 1.0 + prec0)
    np.testing.assert_allclose(out[0, 1], -2.0 - 0.0 + 2.0 - 4.0 * 0.25 - 10.0 - 1.0)
    with pytest.raises(ValueError, match="unknown reward_shaping"):
        RewardShaping.from_dict({"bonus": 1})
    with pytest.raises(ValueError, match="must be a finite number >= 0"):
        RewardShaping(tracking=-1)
    f = ObsFeatures(symlog_scale=50.0, symlog_dims=2)
    obs = np.array([[0.02, -1.0, 0.5]], dtype=np.float32)
    out = f(obs)
    assert out.shape == (1, 5) and f.out_dim(3) == 5 and out.dtype == np.float32
    np.testing.assert_allclose(out[0, 3:], [np.log1p(1.0), -np.log1p(50.0)], rtol=1e-6)


def test_look_ahead_penalty():
    from satenv.training.shaping import RewardShaping

    s = RewardShaping(anticipation=1.0, anticipation_distance=8.0, anticipation_width=2.0, anticipation_horizon=2.0)
    st = np.zeros((1, 3, 6))
    st[0, 1, :3], st[0, 1, 3:], st[0, 2, :3] = [20, 0, 0], [-10, 0, 0], [0, 100, 0]
    np.testing.assert_allclose(s.closest_approach_penalty(st), [[1.0, 1.0, 0.0]])  # head-on in 2 s
    st[0, 1, 3:] = [10, 0, 0]  # moving apart
    np.testing.assert_allclose(s.closest_approach_penalty(st), [[0.0, 0.0, 0.0]])
    st[0, 1, :3], st[0, 1, 3:] = [7, 0, 0], 0.0  # at rest, 7 m apart: ((8 - 7) / 2)^2
    np.testing.assert_allclose(s.closest_approach_penalty(st), [[0.25, 0.25, 0.0]])
    gated = RewardShaping(anticipation=1.0, anticipation_distance=8.0, anticipation_width=2.0,
                          anticipation_horizon=2.0, anticipation_speed=4.0)
    np.testing.assert_allclose(gated.closest_approach_penalty(st), 0.0)  # at rest: no closing speed
    st[0, 1, 3:] = [-2.0, 0, 0]  # closing at 2 m/s (half of anticipation_speed), contact ahead
    np.testing.assert_allclose(gated.closest_approach_penalty(st), [[0.5, 0.5, 0.0]])


def test_features_and_action_map_are_reapplied_at_inference(tmp_path):
    from satenv.training.shaping import ActionMap

    cfg = _cfg(tmp_path, obs_symlog_scale=10.0, obs_symlog_dims=3, obs_drop_dims=(4,), eval_every=0,
               checkpoint_every=0, action_power=3.0, reward_shaping={"tracking": 1.0, "tracking_scale": 5.0})
    final = train(cfg)
    policy = training.load(final, env=ToyEnv(max_steps=10))
    assert policy.actor.spec["obs_dim"] == 9 and policy.obs_shape == (6,)
    env = ToyEnv()
    obs, _ = env.reset(seed=0)
    act = policy.act(obs)
    changed = {a: o.copy() for a, o in obs.items()}
    for o in changed.values():
        o[4] += 3.0                      # a dropped entry: the actions do not change
    np.testing.assert_array_equal(np.stack(list(policy.act(changed).values())), np.stack(list(act.values())))
    for o in changed.values():
        o[0] += 3.0                      # a kept one: they do
    assert not np.allclose(np.stack(list(policy.act(changed).values())), np.stack(list(act.values())))
    stacked = np.stack([obs[a] for a in env.possible_agents])
    import torch

    with torch.no_grad():
        y = policy.actor(torch.as_tensor(policy.normalizer(policy.features(stacked)))).numpy()
    np.testing.assert_allclose(np.stack([act[a] for a in env.possible_agents]),
                               np.sign(y) * np.abs(np.clip(y, -1, 1)) ** 3, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(ActionMap(2.0)(np.array([-2.0, -0.5, 0.5])), [-1.0, -0.25, 0.25])
    with pytest.raises(ValueError, match="action_power"):
        TrainConfig(action_power=0)
    with pytest.raises(ValueError, match="obs_drop_dims"):
        TrainConfig(obs_drop_dims=(-1,))


@pytest.mark.rllib
def test_rllib_one_iteration(tmp_path):
    pytest.importorskip("ray.rllib", reason="ray[rllib] not installed")
    from satenv.training.rllib_train import RLlibConfig, run

    cfg = RLlibConfig(env_id=TOY, env_kwargs={"max_steps": 10}, iterations=1, train_batch_size=200,
                      minibatch_size=100, num_epochs=1, net_arch=(16,), out_dir=str(tmp_path / "rl"),
                      test_seeds=(1, 2))
    progress = run(cfg, verbose=False)
    assert len(progress) == 1 and progress[0]["env_steps"] >= 200
    assert (tmp_path / "rl" / "checkpoint").is_dir()
    assert list((tmp_path / "rl" / "tb").rglob("events.out.tfevents.*")), "no TensorBoard log"
    policy = training.load(tmp_path / "rl" / "final", env=ToyEnv(max_steps=10))  # the exported actor
    ev = json.loads((tmp_path / "rl" / "final" / "eval.json").read_text())
    assert set(ev["aggregate"]) == {"learned", "zero"} and ev["aggregate"]["learned"]["episodes"] == 2
    assert policy.actor.spec["hidden"] == [16]
    assert rollout(ToyEnv(max_steps=10), policy, seed=0).steps == 10


def test_rllib_path_imports_no_stable_baselines3():
    import subprocess
    import sys

    code = ("import sys, satenv.training.rllib_train as r; r._env_creator('platoon_v0', {})\n"
            "from satenv.training.envs import make_env; make_env('platoon_v0')\n"
            "assert not [m for m in sys.modules if m.startswith('stable_baselines3')], 'SB3 imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_rllib_missing_ray_message(monkeypatch):
    import builtins

    from satenv.training import rllib_train

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "ray" or name.startswith("ray."):
            raise ImportError("No module named 'ray'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(SystemExit, match=r"satenv\[rllib\]"):
        rllib_train.main(["--iterations", "1"])


def test_shipped_platoon_policy_solves_a_held_out_seed():
    from satenv.envs.platoon_v0 import parallel_env
    from satenv.metrics import summary

    folder = training.POLICIES_DIR / "platoon_tplf_ppo"
    meta = json.loads((folder / "env.json").read_text())
    env = parallel_env(**meta["eval_env_kwargs"])
    policy = training.load(folder, env=env)
    s = summary(rollout(env, policy, seed=20001))
    assert s["success"] and s["collisions"] == 0 and s["steps"] == 180
    assert s["final_error_m"] < 1.0 and s["rmse"] < 100.0
    with pytest.warns(UserWarning, match="topology='PLF'"):  # same spaces, other scenario
        training.load(folder, env=parallel_env(randomize=True))


SHIPPED = sorted(p.name for p in training.POLICIES_DIR.iterdir() if (p / "env.json").is_file())


def _shipped_env(folder):
    import satenv

    meta = json.loads((folder / "env.json").read_text())
    return satenv.make(meta["env_id"], **meta["eval_env_kwargs"])


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_policy_loads_and_completes_an_episode(name):
    folder = training.POLICIES_DIR / name
    env = _shipped_env(folder)
    policy = training.load(folder, env=env)
    traj = rollout(env, policy, seed=json.loads((folder / "eval.json").read_text())["test_seeds"][0])
    assert traj.steps > 0 and np.all(np.isfinite(traj.actions))
    for key in ("config.json", "README.md", "scoreboard.json", "manifest.json"):
        assert (folder / key).is_file(), f"{name} lacks {key}"


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_reproduces_its_eval_json(name):
    from satenv.training.evaluate import evaluate

    folder = training.POLICIES_DIR / name
    env = _shipped_env(folder)
    saved = json.loads((folder / "eval.json").read_text())
    if "network + filter" in saved:                 # satenv.bench.safety_alone's format: one block per way
        block = saved["network + filter" if "safety_filter" in json.loads((folder / "env.json").read_text())
                      else "network alone"]
        seeds, expected = block["test_seeds"], block["aggregate"]
    else:
        vs = next((v for k, v in saved.items() if k.startswith("vs_")), {})
        seeds, expected = saved["test_seeds"], saved["aggregate"][vs.get("shipped", "learned")]
    res = evaluate(env, training.load(folder, env=env), seeds)["aggregate"]   # loads as shipped
    for key in ("success_rate", "collision_episodes", "rmse", "delta_v"):
        assert res[key] == pytest.approx(expected[key], rel=1e-6), key


TRAINER_COMMANDS = {"train": "train", "benchmarl_train": "train-marl", "rllib_train": "train-rllib",
                    "imitation.cli": "imitate", "rl.ppo": "ppo"}
"""``python -m satenv.training.<module>`` (the module form some pages keep) -> ``satenv <command>``."""


def _trainer_parsers() -> dict:
    """Each trainer command's own parse of a command line (nothing runs)."""
    from satenv.training.benchmarl_train import BenchMARLConfig
    from satenv.training.imitation.cli import parse as parse_imitation
    from satenv.training.rl.ppo import config_from_args
    from satenv.training.rllib_train import RLlibConfig

    return {"train": lambda a: parse_args(a, cls=TrainConfig),
            "train-marl": lambda a: parse_args(a, cls=BenchMARLConfig),
            "train-rllib": lambda a: parse_args(a, cls=RLlibConfig), "imitate": parse_imitation,
            "ppo": config_from_args}


def test_every_training_command_in_the_docs_parses():
    """The shell examples of README.md, docs/ and the shipped policies' READMEs (``satenv train``,
    ``train-marl``, ``train-rllib``, ``imitate``, ``ppo``, or the older ``python -m`` form) use valid
    flags: each parses with its command's own parser."""
    import shlex
    from pathlib import Path

    parsers = _trainer_parsers()
    root = Path(__file__).parents[1]
    pages = [root / "README.md", *root.glob("docs/**/*.md"), *root.glob("satenv/training/policies/*/README.md")]
    modules = "|".join(re.escape(m) for m in TRAINER_COMMANDS)
    pattern = (rf"(?:python -m satenv\.training\.({modules})|\bsatenv (train-marl|train-rllib|train|imitate|ppo))"
               r"(?![\w.-])([^\n#`|]*)")
    found = 0
    for page in pages:
        text = page.read_text().replace("\\\n", " ")
        for m in re.finditer(pattern, text):
            command = TRAINER_COMMANDS[m.group(1)] if m.group(1) else m.group(2)
            argv = [a for a in shlex.split(m.group(3)) if a not in ("--resume", "--help")]
            assert "..." not in argv, f"{page.name}: an incomplete example: {m.group(0)}"
            if "--config" in argv and not argv[argv.index("--config") + 1].startswith("satenv/training/"):
                continue  # a run of the reader's own (runs/x/config.json, FILE)
            parsers[command](argv)
            found += 1
    assert found >= 12


def test_evaluation_is_the_same_in_worker_processes_and_baselines_are_cached(tmp_path, monkeypatch, capsys):
    from satenv import baselines
    from satenv.training.evaluate import cache_dir, evaluate, evaluate_baselines

    env = ToyEnv(max_steps=6)
    one = evaluate(env, baselines.make("random", env), [3, 1, 2], workers=1, progress=False)
    two = evaluate(env, baselines.make("random", env), [3, 1, 2], workers=2, desc="x", progress=True)
    def strip(res):  # as JSON: NaN (no convergence) compares equal to itself
        return json.dumps([{k: v for k, v in e.items() if not k.startswith("compute_ms")} for e in res["episodes"]])

    assert strip(one) == strip(two)
    assert [e["seed"] for e in two["episodes"]] == [3, 1, 2]
    assert "x:   0%|          | 0/3" in capsys.readouterr().err  # a progress bar (an ETA as it runs)
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path))
    first = evaluate_baselines(env, ["zero"], [0, 1], progress=False)
    assert len(list(cache_dir().glob("*.json"))) == 1
    calls = []
    monkeypatch.setattr("satenv.training.evaluate.evaluate", lambda *a, **k: calls.append(a))
    assert evaluate_baselines(env, ["zero"], [0, 1], progress=False) == json.loads(json.dumps(first))
    assert not calls, "a cached baseline was evaluated again"
    evaluate_baselines(env, ["zero"], [0, 2], progress=False)  # other seeds: another entry
    assert len(calls) == 1


def test_a_run_resumed_mid_episode_on_a_training_task_equals_the_uninterrupted_one(tmp_path, monkeypatch):
    """The training reward remembers each copy's episode (``SatVectorEnv.reward_state``): the
    checkpoint saves it with the episodes in flight (``SatVectorEnv.get_state``), so a run resumed
    mid-episode trains on exactly as the uninterrupted one did."""
    monkeypatch.setenv("SATENV_CACHE_DIR", str(tmp_path / "cache"))
    kw = dict(task="platoon-pereira2022-random", num_envs=2, n_steps=8, batch_size=32, n_epochs=1, net_arch=(8,),
              eval_every=0, checkpoint_every=64, test_seeds=(900_000,), eval_baselines=("zero",), workers=1,
              progress=False)
    whole = train(TrainConfig(**kw, total_timesteps=128, out_dir=str(tmp_path / "whole")))
    train(TrainConfig(**kw, total_timesteps=64, out_dir=str(tmp_path / "cut")))
    assert latest_checkpoint(tmp_path / "cut")[0] == 64
    resumed = train(TrainConfig(**kw, total_timesteps=128, out_dir=str(tmp_path / "cut")), resume=True)
    assert (resumed / "weights.safetensors").read_bytes() == (whole / "weights.safetensors").read_bytes()
