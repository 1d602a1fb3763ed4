"""benchmarks.safety_alone: the network alone and behind the filter, resumable, JSON + PNG."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("torch")


def test_two_episodes_write_json_png_and_resume_from_the_cache(tmp_path):
    from benchmarks import safety_alone

    folder = "training/policies/platoon_tplf_safe_distill"
    args = ["--entry", f"platoon-pereira2023={folder}", "--seeds", "2", "--controller-seeds", "1", "--out", str(tmp_path)]
    safety_alone.main(args)
    res = json.loads((tmp_path / "safety_alone.json").read_text())
    assert (tmp_path / "safety_alone.png").stat().st_size > 0
    (block,) = res["entries"]
    assert block["seeds"] == [900_000, 900_001] and block["controller_seeds"] == [900_000, 900_000]
    alone, shielded = block["network alone"], block["network + filter"]
    assert alone["aggregate"]["episodes"] == shielded["aggregate"]["episodes"] == 2
    assert "interventions_per_agent_step" in shielded["aggregate"]
    assert "interventions_per_agent_step" not in alone["aggregate"]
    assert set(alone["targets"]) >= {"success", "no_collisions", "no_violations", "rmse", "delta_v"}
    cache = next(tmp_path.glob("cache/*network_alone.jsonl"))
    first = cache.read_text()
    cache.write_text(first + '{"seed": 9')          # a line cut by an interrupted run
    safety_alone.main(args)                          # reuses the cached episodes, skips the cut line
    assert json.loads((tmp_path / "safety_alone.json").read_text())["entries"][0]["network alone"]["episodes"] == \
        block["network alone"]["episodes"]


def test_a_bad_entry_is_an_error(tmp_path):
    from benchmarks import safety_alone

    with pytest.raises(SystemExit, match="system=policy-folder"):
        safety_alone.main(["--entry", "platoon-pereira2023", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="system=policy-folder"):
        safety_alone.main(["--entry", "platoon-pereira2023=x@many", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="system=policy-folder"):
        safety_alone.main(["--entry", "platoon-pereira2023=x@10:some", "--out", str(tmp_path)])
