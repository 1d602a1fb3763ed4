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


def test_overall_pass_and_no_solver_fallbacks(result):
    assert result["pass"]
    assert all(d["fallbacks"] == 0 and d["steps"] == 180 for d in result["per_topology"].values())


def test_cli_writes_json_and_figures(tmp_path, capsys):
    out = tmp_path / "p23.json"
    plots = tmp_path / "plots"
    assert reproduce.main(["pereira2023", "--out", str(out), "--plots", str(plots)]) == 0
    data = json.loads(out.read_text())
    assert len(data["rows"]) == 12 and data["pass"]
    assert len(list(plots.glob("*.png"))) == 7
    text = capsys.readouterr().out
    assert "PLF" in text and "PASS" in text


def test_unknown_paper_is_a_clear_error():
    with pytest.raises(ValueError, match="no reproduction for paper"):
        reproduce.load("smith1999")
    with pytest.raises(SystemExit):
        reproduce.main(["smith1999"])
