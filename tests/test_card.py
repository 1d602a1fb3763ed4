"""satenv.training.card both ways: the network alone and as shipped, from each folder's own files."""

from __future__ import annotations

import json
import shutil

import pytest

from satenv import training
from satenv.training import card as cardmod
from satenv.training.card import (
    AS_SHIPPED,
    BOTH_WAYS_BEGIN,
    BOTH_WAYS_FILE,
    NETWORK_ALONE,
    NO_FILTER,
    both_ways,
    card,
    shipped_table,
    targets,
    update_readme,
)

FOLDERS = sorted(p for p in training.POLICIES_DIR.iterdir() if (p / "eval.json").is_file())


def _agg(episodes: int, successes: int, collisions: int, violations: int, **extra) -> dict:
    return {"episodes": episodes, "success_rate": successes / episodes, "collision_episodes": collisions,
            "violation_episodes": violations, "violations": float(violations), **extra}


def _both_ways(interventions: int, infeasible: int, agent_steps: int = 10_000) -> dict:
    """A both-ways evaluation (satenv.bench.safety_alone's folder format) with chosen counts."""
    ratios = {"matched_seeds": 4, "rmse_ratio": 1.1, "delta_v_ratio": 0.9}
    return {"test_seeds": list(range(900_000, 900_010)), "source": "x/safety_alone.json", "command": "python -m x",
            "system": "platoon-pereira2023", "task": "platoon-tplf30-random-cw", "controller": "dmpc",
            "controller_aggregate": _agg(5, 4, 1, 1),
            NETWORK_ALONE: {"aggregate": _agg(10, 9, 1, 3), "ratios_vs_controller": ratios},
            AS_SHIPPED: {"aggregate": _agg(4, 4, 0, 0, safety_interventions=interventions,
                                           safety_infeasible=infeasible, safety_agent_steps=agent_steps),
                         "ratios_vs_controller": ratios}}


@pytest.fixture
def filtered_folder(tmp_path):
    src = training.POLICIES_DIR / "platoon_tplf_ppo_shield"
    dst = tmp_path / "filtered"
    shutil.copytree(src, dst)
    (dst / BOTH_WAYS_FILE).unlink(missing_ok=True)
    return dst


def test_a_filtered_folder_is_read_both_ways_from_its_both_ways_file(filtered_folder):
    (filtered_folder / BOTH_WAYS_FILE).write_text(json.dumps(_both_ways(interventions=50, infeasible=2)))
    c = card(filtered_folder)
    assert c["filtered"] and c["evaluation"] == BOTH_WAYS_FILE and c["shipped"] == AS_SHIPPED
    assert (c["episodes"], c["success"], c["collision_episodes"], c["violation_episodes"]) == (4, 1.0, 0, 0)
    n = c["network_alone"]
    assert (n["episodes"], n["success"], n["collision_episodes"], n["violation_episodes"]) == (10, 0.9, 1, 3)
    assert c["interventions_per_agent_step"] == pytest.approx(0.005)
    assert c["infeasible_per_agent_step"] == pytest.approx(0.0002)
    assert c["baseline"] == "dmpc" and c["baseline_episodes"] == 5 and c["matched_seeds"] == 4
    met = targets(c)
    assert met["interventions"] and met["not_below_alone"] and all(met.values())


def test_the_filter_targets_can_fail(filtered_folder):
    ev = _both_ways(interventions=101, infeasible=0)          # 1.01 % of the agent-steps
    (filtered_folder / BOTH_WAYS_FILE).write_text(json.dumps(ev))
    assert not targets(card(filtered_folder))["interventions"]
    ev[AS_SHIPPED]["aggregate"]["success_rate"] = 0.5          # below the network alone's 0.9
    ev[AS_SHIPPED]["aggregate"]["safety_interventions"] = 1
    (filtered_folder / BOTH_WAYS_FILE).write_text(json.dumps(ev))
    met = targets(card(filtered_folder))
    assert met["interventions"] and not met["not_below_alone"]


