"""benchmarks.claims: the shared claim records and the reproduce exit code."""

import json

import numpy as np
import pytest

from benchmarks import claims, reproduce


def test_claim_record_is_json_ready():
    rec = claims.claim("FOE PLF follower 1", 3.262e-6, np.float64(6.9e-6), np.bool_(False),
                       target="<= 1.5x paper", topology="PLF", follower=np.int64(1))
    assert rec == {"claim": "FOE PLF follower 1", "paper": 3.262e-6, "measured": 6.9e-6,
                   "met": False, "target": "<= 1.5x paper", "topology": "PLF", "follower": 1}
    json.dumps(rec)


def test_verdicts():
    ok, bad = claims.claim("a", 1, 1, True), claims.claim("b", 1, 2, False)
    assert claims.all_met([ok]) and not claims.all_met([ok, bad]) and not claims.all_met([])
    assert claims.passed({"pass": True, "claims": [ok]})
    assert not claims.passed({"pass": True, "claims": [ok, bad]})
    assert not claims.passed({"pass": False, "claims": [ok]})
    assert claims.within(2.0, 1.5, 1.5) and not claims.within(3.0, 1.5, 1.5)
    assert claims.within(1.0, 1.5, 1.5) and not claims.within(0.0, 1.5, 1.5)
    with pytest.raises(ValueError, match="factor"):
        claims.within(1.0, 1.0, 0.5)
    with pytest.raises(TypeError, match="claim name"):
        claims.claim("", 1, 1, True)


def test_format_and_markdown(tmp_path, capsys):
    result = {"paper": "x2020", "claims": [claims.claim("a", 1.0, 1.25, True, target="+-30%"),
                                           claims.claim("b", "stated", None, False)]}
    text = claims.format_claims(result["claims"])
    assert "NOT MET" in text and "claims met: 1/2 -> FAIL" in text
    rows = claims.markdown_rows(result)
    assert rows[0] == "| x2020 | a | 1 | 1.25 | +-30% | met |"
    assert "**not met**" in rows[1]
    path = tmp_path / "r.json"
    path.write_text(json.dumps(result))
    assert claims.main([str(path)]) == 0
    assert "| x2020 | b |" in capsys.readouterr().out


def test_reproduce_help_lists_run_times(capsys):
    with pytest.raises(SystemExit):
        reproduce.main(["--help"])
    out = capsys.readouterr().out
    for paper in reproduce.PAPERS:
        assert paper in out
