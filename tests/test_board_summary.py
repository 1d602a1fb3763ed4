"""The scoreboard's summary (satenv.bench.scoreboard.headline): best scripted vs best learned per
system, ratios on matched completed episodes, the markdown section, the figure, re-aggregation."""

import json

import pytest

from satenv.bench.scoreboard import TASKS, ScoreboardError, aggregate, rank
from satenv.bench.scoreboard.board import reaggregate
from satenv.bench.scoreboard.headline import (
    FIGURE,
    headline,
    headline_figure,
    headline_section,
    is_learned,
    paper_systems,
)
from satenv.bench.scoreboard.registry import discover_trained_policies

SCEN = "cluster-case1-random"


def _ep(policy, seed, success=True, rmse=1.0, delta_v=1.0, collisions=0, terminated=False,
        scenario=SCEN, error=None):
    if error is not None:   # as satenv.bench.scoreboard.runner.error_record writes it
        return {"scenario": scenario, "policy": policy, "seed": seed, "error": error, "success": False}
    rec = {m: 0.0 for m in ("rmsee", "foe", "final_error_m", "min_separation_m", "violations", "safety_cost",
                            "fallbacks", "compute_ms_per_decision", "episode_return", "steps")}
    return rec | {"scenario": scenario, "policy": policy, "seed": seed, "env": "cluster_v0", "error": None,
                  "success": success, "rmse": rmse, "delta_v": delta_v, "collisions": collisions,
                  "terminated": terminated, "time_to_converge_s": None}


def _rows(records, systems=None):
    agg = aggregate(records)
    return headline(records, {s: rank(agg[s]) for s in agg},
                    systems if systems is not None else {"cluster": (SCEN, "cluster-case1")})


def test_systems_name_registered_scenarios_ranked_for_a_shipped_policy():
    ranked = {s for spec in discover_trained_policies().values() for s in spec.tasks or ()}
    for system, names in paper_systems().items():
        assert names and set(names) <= set(TASKS), system
        assert names[0] in ranked, f"{system}: no shipped policy is ranked on {names[0]}"


def test_learned_names():
    assert is_learned("trained:a") and is_learned("trained:a+shield") and is_learned("user:run")
    assert not is_learned("dmpc") and not is_learned("dmpc+shield")


def test_best_of_each_kind_by_the_board_ranking():
    records = [_ep("zero", s, success=False, rmse=9.0) for s in range(4)]
    records += [_ep("apf", s, success=s < 2) for s in range(4)]
    records += [_ep("tube_rdmpc", s, rmse=2.0) for s in range(4)]
    records += [_ep("trained:a", s, rmse=1.5) for s in range(4)]               # best learned: lower RMSE
    records += [_ep("trained:a+shield", s, rmse=1.8) for s in range(4)]
    records += [_ep("trained:b", s, success=s == 0, rmse=0.1) for s in range(4)]  # lowest RMSE, worse success
    (row,) = _rows(records)
    assert (row["system"], row["task"]) == ("cluster", SCEN)
    assert row["scripted"]["policy"] == "tube_rdmpc" and row["learned"]["policy"] == "trained:a"
    assert row["scripted"]["success"] == 1.0 and row["scripted"]["episodes"] == 4
    assert row["ratios"] == {"matched_seeds": 4, "rmse_ratio": pytest.approx(0.75), "delta_v_ratio": 1.0}
    assert "unfiltered" not in row["learned"]
    shielded = [r | {"rmse": 1.0} if r["policy"] == "trained:a+shield" else r for r in records]
    (row,) = _rows(shielded)
    assert row["learned"]["policy"] == "trained:a+shield"
    assert row["learned"]["unfiltered"]["policy"] == "trained:a"
    assert "`trained:a+shield` (network alone: `trained:a`)" in "\n".join(headline_section([row]))


