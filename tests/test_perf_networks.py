"""satenv.bench.perf policy_threads: every shipped network's decision time per agent, with its target."""

from __future__ import annotations

import pytest

pytest.importorskip("torch")


@pytest.mark.slow     # loads every shipped folder and its env (about 15 s)
def test_every_shipped_network_is_timed_per_agent_beside_its_env_step():
    from satenv import training
    from satenv.bench.perf.policy_threads import NETWORK_MS_PER_AGENT_LIMIT, network_times

    rows = network_times(seconds=0.0, log=lambda _: None)
    shipped = sorted(p.name for p in training.POLICIES_DIR.iterdir() if (p / "env.json").is_file())
    assert [r["policy"] for r in rows] == shipped
    for r in rows:
        assert r["agents"] >= 1 and 0 < r["ms_per_agent"] and 0 < r["step_ms_per_agent"]
        assert r["ratio_to_step"] == pytest.approx(r["ms_per_agent"] / r["step_ms_per_agent"])
        assert r["met"] == (r["ms_per_agent"] <= NETWORK_MS_PER_AGENT_LIMIT)
    assert any(r["ships_with_filter"] for r in rows) and not all(r["ships_with_filter"] for r in rows)
