"""pereira2023 Table II reproduction (about 1 s, so it runs by default) and the CLI."""

import json

import pytest

from benchmarks import repro_pereira2023, reproduce


@pytest.fixture(scope="module")
def result():
    return repro_pereira2023.reproduce(seed=0)


def test_twelve_rows_with_the_issue_schema(result):
    assert result["paper"] == "pereira2023"
    assert len(result["rows"]) == 12
    keys = {(r["topology"], r["follower"]) for r in result["rows"]}
    assert keys == {(t, f) for t in ("PLF", "BDL", "TPLF") for f in (1, 2, 3, 4)}
    for r in result["rows"]:
        assert {"topology", "follower", "rmse", "rmsee", "foe"} <= set(r)


@pytest.mark.parametrize("i", range(12))
def test_table2_targets(result, i):
    r = result["rows"][i]
    label = f"{r['topology']} follower {r['follower']}"
    assert abs(r["rmse"] / r["paper_rmse"] - 1) <= 0.10, f"{label}: RMSE {r['rmse']:.3f} vs {r['paper_rmse']}"
    assert abs(r["rmsee"] / r["paper_rmsee"] - 1) <= 0.25, f"{label}: RMSEE {r['rmsee']:.3f} vs {r['paper_rmsee']}"
    assert r["foe"] <= 1e-4, f"{label}: FOE {r['foe']:.2e}"


def test_constraints_respected_and_no_solver_fallbacks(result):
    """§IV: the velocity bound (40) holds in every topology (was 2 steps in BDL, 3 in TPLF)."""
    for topo, d in result["per_topology"].items():
        assert d["fallbacks"] == 0 and d["steps"] == 180, topo
        assert d["violations"] == 0, f"{topo}: {d['violations']} violations"


def test_claims_schema_and_verdict(result):
    claims = result["claims"]
    assert len(claims) == 3 * 12 + 2 * 3
    for c in claims:
        assert {"claim", "paper", "measured", "met"} <= set(c)
    foe = [c for c in claims if c["claim"].startswith("FOE ")]
    assert len(foe) == 12 and all(c["paper"] > 0 and c["measured"] > 0 for c in foe)
    assert result["pass"] == all(c["met"] for c in claims)
    assert all(r["tail_rate"] < 1 for r in result["rows"])


def test_plf_tplf_followers_1_2_identical(result):
    """Followers 1-2 hear the same agents with the same g+d in PLF and TPLF and nothing flows back
    from 3-4: under per-agent stopping their numbers are the same (see PLF_TPLF_NOTE)."""
    by = {(r["topology"], r["follower"]): r for r in result["rows"]}
    for f in (1, 2):
        for key in ("rmse", "rmsee", "foe"):
            assert by["PLF", f][key] == pytest.approx(by["TPLF", f][key], rel=1e-9, abs=1e-12)
    assert by["PLF", 3]["rmse"] != pytest.approx(by["TPLF", 3]["rmse"], rel=1e-3)


def test_cli_writes_json_and_figures(tmp_path, capsys):
    out = tmp_path / "p23.json"
    plots = tmp_path / "plots"
    rc = reproduce.main(["pereira2023", "--out", str(out), "--plots", str(plots)])
    data = json.loads(out.read_text())
    assert len(data["rows"]) == 12
    assert rc == (0 if data["pass"] else 1)
    assert len(list(plots.glob("*.png"))) == 7
    text = capsys.readouterr().out
    assert "PLF" in text and "claims met:" in text


def test_unknown_paper_is_a_clear_error():
    with pytest.raises(ValueError, match="no reproduction for paper"):
        reproduce.load("smith1999")
    with pytest.raises(SystemExit):
        reproduce.main(["smith1999"])