def test_ratios_only_on_matched_completed_episodes():
    """An early-terminated learned episode with a tiny delta-v (and a collision, an error) must not
    enter the ratios: on the one clean seed they are 2.0, with all seeds they would be < 1."""
    records = [_ep("dmpc", 0, rmse=1.0, delta_v=2.0), _ep("trained:x", 0, rmse=2.0, delta_v=4.0),
               _ep("dmpc", 1, rmse=1.0, delta_v=2.0),
               _ep("trained:x", 1, success=False, rmse=0.01, delta_v=0.01, terminated=True),
               _ep("dmpc", 2, rmse=1.0, delta_v=2.0, collisions=3, success=False),
               _ep("trained:x", 2, rmse=0.01, delta_v=0.01),
               _ep("dmpc", 3, rmse=1.0, delta_v=2.0), _ep("trained:x", 3, error="RuntimeError: boom"),
               _ep("trained:x", 4, rmse=0.01, delta_v=0.01)]                 # no scripted episode
    (row,) = _rows(records)
    assert row["ratios"] == {"matched_seeds": 1, "rmse_ratio": 2.0, "delta_v_ratio": 2.0}
    assert row["learned"]["collision_episodes"] == 0 and row["scripted"]["collision_episodes"] == 1
    assert row["learned"]["errors"] == 1


def test_no_matched_seed_no_ratio_and_missing_kind():
    records = [_ep("dmpc", s) for s in range(3)] + [_ep("trained:x", s, terminated=True) for s in range(3)]
    (row,) = _rows(records)
    assert row["ratios"] == {"matched_seeds": 0, "rmse_ratio": None, "delta_v_ratio": None}
    line = headline_section([row])[-4]
    assert line.endswith("| – | – | 0 |"), line
    (only,) = _rows([_ep("dmpc", s, scenario="cluster-case1") for s in range(2)])  # fallback scenario
    assert only["task"] == "cluster-case1" and only["learned"] is None
    assert only["ratios"]["matched_seeds"] == 0
    assert _rows([_ep("dmpc", 0, scenario="platoon-PLF-cw")]) == []            # system not on the board


