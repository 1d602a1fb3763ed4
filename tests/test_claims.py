"""satenv.bench.claims: claim and departure records, the exit-code rule, and every reproduction's
departures against its paper-valued config."""

import dataclasses
import json
import re

import numpy as np
import pytest

from satenv.bench import claims, reproduce

SRC = "The convergence time of the distributed RDMPC controller is 1000 s."


def test_band_is_around_the_paper_value_and_can_fail():
    ok = claims.band("t", SRC, 1000.0, np.float64(1055.0), unit="s")
    assert ok["status"] == "met" and ok["met"] and ok["gating"] and ok["measured"] == 1055.0
    assert "[900, 1100] s" in ok["rule"] and ok["source"] == SRC
    for bad in (1101.0, 899.0, None, float("nan")):
        assert claims.band("t", SRC, 1000.0, bad)["status"] == "not met"
    assert claims.band("t", SRC, 1000.0, 1400.0, tol=0.5)["met"]
    vec = claims.band("p", SRC, [0.0, -10.0, 0.0], [0.5, -10.5, 0.5])
    assert vec["met"] and "distance <= 1" in vec["rule"]
    assert not claims.band("p", SRC, [0.0, -10.0, 0.0], [1.0, -10.0, 0.5])["met"]
    with pytest.raises(ValueError, match="tol"):
        claims.band("t", SRC, 1.0, 1.0, tol=1.5)
    with pytest.raises(TypeError, match="source"):
        claims.band("t", "", 1.0, 1.0)
    with pytest.raises(TypeError, match="claim name"):
        claims.band("", SRC, 1.0, 1.0)


def test_bound_statement_and_no_value():
    assert claims.bound("u", SRC, 1.0, 0.99)["met"] and not claims.bound("u", SRC, 1.0, 1.01)["met"]
    assert claims.bound("d", SRC, 10.0, 10.0, op=">=")["met"]
    assert not claims.bound("d", SRC, 10.0, 9.9, op=">=")["met"]
    with pytest.raises(ValueError, match="op"):
        claims.bound("d", SRC, 10.0, 9.9, op="<")
    st = claims.statement("c", SRC, 0, 3, False, rule="0 collisions", case=np.int64(1))
    assert st["status"] == "not met" and st["case"] == 1
    nv = claims.no_value("x", SRC, 12.5, ours="<= 5 deg: not met")
    assert nv["status"] == claims.NO_VALUE and not nv["met"] and not nv["gating"] and nv["paper"] is None
    assert "our test" in nv["rule"]
    json.dumps([st, nv])


def test_exit_rule_counts_only_paper_valued_claims_of_our_run():
    ok = claims.band("a", SRC, 1.0, 1.0)
    bad_pub = claims.band("a", SRC, 1.0, 5.0, variant="as published")
    nv = claims.no_value("b", SRC, 3.0)
    assert claims.passed({"claims": [ok, bad_pub, nv]})
    assert not claims.passed({"claims": [ok, claims.band("c", SRC, 1.0, 2.0)]})
    assert not claims.passed({"claims": [nv]}) and not claims.passed({"claims": []})
    n = claims.count([ok, bad_pub, nv])
    assert n == {"met": 1, "not met": 1, claims.NO_VALUE: 1, "gating": 1, "gating_met": 1}
    assert claims.changed_claims([ok], [bad_pub]) == ["a"]


def test_departure_record_and_tables(tmp_path, capsys):
    d = claims.departure("speed bound", claims.NOT_STATED, "2.5 m/s", "why", "effect", fields=["v_max"])
    assert d["fields"] == ["v_max"] and d["paper"] == "not stated"
    with pytest.raises(TypeError, match="effect"):
        claims.departure("x", 1, 2, "why", "")
    table = claims.markdown_departures([d])
    assert table.splitlines()[2] == "| speed bound | not stated | 2.5 m/s | why | effect |"
    rows = [claims.band("a | b", SRC, 1.0, 1.25), claims.no_value("c", SRC, None)]
    md = claims.markdown_claims(rows)
    assert "a \\| b" in md and "**not met**" in md and "*paper gives no value*" in md and SRC in md
    text = claims.format_claims(rows)
    assert "NOT MET" in text and "our run: 0 of 1 met -> FAIL" in text
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"paper": "x2020", "claims": rows}))
    assert claims.main([str(path)]) == 0
    assert "| x2020 | c |" in capsys.readouterr().out


def test_reproduce_help_lists_run_times_and_rejects_other_names(capsys):
    with pytest.raises(SystemExit):
        reproduce.main(["--help"])
    out = capsys.readouterr().out
    for paper in reproduce.PAPERS:
        assert paper in out
    for bad in ("smith1999", "../../etc/passwd", "claims", "li2022.py"):
        with pytest.raises(ValueError, match="no reproduction for paper"):
            reproduce.load(bad)


# --- departures: every config field that differs from the paper is in the table -----------------

def _differing(ours, paper) -> set[str]:
    a, b = dataclasses.asdict(ours), dataclasses.asdict(paper)
    return {k for k in a if a[k] != b[k]}


def _covered(departures) -> set[str]:
    return {f for d in departures for f in d["fields"]}


def test_li2022_departures_cover_every_field_ours_changes():
    from satenv.baselines.tube_rdmpc import TubeRDMPCConfig
    from satenv.bench.reproductions import li2022

    paper = li2022.paper_config()
    diff = _differing(TubeRDMPCConfig(), paper) | set(li2022.PAPER_ENV)
    assert diff >= {"v_max", "terminal_braking", "safety_margin", "relax_on_failure", "lyapunov_tolerance"}
    assert diff <= _covered(li2022.departures())
    assert not _differing(paper, TubeRDMPCConfig.published(safety_margin=0.0, lyapunov_tolerance=0.0,
                                                           relax_on_failure=False))
    for addition, values in li2022.ADDITIONS.items():       # each ablation removes exactly one addition
        assert set(values) == _differing(TubeRDMPCConfig(), TubeRDMPCConfig(**values)), addition


