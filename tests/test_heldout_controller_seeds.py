"""satenv.training.recipes.heldout --controller-seeds: a slow controller runs on a subset of the held-out
seeds; the learned variants on all of them; ratios on the matched subset (issue 27, servicing)."""

from __future__ import annotations

from satenv import training
from satenv.training.recipes import heldout


def _fake_episodes(env, policy, seeds):
    return [{"seed": int(s), "success": True, "rmse": 2.0 if policy == "ctrl" else 3.0, "delta_v": 1.0,
             "collisions": 0, "terminated": False, "violations": 0, "final_error_m": 0.1,
             "min_separation_m": 7.0, "compute_ms_per_agent": 0.1, "policy": policy} for s in seeds]


def test_the_controller_runs_on_its_seeds_only(monkeypatch):
    monkeypatch.setattr(heldout, "episodes", _fake_episodes)
    from satenv import baselines
    monkeypatch.setattr(baselines, "make", lambda name, env: "ctrl")
    folder = training.POLICIES_DIR / "servicing_pereira2022_dagger_shield"
    res = heldout.evaluate_policies("servicing-pereira2022", folder, [900000, 900001, 900002], [0],
                                    "nmpc", shield=False, controller_seeds=[900001])
    block = res["random"]
    assert [e["seed"] for e in block["nmpc"]["episodes"]] == [900001]
    assert [e["seed"] for e in block["learned"]["episodes"]] == [900000, 900001, 900002]
    assert block["learned"]["ratios"] == {"matched_seeds": 1, "rmse_ratio": 1.5, "delta_v_ratio": 1.0}
    assert [e["seed"] for e in res["paper"]["nmpc"]["episodes"]] == [0]     # the paper start: all its seeds
