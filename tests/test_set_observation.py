"""The fixed, team-size-independent observation layout (``obs_neighbours``) of cluster_v0 and
formation_v0, and the permutation-invariant set actor (satenv.training.set_policy) that reads it."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import satenv
from satenv import training
from satenv.envs.cluster_v0 import N_FIXED_OBS, POS_SCALE, ClusterCore
from satenv.errors import SatenvError, SatenvTypeError
from satenv.scenarios.cluster import resolve_scenario, swarm
from satenv.training.policy import LearnedPolicy, ObsNormalizer, PolicyLoadError, save_artifacts
from satenv.training.set_policy import SetActor, set_statistics, slot_layout
from satenv.training.shaping import ObsFeatures

K = 4


def _cluster(n: int, **kw):
    return satenv.make("cluster_v0", **swarm(n), obs_neighbours=K, **kw)


@pytest.mark.parametrize("n", [2, 10, 40])
def test_cluster_fixed_layout_has_one_size_for_every_team(n):
    env = _cluster(n)
    obs, _ = env.reset(seed=3)
    assert env.observation_space("sat_1").shape == (N_FIXED_OBS + 7 * K,)
    assert all(o.shape == (N_FIXED_OBS + 7 * K,) for o in obs.values())
    x = np.asarray(env.state())[:6 * n].reshape(n, 6)
    o = obs["sat_1"]
    slots = o[N_FIXED_OBS:].reshape(K, 7)
    d = np.linalg.norm(x[1:, :3] - x[0, :3], axis=1)
    near = np.sort(d[d <= env.scenario.comm_range])[:K]
    assert slots[:, 0].sum() == len(near)                     # present flags: the in-range ones
    assert np.all(slots[len(near):] == 0)                     # the rest zero-padded
    np.testing.assert_allclose(np.linalg.norm(slots[:len(near), 1:4], axis=1) * POS_SCALE, near, rtol=1e-5)


def test_cluster_fixed_layout_equals_the_default_one_when_k_is_the_graph_degree():
    kw = swarm(10)
    a, b = satenv.make("cluster_v0", **kw), satenv.make("cluster_v0", **kw, obs_neighbours=K)
    oa, _ = a.reset(seed=5)
    ob, _ = b.reset(seed=5)
    for _ in range(3):
        assert all(np.array_equal(oa[k], ob[k]) for k in oa)
        act = {k: np.full(3, 0.3, np.float32) for k in oa}
        oa, ob = a.step(act)[0], b.step(act)[0]


def test_cluster_fixed_layout_compiled_and_numpy_paths_agree():
    sc = resolve_scenario(**{k: v for k, v in swarm(30).items() if k != "preset"}, obs_neighbours=6)
    rng = np.random.default_rng(0)
    cores = [ClusterCore(sc, batch=2, fused=f) for f in (True, False)]
    x0 = np.stack([sc.initial_array() for _ in range(2)])
    x0[..., :3] += rng.uniform(-300, 300, x0[..., :3].shape)
    for c in cores:
        c.reset(x0, rng=np.random.default_rng(1))
    np.testing.assert_allclose(cores[0].observe(), cores[1].observe(), atol=1e-6)


def test_formation_fixed_layout_lists_the_nearest_others_padded():
    env = satenv.make("formation_v0", randomize=True, obs_neighbours=K)
    ref = satenv.make("formation_v0", randomize=True)
    obs, _ = env.reset(seed=2)
    full, _ = ref.reset(seed=2)
    assert env.observation_space("sat_1").shape == (7 + 7 * K,)
    o, f = obs["sat_2"], full["sat_2"]
    assert np.array_equal(o[:6], f[:6]) and o[6] == f[-1]
    slots = o[7:].reshape(K, 7)
    others = f[6:-1].reshape(2, 6)
    order = np.argsort(np.linalg.norm(others[:, :3], axis=1))
    assert np.array_equal(slots[:2, 0], [1, 1]) and np.array_equal(slots[:2, 1:], others[order])
    assert np.all(slots[2:] == 0)


@pytest.mark.parametrize("env_id", ["cluster_v0", "formation_v0"])
@pytest.mark.parametrize("bad", [0, 65, -1, 2.5, "4", True])
def test_bad_obs_neighbours_raise_a_typed_error_naming_the_field(env_id, bad):
    wrong_kind = isinstance(bad, str | bool | float)
    with pytest.raises(SatenvTypeError if wrong_kind else SatenvError, match="obs_neighbours") as err:
        satenv.make(env_id, obs_neighbours=bad)
    assert str(bad) in str(err.value) and "64" in str(err.value)


def _actor(obs_dim: int, own: int = N_FIXED_OBS) -> SetActor:
    torch.manual_seed(0)
    return SetActor(obs_dim, 3, own, 7, K, [32, 32], [64, 64], "relu", True)


def _slot_obs(n: int, rng: np.random.Generator, present: int = 3) -> np.ndarray:
    x = rng.normal(size=(n, N_FIXED_OBS + 7 * K)).astype(np.float32)
    slots = x[:, N_FIXED_OBS:].reshape(n, K, 7)
    slots[:, :, 0] = 0
    slots[:, :present, 0] = 1
    slots[:, present:, 1:] = 0
    return x


def test_permuting_the_slots_leaves_the_action_exactly_unchanged():
    rng = np.random.default_rng(7)
    actor = _actor(N_FIXED_OBS + 7 * K + 6)                    # 6 appended own features after the slots
    x = np.concatenate([_slot_obs(64, rng), rng.normal(size=(64, 6)).astype(np.float32)], axis=1)
    with torch.no_grad():
        y = actor(torch.as_tensor(x)).numpy()
        for perm in ([3, 2, 1, 0], [1, 0, 3, 2], [2, 3, 0, 1]):
            xp = x.copy()
            block = slice(N_FIXED_OBS, N_FIXED_OBS + 7 * K)
            xp[:, block] = x[:, block].reshape(64, K, 7)[:, perm].reshape(64, -1)
            assert np.array_equal(actor(torch.as_tensor(xp)).numpy(), y)
        # an empty slot's content is not read; a present slot's is
        xe = x.copy()
        xe[:, N_FIXED_OBS + 7 * 3 + 1:N_FIXED_OBS + 7 * 4] = 5.0
        assert np.array_equal(actor(torch.as_tensor(xe)).numpy(), y)
        xs = x.copy()
        xs[:, N_FIXED_OBS + 1] += 1.0
        assert not np.array_equal(actor(torch.as_tensor(xs)).numpy(), y)


def test_set_statistics_share_the_slot_statistics_and_keeps_the_flag():
    rng = np.random.default_rng(1)
    fx = _slot_obs(500, rng).astype(np.float64)
    norm = ObsNormalizer(*set_statistics(_actor(fx.shape[1]).spec, fx), 10.0)
    m, v = norm.mean[N_FIXED_OBS:].reshape(K, 7), norm.var[N_FIXED_OBS:].reshape(K, 7)
    assert np.all(m == m[0]) and np.all(v == v[0]) and m[0, 0] == 0 and v[0, 0] == 1
    out = norm(fx)[:, N_FIXED_OBS:].reshape(-1, K, 7)
    assert np.array_equal(out[..., 0], fx[:, N_FIXED_OBS:].reshape(-1, K, 7)[..., 0])


def _folder(tmp_path, env):
    feats = ObsFeatures(300.0, 6, (18,))
    obs_dim = env.observation_space("sat_1").shape[0]
    own, slot, k = slot_layout(env)
    torch.manual_seed(0)
    actor = SetActor(feats.out_dim(obs_dim), 3, own, slot, k, [16], [32], "relu", True)
    fx = feats(_slot_obs(200, np.random.default_rng(2)).astype(np.float64))
    norm = ObsNormalizer(*set_statistics(actor.spec, fx), 10.0)
    policy = LearnedPolicy(actor, norm, obs_shape=(obs_dim,), features=feats)
    meta = {"env_id": "cluster_v0", "env_name": "cluster_v0", "observation_shape": [obs_dim], "action_shape": [3],
            "env_kwargs": {"obs_neighbours": K}}
    config = {"obs_symlog_scale": 300.0, "obs_symlog_dims": 6, "obs_drop_dims": [18], "architecture": "set"}
    return save_artifacts(tmp_path / "set", policy, env_meta=meta, config=config, source="test")


def test_one_policy_folder_flies_cluster_teams_of_10_20_and_40(tmp_path):
    folder = _folder(tmp_path, _cluster(10))
    assert json.loads((folder / "policy.json").read_text())["actor"]["type"] == "set"
    for n in (10, 20, 40):
        env = _cluster(n, max_steps=3)
        policy = training.load(folder, env=env)
        obs, _ = env.reset(seed=900000)
        while env.agents:
            act = policy.act(obs)
            assert len(act) == n and all(np.all(np.abs(a) <= 1) and np.isfinite(a).all() for a in act.values())
            obs = env.step(act)[0]
        # the loaded policy (features, normalisation, network) ignores the slots' order
        o = np.stack([obs_i for obs_i in env.reset(seed=900001)[0].values()])
        p = o.copy()
        p[:, N_FIXED_OBS:] = o[:, N_FIXED_OBS:].reshape(n, K, 7)[:, ::-1].reshape(n, -1)
        assert np.array_equal(policy.predict(o), policy.predict(p))


def test_a_set_policy_does_not_load_on_the_default_layout_of_a_small_team(tmp_path):
    folder = _folder(tmp_path, _cluster(10))
    with pytest.raises(PolicyLoadError, match="observations"):
        training.load(folder, env=satenv.make("cluster_v0", **swarm(3)))


def test_a_bad_set_spec_is_a_load_error_naming_policy_json(tmp_path):
    from satenv.training.policy import write_manifest

    folder = _folder(tmp_path, _cluster(10))
    spec = json.loads((folder / "policy.json").read_text())
    spec["actor"]["n_slots"] = 400
    (folder / "policy.json").write_text(json.dumps(spec))
    write_manifest(folder)
    with pytest.raises(PolicyLoadError, match="policy.json"):
        training.load(folder)


@pytest.mark.filterwarnings("ignore:env scenario differs")
def test_dagger_trains_a_set_actor(tmp_path, capsys):
    from satenv.training.imitation.cli import main

    kw = {**swarm(5), "obs_neighbours": K, "max_steps": 4}
    flags = ["--env-id", "cluster_v0", "--env-kwargs", json.dumps(kw), "--expert", "apf", "--rounds", "2",
             "--round0-episodes", "1", "--episodes-per-round", "1", "--epochs", "1", "--net-arch", "16",
             "--architecture", "set", "--set-encoder", "8", "--eval-seeds", "700001", "--final-eval", "false",
             "--out-dir", str(tmp_path / "run"), "--progress", "false", "--workers", "1"]
    main(flags)
    folder = tmp_path / "run" / "rounds" / "0001"
    assert json.loads((folder / "policy.json").read_text())["actor"]["type"] == "set"
    policy = training.load(folder, env=_cluster(20))
    obs, _ = _cluster(20).reset(seed=1)
    assert len(policy.act(obs)) == 20
    bad = [*flags[:3], json.dumps({**swarm(5), "max_steps": 4}), *flags[4:-6], "--out-dir", str(tmp_path / "b"),
           "--progress", "false", "--workers", "1"]
    assert main(bad) == 2 and "obs_neighbours" in capsys.readouterr().err


def test_team_sizes_reports_each_task_both_ways(tmp_path):
    from satenv.training.team_sizes import evaluate, table

    folder = _folder(tmp_path, _cluster(10))
    out = tmp_path / "sizes.json"
    result = evaluate(folder, ("cluster-swarm10", "cluster-swarm20"), (900000,), {"obs_neighbours": K, "max_steps": 3},
                      out)
    assert json.loads(out.read_text())["tasks"]["cluster-swarm20"]["agents"] == 20
    for entry in result["tasks"].values():
        assert entry["network alone"]["aggregate"]["episodes"] == 1
        assert entry["network + filter"]["aggregate"]["interventions_per_agent_step"] is not None
    assert table(result).count("| cluster-swarm") == 4
