"""PPO-Lagrangian's dual variable: the penalty it subtracts and its projected ascent step."""

from __future__ import annotations

import numpy as np
import pytest

from satenv.training.rl.lagrangian import Lagrange


def test_dual_ascent_by_hand():
    dual = Lagrange(budget=1.0, lr=0.5)
    assert dual.update([3.0, 1.0]) == pytest.approx(0.5)       # 0 + 0.5 (2 - 1)
    assert dual.update([]) == pytest.approx(0.5)               # no finished episode: no step
    assert dual.update([0.0, 0.0]) == pytest.approx(0.0)       # 0.5 + 0.5 (0 - 1) < 0: projected to 0
    dual.lam = 1.0
    out = dual.penalise(np.array([[2.0, 1.0]], dtype=np.float32), np.array([[1.0, 0.0]]))
    assert out.dtype == np.float32 and np.allclose(out, [[0.5, 0.5]])    # (2 - 1) / 2, (1 - 0) / 2


@pytest.mark.parametrize("field, value", [("budget", -1.0), ("lr", float("nan")), ("lam", True)])
def test_bad_dual_fields_are_named(field, value):
    with pytest.raises(ValueError, match=field):
        Lagrange(**{"budget": 0.0, field: value})


def test_lean_config_lagrangian_needs_a_budget(tmp_path):
    from satenv.training.rl import ppo

    cfg = ppo.LeanConfig(task="platoon-tplf30-rung1-near", lagrangian=True, budget=256, num_envs=4, n_steps=8,
                         minibatch_size=64, test_seeds=(900000,), eval_baselines=(), out_dir=str(tmp_path / "run"))
    final = ppo.train(cfg)
    rows = (tmp_path / "run" / "progress.jsonl").read_text().splitlines()
    assert final.is_dir() and all("lagrange_multiplier" in r for r in rows)
    with pytest.raises(ValueError, match="lagrangian"):
        ppo.LeanConfig(task="platoon-tplf30-rung1-near", lagrangian="yes")
