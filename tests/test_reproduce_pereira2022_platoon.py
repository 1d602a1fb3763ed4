"""pereira2022 §5.1 reproduction: a short episode by default, the full one behind ``slow``."""

import json

import pytest

from satenv.bench import reproduce
from satenv.bench.reproductions import pereira2022_platoon as repro


def test_short_run_schema_and_claims(tmp_path):
    result = repro.reproduce(steps=15, plots=tmp_path)
    assert set(result["variants"]) == {"own_pair", "coupled"}
    assert len(result["claims"]) == 2 * 6
    for c in result["claims"]:
        assert {"claim", "source", "paper", "measured", "met", "variant", "rule", "status"} <= set(c)
    assert {c["variant"] for c in result["claims"]} == {"ours", "as published"}
    assert result["pass"] == all(c["met"] for c in result["claims"] if c["gating"])
    assert {d["name"] for d in result["departures"]} >= {"pair constraints each agent imposes (eq. 29)"}
    # 1.5 s is too short to reach the spacing: the claim must be able to fail
    spacing = [c for c in result["claims"] if "final position" in c["claim"]]
    assert not any(c["met"] for c in spacing)
    for d in result["variants"].values():
        assert d["steps"] == 15 and d["min_keepout_margin_m"] > 0 and d["min_los_margin_m"] > 0
    assert len(result["figures"]) == 2
    json.dumps(result)
    assert "claims of our run:" in repro.format_table(result)


def test_constraint_margins_sign():
    import numpy as np

    import satenv

    sc = satenv.make("platoon_v0", preset="pereira2022").scenario
    x = np.zeros((2, 2, 6))
    x[0, 0, :3] = (0, -10, 0)       # inside the cone, outside the sphere
    x[0, 1, :3] = (0, -20, 0)
    x[1, 0, :3] = (0, -3, 0)        # inside the sphere
    x[1, 1, :3] = (20, -3, 0)       # pair (20, 0, 0): outside the cone
    m = repro.constraint_margins(sc, x)
    assert m["keepout"][0, 0] == pytest.approx(4.0) and m["keepout"][1, 0] < 0
    assert m["los"][0].min() > 0 and m["los"][1, 1] < 0


def test_registered():
    assert reproduce.load("pereira2022-platoon") is repro


@pytest.mark.slow
def test_full_reproduction(tmp_path):
    out = tmp_path / "p22.json"
    rc = reproduce.main(["pereira2022-platoon", "--out", str(out)])
    data = json.loads(out.read_text())
    assert rc == (0 if data["pass"] else 1)
    own = [c for c in data["claims"] if c["gating"]]
    assert own and all(c["met"] for c in own), own
    coupled = data["variants"]["coupled"]
    assert coupled["keepout_violation_steps"] == 0 and coupled["los_violation_steps"] == 0