def test_a_folder_shipped_without_the_filter_is_the_network_alone_both_ways():
    c = card(training.POLICIES_DIR / "platoon_tplf_ppo")
    assert not c["filtered"] and c["interventions_per_agent_step"] is None
    n = c["network_alone"]
    assert (n["success"], n["collision_episodes"], n["violation_episodes"]) == \
        (c["success"], c["collision_episodes"], c["violation_episodes"])
    assert n["violation_episodes"] is not None                 # counted from the episode records
    assert "interventions" not in targets(c)
    row = next(r for r in shipped_table().splitlines() if r.startswith("| `platoon_tplf_ppo` "))
    assert NO_FILTER in row


def test_every_filtered_shipped_folder_reports_interventions_and_infeasible_steps():
    for folder in FOLDERS:
        c = card(folder)
        if c["filtered"]:
            assert c["interventions_per_agent_step"] is not None, folder.name
            assert c["infeasible_per_agent_step"] is not None, folder.name
            assert c["network_alone"]["episodes"] > 0 and c["episodes"] > 0


def test_every_policy_readme_has_its_current_both_ways_section():
    for folder in FOLDERS:
        text = (folder / "README.md").read_text()
        assert both_ways(folder) in text, (f"{folder.name}/README.md: the both-ways section is stale: "
                                           "run `python -m satenv.training.card --readmes`")


def test_update_readme_inserts_the_section_once_then_replaces_it(filtered_folder):
    (filtered_folder / BOTH_WAYS_FILE).write_text(json.dumps(_both_ways(interventions=50, infeasible=2)))
    readme = filtered_folder / "README.md"
    readme.write_text("# title\n\nintro\n\n## Later\n\ntext\n")
    assert update_readme(filtered_folder)
    text = readme.read_text()
    assert text.startswith("# title\n\nintro\n\n" + BOTH_WAYS_BEGIN) and text.endswith("## Later\n\ntext\n")
    assert not update_readme(filtered_folder)                  # already current
    (filtered_folder / BOTH_WAYS_FILE).write_text(json.dumps(_both_ways(interventions=70, infeasible=2)))
    assert update_readme(filtered_folder)
    text = readme.read_text()
    assert text.count(BOTH_WAYS_BEGIN) == 1 and "0.7 %" in text


def test_the_command_line_refuses_an_unknown_folder_and_has_a_help(capsys):
    with pytest.raises(SystemExit) as exit_:
        cardmod.main(["no_such_policy"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "error: NAME 'no_such_policy': expected a shipped policy" in err
    with pytest.raises(SystemExit) as exit_:
        cardmod.main(["--help"])
    out = capsys.readouterr().out
    assert exit_.value.code == 0 and "--readmes" in out and "``" not in out and ":data:" not in out


def test_the_perturbations_are_a_table_of_each_variant_beside_the_controller():
    """A both-ways file with a ``perturbations`` block gets one row per perturbation and variant
    (the controller's on its own, shorter seed count); without the block, no table."""
    ev = {"perturbations": {"seeds": [900_000, 900_009],
                            "nav-1m": {NETWORK_ALONE: _agg(10, 0, 10, 10, delta_v=36.0),
                                       AS_SHIPPED: _agg(10, 1, 0, 0, delta_v=260.0,
                                                        interventions_per_agent_step=0.394),
                                       "controller": _agg(3, 1, 2, 2, delta_v=85.0)},
                            "thrust-80": {NETWORK_ALONE: _agg(10, 10, 0, 0, delta_v=1.0),
                                          AS_SHIPPED: _agg(10, 10, 0, 0, delta_v=1.0),
                                          "controller": {"error": "BaselineError: refuses the wrapped env"}}}}
    lines = cardmod.perturbation_table(ev, "tube_rdmpc")
    rows = [line for line in lines if line.startswith("| nav-1m") or line.startswith("| thrust-80")]
    assert rows == ["| nav-1m | network alone | 10 | 0.00 | 10/10 | 10/10 | 36.0 | – |",
                    "| nav-1m | as shipped | 10 | 0.10 | 0/10 | 0/10 | 260.0 | 39.4 % |",
                    "| nav-1m | controller | 3 | 0.33 | 2/3 | 2/3 | 85.0 | – |",
                    "| thrust-80 | network alone | 10 | 1.00 | 0/10 | 0/10 | 1.0 | – |",
                    "| thrust-80 | as shipped | 10 | 1.00 | 0/10 | 0/10 | 1.0 | – |"]
    assert "900000-900009" in lines[1] and "`tube_rdmpc`" in lines[1]
    assert cardmod.perturbation_table({}, "dmpc") == []
