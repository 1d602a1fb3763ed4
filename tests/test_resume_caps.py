"""``satenv.training.train --resume`` reads a run's checkpoint under a policy folder's rules: sizes from
headers first. ``sb3_state.pt`` is what ``torch.save`` writes (a zip of stored entries), at most
the size the config's model allows; ``replay_buffer.npz`` is what ``np.savez`` writes, each
array's header checked against the buffer before it is read."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from test_training import _cfg

from satenv.training.runfolder import RunFolderError
from satenv.training.train import CHECKPOINT_STATE, latest_checkpoint, train
from satenv.training.trust import UntrustedDataError, npz_headers, stored_zip


def _bomb(path, inflated: int) -> None:
    """A zip whose one deflated entry inflates to ``inflated`` bytes of zeros."""
    path.unlink(missing_ok=True)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf, zf.open("archive/data.pkl", "w") as f:
        chunk = bytes(2**20)
        for _ in range(inflated // len(chunk)):
            f.write(chunk)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("resume")
    cfg = _cfg(tmp, total_timesteps=96, checkpoint_every=96, eval_every=0)
    train(cfg)
    return cfg, latest_checkpoint(tmp / "run")[1]


def test_a_zip_bomb_checkpoint_is_refused_before_it_inflates(run, tmp_path):
    cfg, folder = run
    state = folder / CHECKPOINT_STATE
    good = state.read_bytes()
    try:
        _bomb(state, 256 * 2**20)            # 256 KiB on disk, 256 MiB inflated
        assert state.stat().st_size < 2**20
        with pytest.raises(RunFolderError, match="compressed"):
            train(cfg.replace(total_timesteps=192), resume=True)
        with zipfile.ZipFile(state, "w", compression=zipfile.ZIP_STORED) as zf:
            zf.writestr("archive/data.pkl", bytes(8 * 2**20))   # stored, but beyond the model's size
        with pytest.raises(RunFolderError, match="cap"):
            train(cfg.replace(total_timesteps=192), resume=True)
    finally:
        state.write_bytes(good)


def test_stored_zip_and_npz_headers(tmp_path):
    np.savez(tmp_path / "b.npz", observations=np.zeros((5, 3), np.float32), pos=np.array(2))
    path = stored_zip(tmp_path, "b.npz", 2**20)
    assert npz_headers(path) == {"observations": ((5, 3), np.dtype(np.float32)), "pos": ((), np.dtype(int))}
    np.savez_compressed(tmp_path / "c.npz", observations=np.zeros((5, 3)))
    with pytest.raises(UntrustedDataError, match="compressed"):
        stored_zip(tmp_path, "c.npz", 2**20)
    (tmp_path / "d.npz").write_bytes(b"not a zip")
    with pytest.raises(UntrustedDataError, match="not a readable zip"):
        stored_zip(tmp_path, "d.npz", 2**20)