def test_servicing_departures_cover_the_terminal_attitude_weight():
    from satenv.baselines.nmpc import NMPCConfig
    from satenv.bench.reproductions import pereira2022_servicing as serv

    paper = NMPCConfig(**serv.VARIANTS["as published"])
    assert _differing(NMPCConfig(), paper) <= _covered(serv.departures({}))


def test_platoon_departures_cover_the_config_fields():
    from satenv.baselines.dmpc import PAPER_CONFIGS
    from satenv.bench.reproductions import pereira2022_platoon as plat
    from satenv.bench.reproductions import pereira2023 as p23

    p23_paper = dataclasses.replace(PAPER_CONFIGS["pereira2023"], velocity_margin=0.0)
    assert _differing(PAPER_CONFIGS["pereira2023"], p23_paper) <= _covered(p23.departures())
    assert "min_error_constraint" in _covered(p23.departures())           # the scenario's (41)-(42)
    own = dataclasses.replace(PAPER_CONFIGS["pereira2022"], coupled_constraints=False)
    eq29 = dataclasses.replace(own, coupled_constraints=True)
    assert _differing(own, eq29) <= _covered(plat.departures({}))


def test_kannan_departures_cover_the_preset_choices():
    """kannan2022 gives no weights, horizon, sampling time, duration, range or input unit: every
    scenario field that holds one of those choices is in the table."""
    from satenv.bench.reproductions import kannan2022

    ours = {"offset_weight", "u_max", "dt", "max_steps", "position_weight", "input_weight", "length_scale",
            "connection_range"}
    assert ours <= _covered(kannan2022.departures())


BEHAVIOURS_THE_PAPERS_DO_NOT_GIVE = {
    "pereira2023": {"warm_start", "fallback", "tracking_error"},
    "pereira2022-platoon": {"fallback", "terminal_set", "warm_start", "coupled_constraints"},
    "pereira2022-servicing": {"fallback", "warm_start", "quaternion_error", "mass", "prediction_model",
                              "terminal_attitude_weight"},
    "li2022": {"fallback", "relax_on_failure", "warm_start", "apf", "prediction_model", "disturbance_force"},
    "kannan2022": {"fallback", "connection_range"},
}
"""Per reproduction, what its run decides that the paper does not give or gives otherwise: the
solver fallbacks, warm starts, error definitions, controller designs and prediction models."""
BEHAVIOUR_FIELD = re.compile(r"warm|fallback|relax|quaternion_error|initial_guess|terminal")
"""Controller config fields of those kinds: each must be a departure or stated as the paper's."""
AS_THE_PAPER = {"terminal_weight"}
"""Fields of those kinds whose value is the paper's (DMPC: pereira2023 Table I's P, §5.1's P)."""


def _departures(paper: str) -> list[dict]:
    from satenv.bench import reproduce

    module = reproduce.load(paper)
    return module.departures({}) if paper in ("pereira2022-platoon", "pereira2022-servicing") else module.departures()


@pytest.mark.parametrize("paper", sorted(BEHAVIOURS_THE_PAPERS_DO_NOT_GIVE))
def test_departures_cover_fallbacks_warm_starts_error_definitions_and_designs(paper):
    """Each behaviour the paper leaves open is a departure with the paper's value (or 'not
    stated'), ours and an effect; and every controller config field of those kinds is covered."""
    from satenv.baselines.apf import APFConfig
    from satenv.baselines.cgmres import CGMRESConfig
    from satenv.baselines.dmpc import DMPCConfig
    from satenv.baselines.nmpc import NMPCConfig
    from satenv.baselines.tube_rdmpc import TubeRDMPCConfig

    deps = _departures(paper)
    covered = _covered(deps)
    missing = BEHAVIOURS_THE_PAPERS_DO_NOT_GIVE[paper] - covered
    assert not missing, f"{paper}: no departure lists {sorted(missing)}"
    for d in deps:
        assert d["paper"] not in (None, "") and d["ours"] not in (None, "") and d["effect"], d["name"]
    configs = {"pereira2023": [DMPCConfig], "pereira2022-platoon": [DMPCConfig], "li2022": [TubeRDMPCConfig, APFConfig],
               "pereira2022-servicing": [NMPCConfig], "kannan2022": [CGMRESConfig]}[paper]
    kinds = {f.name for cfg in configs for f in dataclasses.fields(cfg) if BEHAVIOUR_FIELD.search(f.name)}
    assert kinds - AS_THE_PAPER <= covered, f"{paper}: {sorted(kinds - AS_THE_PAPER - covered)}"


def test_summary_rows_one_per_run(tmp_path, capsys):
    rows = [claims.band("a", SRC, 1.0, 1.0), claims.band("b", SRC, 1.0, 2.0),
            claims.no_value("c", SRC, 3.0), claims.band("a", SRC, 1.0, 9.0, variant="as published")]
    out = claims.summary_rows({"paper": "x", "claims": rows})
    assert out[0] == "| x | ours (gating) | 1/2 | b: 2 (paper 1) | 1 |"
    assert out[1] == "| x | as published | 0/1 | a: 9 (paper 1) | 0 |"
    path = tmp_path / "r.json"
    path.write_text(json.dumps({"paper": "x", "claims": rows}))
    assert claims.main(["--summary", str(path)]) == 0
    assert "| x | ours (gating) |" in capsys.readouterr().out
