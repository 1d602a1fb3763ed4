"""benchmarks.perf's learning section (tiny sizes; no timing assertions)."""

from importlib.util import find_spec

import pytest

from benchmarks import perf


@pytest.mark.skipif(find_spec("torchrl") is None, reason="torchrl not installed (marl extra)")
def test_learning_section_smoke(monkeypatch):
    ran = []
    real = perf.learning._train_rate
    monkeypatch.setattr(perf.learning, "_train_rate", lambda name, frames: ran.append(name) or (
        real(name, frames) if name == "sb3_ppo" else {"skipped": "not timed in the smoke test"}))
    out = perf.learning_throughput(batch=2, frames=64, steps=3, log=lambda _: None)
    t = out["torchrl"]
    assert t["native_agent_steps_per_s"] > 0 and t["ratio"] == t["native_agent_steps_per_s"] / t[
        "pettingzoo_wrapper_agent_steps_per_s"]
    assert ran == ["sb3_ppo", "benchmarl_mappo", "rllib_ppo"]
    assert out["training"]["sb3_ppo"]["agent_steps"] >= 64 * perf.AGENTS