def test_section_and_figure(tmp_path):
    records = [_ep("dmpc", s) for s in range(3)] + [_ep("trained:x", s, success=s > 0) for s in range(3)]
    records[4]["violations"] = 2                                   # one learned episode breaks a bound
    rows = _rows(records) + _rows([_ep("cgmres", 0, scenario="formation-kannan2022-position")],
                                  {"formation": ("formation-kannan2022-position",)})
    text = "\n".join(headline_section(rows))
    assert "## Summary: best scripted and best learned policy per system" in text
    assert ("| cluster | `cluster-case1-random` | `dmpc` | 100 % (3/3) | 0/3 | 0/3 | `trained:x` | 67 % (2/3) "
            "| 0/3 | 1/3 |") in text
    assert f"]({FIGURE})" in text and FIGURE not in "\n".join(headline_section(rows, figure=False))
    assert headline_section([]) == []
    path = headline_figure(rows, tmp_path / "h.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _header(scenarios, policies):
    return {"title": "t", "satenv_version": "0", "env_versions": ["cluster_v0"], "seeds": [0, 1],
            "generated": "now", "ranking": "success", "notes": [],
            "machine": {"cpu": "c", "cpus": 1, "platform": "p", "python": "3", "numpy": "2"},
            "scenarios": {s: {"env": "cluster_v0", "description": s, "success_tol_m": 1.0} for s in scenarios},
            "policies": {p: {"description": p} for p in policies}}


def test_reaggregate_writes_the_summary_at_the_top(tmp_path):
    records = [_ep(p, s, scenario=sc) for sc in ("cluster-case1", SCEN) for p in ("tube_rdmpc", "trained:x")
               for s in (1, 0)]
    records.append(_ep("trained:x", 0, scenario=SCEN, rmse=5.0))  # a repeated key: the first line counts
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    (tmp_path / "scoreboard.json").write_text(json.dumps({"header": _header(["cluster-case1", SCEN],
                                                                            ["tube_rdmpc", "trained:x"])}))
    board = reaggregate(tmp_path, plots=False)
    md = (tmp_path / "scoreboard.md").read_text()
    assert md.index("## Summary: best scripted") < md.index("## cluster-case1 (")
    assert list(board.aggregates) == ["cluster-case1", SCEN] and len(board.records) == 8
    assert [(r["policy"], r["seed"]) for r in board.records[:4]] == [
        ("tube_rdmpc", 0), ("tube_rdmpc", 1), ("trained:x", 0), ("trained:x", 1)]
    assert board.headline[0]["ratios"]["rmse_ratio"] == 1.0
    assert FIGURE not in md and not (tmp_path / "plots").exists()
    assert json.loads((tmp_path / "scoreboard.json").read_text())["headline"][0]["task"] == SCEN
    (tmp_path / "scoreboard.json").unlink()
    with pytest.raises(ScoreboardError, match="scoreboard.json"):
        reaggregate(tmp_path)


def test_a_policy_shipped_with_its_filter_has_its_network_alone_beside_it():
    import satenv
    from satenv.safety import Shield

    specs = discover_trained_policies()
    name = "trained:platoon_pereira2022_dagger_shield"
    assert name + ":network" in specs and "trained:platoon_tplf_ppo:network" not in specs
    env = satenv.platoon_v0(preset="pereira2022", randomize=True)
    assert isinstance(specs[name].make(env), Shield)
    assert not isinstance(specs[name + ":network"].make(env), Shield)
    assert specs[name].fingerprint() != specs[name + ":network"].fingerprint()
    records = [_ep("tube_rdmpc", s) for s in range(2)] + [_ep("trained:s", s) for s in range(2)]
    records += [_ep("trained:s:network", s, success=False, collisions=1) for s in range(2)]
    (row,) = _rows(records)
    assert row["learned"]["policy"] == "trained:s"
    assert row["learned"]["unfiltered"]["policy"] == "trained:s:network"
    assert row["learned"]["unfiltered"]["collision_episodes"] == 2


def test_shield_twins_skip_a_policy_shipped_with_its_filter():
    from satenv.bench.scoreboard.plan import select

    registry = {**discover_trained_policies()}
    notes: list[str] = []
    sel = select(["trained:*+shield"], registry, "policy", notes, strict=True)
    assert "trained:platoon_tplf_ppo+shield" in sel.names
    assert not any(n.startswith("trained:platoon_pereira2022_dagger_shield") for n in sel.names)
    notes = []
    sel = select(["trained:platoon_pereira2022_dagger_shield+shield"], registry, "policy", notes, strict=True)
    assert not sel.names and "ships behind the safety filter already" in notes[0]


def test_a_filtered_policy_shows_its_interventions_per_agent_step_old_records_included(tmp_path):
    """Behind the filter: the share of agent-steps it changed, in the scenario table and the
    summary; an older record (interventions only) gets it from its steps and the env's agents."""
    records = [_ep("tube_rdmpc", s) for s in range(2)]
    records += [_ep("trained:s", s) | {"steps": 400.0, "interventions": k, "mean_du": 0.1, "infeasible_steps": 0}
                for s, k in ((0, 400), (1, 1200))]                   # no rate: written before it existed
    records += [_ep("trained:s:network", s, success=False, collisions=1) for s in range(2)]
    (tmp_path / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    header = _header([SCEN], ["tube_rdmpc", "trained:s", "trained:s:network"])
    header["scenarios"][SCEN]["kwargs"] = {"preset": "li2022-case1", "randomize": True}
    (tmp_path / "scoreboard.json").write_text(json.dumps({"header": header}))
    board = reaggregate(tmp_path, plots=False)
    rates = [r.get("interventions_per_agent_step") for r in board.records if r["policy"] == "trained:s"]
    assert rates == [pytest.approx(400 / 4000), pytest.approx(1200 / 4000)]          # 10 satellites
    assert board.aggregates[SCEN]["trained:s"]["interventions_per_agent_step"]["mean"] == pytest.approx(0.2)
    (row,) = board.headline
    assert row["learned"]["interventions_per_agent_step"] == pytest.approx(0.2)
    assert row["learned"]["unfiltered"]["interventions_per_agent_step"] is None
    md = (tmp_path / "scoreboard.md").read_text()
    assert "| interventions / agent-step |" in md and "| 20 % |" in md


def test_an_episode_behind_the_filter_records_its_share_of_agent_steps():
    import numpy as np

    import satenv
    from satenv.rollout import rollout
    from satenv.safety import shield
    from satenv.scoring import episode_record

    class FullThrust:
        def reset(self, seed=None):
            pass

        def act(self, obs):
            return {a: np.ones(3, dtype=np.float32) for a in obs}

    env = satenv.platoon_v0(preset="pereira2022", randomize=True, max_steps=6)
    traj = rollout(env, shield(FullThrust(), env), seed=0)
    rec = episode_record(traj, 0, len(env.possible_agents))
    assert rec["interventions_per_agent_step"] == pytest.approx(
        rec["safety_interventions"] / (traj.steps * len(env.possible_agents)))
    plain = episode_record(rollout(env, FullThrust(), seed=0), 0, len(env.possible_agents))
    assert "safety_interventions" not in plain and "interventions_per_agent_step" not in plain
