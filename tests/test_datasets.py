"""Minari datasets of the controllers' episodes: written, read by Minari's loader, replayed exactly."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

minari = pytest.importorskip("minari")

from satenv.bench.learning import datasets  # noqa: E402

SYSTEM = "platoon-pereira2023"   # the DMPC flies it in a fraction of a second per episode


@pytest.fixture
def tiny(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    datasets.write(SYSTEM, 2, progress=False, cache=tmp_path / "cache")
    return datasets.read(SYSTEM)


def test_written_dataset_is_read_by_minari(tiny):
    assert tiny.total_episodes == 2
    assert datasets.dataset_id(SYSTEM) in minari.list_local_datasets()
    ep = next(tiny.iterate_episodes())
    m = 4   # TPLF: four followers
    assert ep.observations.shape[0] == len(ep.actions) + 1
    assert ep.actions.shape[1] == m * 3 and np.all(np.abs(ep.actions) <= 1)
    for key in datasets.INFO_FIELDS:
        assert ep.infos[key].shape == (len(ep.actions) + 1, m)
    assert "possible_agents order" in tiny.storage.metadata["description"]   # the dataset card
    assert [datasets.episode_seed(tiny, i) for i in range(2)] == [0, 1]   # the training task's train seeds


def test_a_recorded_episode_replays_to_the_same_states(tiny):
    for ep in tiny.iterate_episodes():
        err = datasets.replay(SYSTEM, ep, datasets.episode_seed(tiny, ep.id))
        assert err == {"observation": 0.0, "state": 0.0, "flags": 0}


def test_replay_detects_other_actions(tiny):
    ep = next(tiny.iterate_episodes())
    ep.actions[0] = -ep.actions[0] if np.any(ep.actions[0]) else ep.actions[0] + 0.5
    err = datasets.replay(SYSTEM, ep, datasets.episode_seed(tiny, ep.id))
    assert err["state"] > 0.0


def test_bad_episode_count_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    with pytest.raises(datasets.DatasetError, match="episodes"):
        datasets.write(SYSTEM, 0, cache=tmp_path / "cache")
    with pytest.raises(datasets.DatasetError, match="workers"):
        datasets.write(SYSTEM, 1, workers=0, cache=tmp_path / "cache")


def test_an_interrupted_write_records_only_what_it_has_not_got(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    cache = tmp_path / "cache"
    datasets._record_one((SYSTEM, 0, str(cache)))     # seed 0 recorded before the interruption
    recorded = []
    real = datasets._record_one
    monkeypatch.setattr(datasets, "_record_one", lambda job: recorded.append(job[1]) or real(job))
    ds = datasets.write(SYSTEM, 2, progress=False, cache=cache)
    assert recorded == [1]
    assert [datasets.episode_seed(ds, i) for i in range(2)] == [0, 1]
    for ep in ds.iterate_episodes():   # the cached episode is the same data: it replays exactly
        assert datasets.replay(SYSTEM, ep, datasets.episode_seed(ds, ep.id)) == EXACT
    assert not list(cache.rglob("*.npz"))   # the cache is emptied once the dataset is written


EXACT = {"observation": 0.0, "state": 0.0, "flags": 0}
CLUSTER = "cluster-li2022"   # tube-RDMPC: its tube controller acts inside the env at the physics rate
SHORT = {"max_steps": 3}      # three decisions (15 s) of the cluster's training task


@pytest.fixture(scope="module")
def cluster_episode():
    env = datasets.make_env(CLUSTER, **SHORT)
    try:
        return datasets.record_episode(env, datasets.make_controller(CLUSTER, env), 0)
    finally:
        env.close()


def test_an_episode_of_a_controller_acting_inside_the_env_replays(cluster_episode):
    assert len(cluster_episode.actions) == 3
    assert datasets.replay(CLUSTER, cluster_episode, 0, **SHORT) == EXACT


def test_the_inner_loop_is_what_the_actions_alone_do_not_replay(cluster_episode, monkeypatch):
    from satenv import baselines
    assert datasets.inner_loop_name(CLUSTER) == "TubeController"
    assert datasets.inner_loop_name(SYSTEM) is None
    # without the tube controller in the env (a controller that installs nothing) the same actions fly elsewhere
    monkeypatch.setattr(datasets, "make_controller", lambda system, env: baselines.make("zero", env.unwrapped.env))
    err = datasets.replay(CLUSTER, cluster_episode, 0, **SHORT)
    assert err["state"] > 1e-3


def test_replay_counts_an_episode_that_outlasts_the_env(tiny):
    ep = next(tiny.iterate_episodes())
    longer = SimpleNamespace(observations=ep.observations, infos=ep.infos, terminations=ep.terminations,
                             truncations=ep.truncations, actions=np.concatenate([ep.actions, ep.actions[-1:]]))
    err = datasets.replay(SYSTEM, longer, datasets.episode_seed(tiny, ep.id))
    assert err == {"observation": np.inf, "state": np.inf, "flags": 1}


def test_a_cached_episode_that_does_not_replay_is_recorded_again(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    cache = tmp_path / "cache"
    datasets._record_one((SYSTEM, 0, str(cache)))
    path = datasets._episode_path(cache, SYSTEM, 0)
    stale = datasets.load_episode(path)
    stale.infos["state"][5] = stale.infos["state"][5] + 1.0   # as if an older env had flown it elsewhere
    datasets.save_episode(stale, path)
    datasets._record_one((SYSTEM, 1, str(cache)))           # an intact one is kept
    recorded = []
    real = datasets._record_one
    monkeypatch.setattr(datasets, "_record_one", lambda job: recorded.append(job[1]) or real(job))
    ds = datasets.write(SYSTEM, 2, progress=False, cache=cache)
    assert recorded == [0]
    for ep in ds.iterate_episodes():
        assert datasets.replay(SYSTEM, ep, datasets.episode_seed(ds, ep.id)) == EXACT


def test_the_command_records_into_a_user_folder_unless_asked_to_update_the_packaged_manifest(tmp_path, monkeypatch,
                                                                                               capsys):
    """``satenv datasets write`` leaves the packaged manifest alone by default; ``--update-published``
    names it, and giving both it and ``--manifest`` is one error."""
    packaged = datasets.MANIFEST.read_bytes()
    monkeypatch.chdir(tmp_path)
    args = ["write", "--systems", SYSTEM, "--episodes", "1", "--root", str(tmp_path / "minari"),
            "--cache", str(tmp_path / "cache")]
    assert datasets.main(args) == 0
    assert datasets.MANIFEST.read_bytes() == packaged
    assert datasets.dataset_id(SYSTEM) in (tmp_path / datasets.USER_MANIFEST).read_text()
    with pytest.raises(SystemExit) as exit_:
        datasets.main([*args, "--update-published", "--manifest", str(tmp_path / "m.json")])
    assert exit_.value.code == 2 and "--update-published" in capsys.readouterr().err
