"""satenv.bench.perf's learning section (tiny sizes; no timing assertions)."""

from importlib.util import find_spec

import pytest

from satenv.bench import perf
from satenv.bench.perf import learning


@pytest.mark.skipif(find_spec("torchrl") is None, reason="torchrl not installed (marl extra)")
def test_learning_section_smoke(monkeypatch):
    ran = []
    real = learning.end_to_end
    monkeypatch.setattr(learning, "end_to_end", lambda trainer, env_id, steps, config=None: ran.append(
        (trainer, env_id, config)) or (real(trainer, env_id, steps, config) if env_id == "platoon_v0"
                                       else {"skipped": "not timed in the smoke test"}))
    out = perf.learning_throughput(batch=2, agent_steps=64, steps=3, trainers=("sb3_ppo",), log=lambda _: None)
    t = out["torchrl"]
    assert t["native_agent_steps_per_s"] > 0 and t["ratio"] == t["native_agent_steps_per_s"] / t[
        "pettingzoo_wrapper_agent_steps_per_s"]
    assert ran == ([("sb3_ppo", "platoon_v0", None)] + [("sb3_ppo", e, None) for e in learning.ENV_IDS]
                   + [("sb3_ppo", "platoon_v0", {})])
    rows = out["training"]["sb3_ppo"]
    row, ref = rows["platoon_v0"], rows["platoon_v0 (defaults)"]
    assert row["agent_steps"] >= 64 and row["config"] == learning.FAST_CONFIGS["sb3_ppo"] and ref["config"] == {}
    assert ref["fast_speedup"] == row["agent_steps_per_s"] / ref["agent_steps_per_s"]
    for r in (row, ref):
        assert 0 < r["env_share"] and 0 < r["learner_share"] and r["env_share"] + r["learner_share"] < 1


def test_dagger_end_to_end_splits_expert_env_and_learner():
    row = learning.end_to_end("dagger", "platoon_v0", 64)
    from satenv import tasks

    assert row["expert"] == tasks.system(learning.DAGGER_TASKS["platoon_v0"]).expert and row["agent_steps"] > 0
    shares = [row[f"{k}_share"] for k in ("env", "expert", "learner")]
    assert all(s > 0 for s in shares) and sum(shares) < 1


def test_fast_configs_are_valid_trainer_configs():
    """Every fast configuration builds its trainer's validated config (no stale field names)."""
    from satenv.training.config import TrainConfig
    from satenv.training.imitation import ImitationConfig

    TrainConfig(**learning.FAST_CONFIGS["sb3_ppo"])
    ImitationConfig(**learning.FAST_CONFIGS["dagger"])
    if find_spec("benchmarl") is not None:
        from satenv.training.benchmarl_train import BenchMARLConfig

        BenchMARLConfig(**learning.FAST_CONFIGS["benchmarl_mappo"])
