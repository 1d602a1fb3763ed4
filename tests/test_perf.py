"""A smoke run of the speed benchmark (tiny sizes; no timing assertions)."""

import json

from benchmarks import perf


def test_perf_smoke_writes_figures_and_ratios(tmp_path):
    out = tmp_path / "perf.json"
    result = perf.main(["--out", str(out), "--batches", "1,2", "--min-time", "0.002", "--api-time", "0.01",
                        "--sections", "api,mpe2,batched,vmas,solvers", "--solvers", "dmpc",
                        "--solver-scale", "0.05"])
    data = json.loads(out.read_text())
    assert data["config"]["batches"] == [1, 2]
    rows = data["batched"]
    assert {(r["kind"], r["model"], r["batch"]) for r in rows if r["kind"] == "dynamics"} == {
        ("dynamics", m, b) for m in ("cw", "j2") for b in (1, 2)}
    for r in rows:
        assert r["agent_steps_per_s"] > 0
        if r["kind"] == "dynamics":
            assert 0 < r["ratio_to_limit"] == r["agent_steps_per_s"] / r["memory_limit_agent_steps_per_s"]
    assert data["api"]["agent_steps_per_s"] > 0 and data["api"]["agents"] == 4
    if "skipped" not in data["mpe2"]:
        assert data["ratios"]["api_vs_mpe2"] == data["api"]["agent_steps_per_s"] / data["mpe2"]["agent_steps_per_s"]
    if "skipped" not in data["vmas"]:
        assert [r["batch"] for r in data["vmas"]["rows"]] == [1, 2]
        assert set(data["ratios"]["core_cw_vs_vmas_by_batch"]) == {"1", "2"}
    assert data["ratios"]["cw_best_batch"] in (1, 2)
    dmpc = data["solvers"]["dmpc@platoon-PLF-cw"]
    assert "skipped" in dmpc or (dmpc["decisions"] >= 1 and dmpc["act_ms_median"] > 0)
    names = {t["name"] for t in data["targets"]}
    assert any(n.startswith("(b) cw") for n in names) and all(isinstance(t["met"], bool) for t in data["targets"])
    assert result["ratios"] == json.loads(json.dumps(result["ratios"]))  # JSON round trip
