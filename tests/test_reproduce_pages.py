"""The reproduction pages: each committed result is rendered from its JSON (departures, claims with
their sources, analyses), and the committed departures cover what ours changes."""

import dataclasses
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "assets" / "reproductions"
PAPERS = ("pereira2023", "kannan2022", "pereira2022-platoon", "pereira2022-servicing", "li2022")


def _gen():
    spec = importlib.util.spec_from_file_location("gen_reproductions", ROOT / "docs" / "gen_reproductions.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("paper", PAPERS)
def test_committed_page_is_rendered_from_its_json(paper):
    result = json.loads((OUT / f"{paper}.json").read_text())
    page = (OUT / f"{paper}.md").read_text()
    assert page == _gen().render(result), f"run: python docs/gen_reproductions.py --render-only --only {paper}"
    assert "### Departures from the paper" in page and "### Claims" in page
    for c in result["claims"]:
        assert c["source"] in page.replace("\\|", "|") and c["rule"]
    for d in result["departures"]:
        assert d["effect"] and d["paper"] is not None


def test_render_shows_departures_and_no_value_rows():
    from satenv.bench.claims import departure, no_value

    result = {"pass": False, "claims": [no_value("c", "The paper says so.", 1.0)],
              "departures": [departure("margin", "0", "5 m", "why", "effect")]}
    page = _gen().render(result)
    assert "| margin | 0 | 5 m | why | effect |" in page and "*paper gives no value*" in page


def test_figure_paths_name_no_machine(tmp_path):
    """A result records its figures relative to the repository, or to the plots folder outside it."""
    from satenv.bench.reproductions import REPOSITORY, figure_paths

    inside = REPOSITORY / "docs" / "assets" / "reproductions" / "x" / "a.png"
    assert figure_paths([inside], inside.parent) == ["docs/assets/reproductions/x/a.png"]
    assert figure_paths([tmp_path / "figs" / "b.png"], tmp_path / "figs") == ["b.png"]


def test_render_puts_comparisons_with_our_designs_apart():
    from satenv.bench.claims import against_our_design, statement

    ours = statement("paper claim", "The paper says A.", 0, 0, True, rule="0")
    apart = against_our_design(statement("ours vs our APF", "The paper says B.", "faster", 1, True, rule="<"),
                               "our APF")
    page = _gen().render({"pass": True, "claims": [ours, apart], "departures": []})
    claims, comparisons = page.split("### Comparisons with our own designs (not gating)")
    assert "paper claim" in claims and "ours vs our APF" not in claims and "ours vs our APF" in comparisons
    assert "1 of 1 met" in page and not apart["gating"]


def test_committed_li2022_departures_cover_the_config_fields_ours_changes():
    from satenv.baselines.tube_rdmpc import TubeRDMPCConfig
    from satenv.bench.reproductions import li2022

    result = json.loads((OUT / "li2022.json").read_text())
    ours, paper = dataclasses.asdict(TubeRDMPCConfig()), dataclasses.asdict(li2022.paper_config())
    differing = {k for k in ours if ours[k] != paper[k]} | set(li2022.PAPER_ENV)
    covered = {f for d in result["departures"] for f in d["fields"]}
    assert differing <= covered, differing - covered
    assert {"as published"} <= {c["variant"] for c in result["claims"]}


def test_committed_servicing_has_the_as_published_row():
    result = json.loads((OUT / "pereira2022-servicing.json").read_text())
    assert set(result["runs"]) == {"ours", "as published"}
    covered = {f for d in result["departures"] for f in d["fields"]}
    assert "terminal_attitude_weight" in covered


def test_committed_servicing_counts_failed_solves_by_stop_reason_never_a_clock():
    result = json.loads((OUT / "pereira2022-servicing.json").read_text())
    for name, run in result["runs"].items():
        assert run["solve_time_limit"] is None and run["iteration_cap"] > 0
        assert sum(result["stop_reasons"][name].values()) == run["fallbacks"], name
        assert not any("time" in reason.lower() for reason in result["stop_reasons"][name]), name


def test_committed_li2022_counts_against_the_paper_only():
    """No gating claim compares with our APF; the β reading is a departure naming the gating
    claims its variant run changes; eps_bar's rule does not call (15) at eta = 1 the paper's limit."""
    result = json.loads((OUT / "li2022.json").read_text())
    gate = [c for c in result["claims"] if c["gating"]]
    assert gate and not any("APF" in c["claim"] or c.get("against_our_design") for c in gate)
    beta = next(d for d in result["departures"] if d["fields"] == ["beta"])
    assert "gating claims changed: case 1 RDMPC" in beta["effect"]
    assert any(r["gating_claims_changed"] for r in result["readings"])
    theorem2 = [c for c in result["claims"] if "(Theorem 2)" in c["claim"]]
    assert theorem2 and not any("the paper's limit" in c["rule"] for c in theorem2)
    assert result["eta_range"]["low"] < 1.0 < result["eta_range"]["high"]


def test_committed_pereira2023_plf_claim_records_both_counts():
    result = json.loads((OUT / "pereira2023.json").read_text())
    most = next(c for c in result["claims"] if c["claim"].startswith("PLF gives the best value in most")
                and c["variant"] == "ours")
    assert most["measured"] == most["cells_with_ties"] >= most["cells_strict"]
    assert "shared or not" in most["rule"]


def test_index_run_times_are_the_committed_runs():
    """The index's time column is each committed JSON's wall time (rewritten by the generator)."""
    gen = _gen()
    index = gen.INDEX.read_text()
    assert index == gen.index_text(index), "run: python docs/gen_reproductions.py --render-only"
    for paper in PAPERS:
        wall = json.loads((OUT / f"{paper}.json").read_text())["wall_time_s"]
        assert f"({paper}.md) |" in index and f"| {gen.wall_time_text(wall)} |" in index
