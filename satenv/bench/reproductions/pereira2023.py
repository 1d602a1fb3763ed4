"""Reproduce pereira2023 Table II: the 1-hop DMPC on the Table I platoon, PLF / BDL / TPLF.

Runs ``satenv.platoon_v0(preset="pereira2023", topology=T, terminate_on_collision=False)`` with
``satenv.baselines.dmpc.DMPC`` (defaults: DAQP, sigma = 0.5, seeded random initial sequence, shifted
warm start) through ``satenv.rollout`` and measures RMSE / RMSEE / FOE with ``satenv.metrics``
(the tracking error is ``E_f - (g_f + d_f) E_d``, eq. 15). The formation of Table I brings bodies
closer than ``2 r_f`` (see ``satenv.envs.platoon_v0``), hence ``terminate_on_collision=False``;
the collision flags are reported, not hidden.

Claims (``result["claims"]``, :mod:`satenv.bench.claims`), each quoting its Table II cell: every
RMSE, RMSEE and FOE within +-10 % of the paper's value, and per topology the constraints
respected (§IV: "while respecting the constraints"; 0 violations). Whether the error converges
has no value of its own in the paper beyond the FOE cells ("paper gives no value"). The FOE
analysis (:func:`foe_analysis`: per cell the ratio to Table II and the tail delay; each setting
varied and how much it moved the FOE) and :data:`PLF_TPLF_NOTE` (why followers 1-2 are identical
in PLF and TPLF, measured as the largest state difference) are on the page; the departures
(:func:`departures`) include the velocity margin, whose effect is measured in the same run.
Also reported per row: ``rmse_unscaled_ed``, the RMSE of ``E_f - E_d`` (E_d not multiplied by
``g_f + d_f``), the other reading of the paper's metric.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from satenv.bench._io import progress
from satenv.bench.claims import (
    NOT_STATED,
    band,
    departure,
    format_claims,
    no_value,
    passed,
    statement,
)
from satenv.bench.reproductions import figure_paths

PAPER = "pereira2023"
TOPOLOGIES = ("PLF", "BDL", "TPLF")

# Table II of pereira2023: (RMSE, RMSEE [m/s^2], FOE) per follower and network.
TABLE_II: dict[str, list[tuple[float, float, float]]] = {
    "PLF": [(19.781, 4.930, 3.262e-6), (36.932, 4.807, 4.873e-6),
            (40.557, 4.884, 6.726e-6), (31.953, 3.985, 4.670e-6)],
    "BDL": [(41.506, 4.697, 7.180e-6), (44.486, 4.682, 5.385e-6),
            (50.787, 4.346, 1.035e-5), (33.542, 4.836, 7.941e-6)],
    "TPLF": [(19.980, 5.064, 3.783e-6), (36.829, 4.840, 4.727e-6),
             (71.448, 4.665, 1.419e-5), (58.155, 4.214, 8.990e-6)],
}
SOURCE_TABLE = "TABLE II: Simulation performance of the DMPC for spacecraft platooning"
SOURCE_CONSTRAINTS = ("In all scenarios the proposed strategy manages to successfully converge the error to the "
                      "desired values, while respecting the constraints that were imposed for each topology and "
                      "with a behavior that goes according to the considered penalties.")
VARIATIONS: dict[str, dict[str, Any]] = {
    "stopping rule 'all'": {"stopping": "all"},
    "sigma 1e-6": {"sigma": 1e-6},
    "warm start 'previous'": {"warm_start": "previous"},
    "initial sequence zeros": {"initial": "zeros"},
    "seed 1 (random initial sequence)": {"seed": 1},
    "minimum-error constraint (41)-(42) on (the paper's)": {"min_error_constraint": True},
    "velocity margin 0 (the paper's box (40))": {"velocity_margin": 0.0},
    "horizon N = 40": {"horizon": 40},
    "unconstrained": {"constrained": False},
}
"""FOE analysis: DMPC settings varied one at a time (``DMPCConfig`` fields) against our default."""
PAPER_OPTIONS: dict[str, Any] = {"warm_start": "previous", "min_error_constraint": True, "velocity_margin": 0.0}
"""The as-published run: Algorithm 1 line 6 (Û(0) <- U*(k-1), the previous optimal sequence
unshifted), the minimum-error constraint (41)-(42) imposed (Fig. 8) and the velocity box (40)
without our margin (``DMPCConfig`` fields against our default)."""
VARIANTS = {"ours": {}, "as published": PAPER_OPTIONS}
"""Run -> DMPC options."""
METRICS = ("rmse", "rmsee", "foe")
SOURCE_MOST = ("Yet they provide further insight, as for most cases the best values are obtained for the PLF "
               "topology.")
SOURCE_F1 = ("Comparing the PLF and TPLF for follower 1, which present the same initial conditions and the same "
             "desired value, it can be concluded that the PLF has slightly superior results, especially when "
             "observing the control action and results of Table II.")
SOURCE_F2 = "From Table II it can also be concluded that the PLF has slightly worse results than TPLF."
SOURCE_F2_INPUT = ("behaviors, the most significant difference being in the control action at $x$ where the PLF "
                   "topology shows more oscillation.")
SOURCE_F3 = "In the control action, the BDL presents significantly more oscillation than the other topologies."
SOURCE_F4_FIG = "Of these two topologies, the PLF is faster and with less overshoot."
SOURCE_F4 = "This comparison is also seen in Table II, where PLF performs better on all criteria."
SOURCE_TRANSIENT = ("It can also be seen that the TPLF has in general better performance in the transient "
                    "networks response.")
SOURCE_TRUSTWORTHY = ("And finally, the 1-hop interactive local optimization algorithm proposed, results in a more "
                      "trustworthy solution, when compared to the simple convex step distributed algorithm used in "
                      "[21], for this cooperative scenario.")
SETTLING_FRACTION = 0.02
"""Settling time of a follower: the time after which its position error stays within this
fraction of its largest value (our measure of "faster" for the figure sentences)."""
RUN_TIME = "about 1-3 min (2-8 s for Table II ours and as published, the rest for the FOE analysis)"

FOE_NOTE = (
    "FOE is the tail of a mode that decays by the measured rate per step (the slow closed-loop pole "
    "of Q = 13 I, W = 0.1 I) over the whole episode, so it is the slow-mode amplitude times ~e^-18: "
    "'steps_behind' = ln(FOE / paper) / ln(1 / rate) is the delay of our tail behind the paper's. "
    "The FOE analysis varies one DMPC setting at a time and reports the range of FOE / Table II over "
    "the 12 cells and the largest change of a cell's FOE against our default.")
PLF_TPLF_NOTE = (
    "Followers 1 and 2 hear the same agents (leader; leader and follower 1) with the same g+d in "
    "PLF and TPLF and nothing flows back from followers 3-4, so under Algorithm 1 (per-agent "
    "stopping) their problems, states and inputs are identical in both topologies; the paper's "
    "different numbers (19.781 vs 19.980, 36.932 vs 36.829) cannot come from the stated "
    "algorithm and data (follower 1's QP involves no other agent's plan, so neither the random "
    "initial sequence nor the stopping rule can change it).")


def run_topology(topology: str, seed: int = 0, **dmpc_options):
    """One Table I episode under ``topology``; returns ``(trajectory, env, policy)``."""
    import satenv
    from satenv.baselines.dmpc import DMPC
    from satenv.rollout import rollout

    env = satenv.make("platoon_v0", preset=PAPER, topology=topology, terminate_on_collision=False)
    policy = DMPC(env, seed=seed, **dmpc_options)
    traj = rollout(env, policy, seed=seed)
    return traj, env, policy


def _foe(seed: int, **dmpc_options) -> tuple[dict[tuple[str, int], float], int]:
    """FOE per (topology, follower) of one run of the three topologies, and its violations."""
    from satenv import metrics

    out, violations, rmse_err = {}, 0, 0.0
    for topo in TOPOLOGIES:
        traj, _env, _pol = run_topology(topo, seed=seed, **dmpc_options)
        out.update({(topo, f + 1): float(v) for f, v in enumerate(metrics.foe(traj))})
        violations += metrics.violations(traj)
        rmse_err = max([rmse_err] + [abs(v / TABLE_II[topo][f][0] - 1) for f, v in enumerate(metrics.rmse(traj))])
    return out, violations, rmse_err


def foe_analysis(rows: list[dict], seed: int = 0, violations: int | None = None) -> list[dict[str, Any]]:
    """Each :data:`VARIATIONS` entry: FOE / Table II over the 12 cells (min, max) and the largest
    relative change of a cell's FOE against our default (what moved it)."""
    base = {(r["topology"], r["follower"]): r["foe"] for r in rows}
    paper = {(r["topology"], r["follower"]): r["paper_foe"] for r in rows}
    out = [{"setting": "our default (Table I, sigma = 0.5, per-agent stopping, shift warm start)",
            "foe_ratio_min": min(base[k] / paper[k] for k in base),
            "foe_ratio_max": max(base[k] / paper[k] for k in base),
            "max_change_vs_default": 0.0, "cells_within_10pct": sum(abs(base[k] / paper[k] - 1) <= 0.1 for k in base),
            "violations": violations, "rmse_worst_rel_err": max(abs(r["rmse_rel_err"]) for r in rows)}]
    for name, opts in VARIATIONS.items():
        progress(f"pereira2023: FOE analysis, {name} ...")
        seed_v = opts.get("seed", seed)
        foe, violations, rmse_err = _foe(seed_v, **{k: v for k, v in opts.items() if k != "seed"})
        out.append({"setting": name, "foe_ratio_min": min(foe[k] / paper[k] for k in foe),
                    "foe_ratio_max": max(foe[k] / paper[k] for k in foe),
                    "max_change_vs_default": max(abs(foe[k] / base[k] - 1) for k in foe),
                    "cells_within_10pct": sum(abs(foe[k] / paper[k] - 1) <= 0.1 for k in foe),
                    "violations": violations, "rmse_worst_rel_err": rmse_err})
    return out


def _table_rows(traj, env, topo: str) -> list[dict[str, Any]]:
    """The Table II rows of one topology's episode, with the transient measures the figure
    sentences are judged on (settling time, overshoot, input sign changes)."""
    from satenv import metrics

    rmse, rmsee, foe = metrics.rmse(traj), metrics.rmsee(traj), metrics.foe(traj)
    e_d = np.asarray(env.scenario.desired_error)
    unscaled = traj.info["neighbourhood_error"][:-1] - e_d
    rmse_unscaled = np.sqrt(np.mean(np.sum(unscaled**2, axis=-1), axis=0))
    err = np.linalg.norm(traj.info["tracking_error"], axis=-1)
    rate = err[-1] / err[-2]
    pos = np.asarray(traj.info["tracking_error"])[..., :3]
    u = np.asarray(traj.info["accel"])[1:]
    rows = []
    for f in range(env.scenario.n_followers):
        p_rmse, p_rmsee, p_foe = TABLE_II[topo][f]
        n = np.linalg.norm(pos[:, f], axis=-1)
        outside = np.nonzero(n > SETTLING_FRACTION * n.max())[0]
        settle = float(traj.t[min(outside[-1] + 1, len(n) - 1)]) if outside.size else 0.0
        sign0 = np.sign(pos[0, f])
        overshoot = float(max(0.0, np.max(-sign0 * pos[:, f])))
        signs = np.sign(np.where(np.abs(u[:, f]) > 1e-9, u[:, f], 0.0))
        flips = [int(np.sum(np.abs(np.diff(s[s != 0])) > 0)) for s in signs.T]
        rows.append({
            "topology": topo, "follower": f + 1,
            "rmse": float(rmse[f]), "rmsee": float(rmsee[f]), "foe": float(foe[f]),
            "paper_rmse": p_rmse, "paper_rmsee": p_rmsee, "paper_foe": p_foe,
            "rmse_rel_err": float(rmse[f] / p_rmse - 1.0),
            "rmsee_rel_err": float(rmsee[f] / p_rmsee - 1.0),
            "foe_ratio": float(foe[f] / p_foe),
            "tail_rate": float(rate[f]),
            "steps_behind": float(np.log(foe[f] / p_foe) / np.log(1.0 / rate[f])),
            "rmse_unscaled_ed": float(rmse_unscaled[f]),
            "settling_time_s": settle, "overshoot_m": overshoot,
            "input_sign_changes": int(sum(flips)), "input_sign_changes_x": flips[0],
        })
    return rows


def _per_topology(traj, policy) -> dict[str, Any]:
    from satenv import metrics

    qp_ms = np.asarray(policy.info["qp_ms"])
    return {
        "collision_steps": metrics.collisions(traj),
        "min_separation_m": metrics.min_separation(traj),
        "violations": metrics.violations(traj),
        "fallbacks": int(policy.info["fallbacks"]),
        "not_converged": int(policy.info["not_converged"]),
        "mean_jacobi_iterations": float(np.mean(policy.info["iterations"])),
        "max_jacobi_iterations": int(np.max(policy.info["iterations"])),
        "jacobi_iteration_cap": int(policy.cfg.max_iterations),
        "median_qp_ms": float(np.median(qp_ms)) if qp_ms.size else 0.0,
        "median_decision_ms": float(np.median(policy.info["solve_ms"])),
        "steps": traj.steps,
    }


def reproduce(plots: str | Path | None = None, seed: int = 0, analysis: bool = True,
              variant: str = "both") -> dict[str, Any]:
    """Run the three topologies ours and (``variant="both"``) as published (:data:`PAPER_OPTIONS`),
    compare with Table II and the paper's comparative sentences; the FOE analysis (``analysis``)
    and optionally the figures (``plots``, our run)."""
    if variant not in ("ours", "both"):
        raise ValueError(f"variant must be 'ours' or 'both', got {variant!r}")
    start = time.perf_counter()
    runs, by_variant = {}, {}
    for name, opts in VARIANTS.items():
        if variant == "ours" and name != "ours":
            continue
        rows, per_topology = [], {}
        for topo in TOPOLOGIES:
            progress(f"pereira2023: {name}, {topo} ...")
            traj, env, policy = run_topology(topo, seed=seed, **opts)
            if name == "ours":
                runs[topo] = (traj, env)
            rows += _table_rows(traj, env, topo)
            per_topology[topo] = _per_topology(traj, policy)
        by_variant[name] = {"rows": rows, "per_topology": per_topology}
    rows, per_topology = by_variant["ours"]["rows"], by_variant["ours"]["per_topology"]
    plf, tplf = runs["PLF"][0].states, runs["TPLF"][0].states
    checks = [c for name, v in by_variant.items()
              for c in check_claims(v["rows"], v["per_topology"], variant=name)]
    violations = sum(d["violations"] for d in per_topology.values())
    foe_rows = foe_analysis(rows, seed=seed, violations=violations) if analysis else []
    published = by_variant.get("as published")
    result = {
        "paper": PAPER, "rows": rows, "claims": checks, "per_topology": per_topology, "seed": seed,
        "notes": {"foe": FOE_NOTE, "plf_tplf_followers_1_2": PLF_TPLF_NOTE},
        "plf_tplf_followers_1_2_max_state_difference": float(np.abs(plf[:, :2] - tplf[:, :2]).max()),
        "foe_analysis": foe_rows,
        "departures": departures(foe_rows, published, per_topology),
        "settings": {"env": "platoon_v0(preset='pereira2023', terminate_on_collision=False)",
                     "policy": "satenv.baselines.dmpc.DMPC (one_hop, daqp, sigma=0.5, per-agent stopping, "
                               "warm_start='shift')",
                     "as_published": dict(PAPER_OPTIONS),
                     "metric": "tracking error E_f - (g_f + d_f) E_d (eq. 15)"},
    }
    if published is not None:
        result["as_published"] = published
    result["pass"] = passed(result)
    if plots is not None:
        result["figures"] = figure_paths(save_figures(runs, Path(plots)), plots)
    result["wall_time_s"] = time.perf_counter() - start
    return result


def _cell(r: dict, metric: str) -> str:
    i = {"rmse": 0, "rmsee": 1, "foe": 2}[metric]
    return (f"{SOURCE_TABLE}: f = {r['follower']}, {r['topology']}, {metric.upper()} = "
            f"{TABLE_II[r['topology']][r['follower'] - 1][i]:g}")


def check_claims(rows: list[dict], per_topology: dict[str, dict], variant: str = "ours") -> list[dict[str, Any]]:
    """Table II per cell (RMSE, RMSEE, FOE within +-10 %), per topology the constraints respected
    (§IV) and the error converged (no value of its own), and the paper's comparative sentences
    (:func:`comparative_claims`)."""
    out = []
    for r in rows:
        cell = {"topology": r["topology"], "follower": r["follower"]}
        label = f"{r['topology']} follower {r['follower']}"
        out.append(band(f"RMSE {label}", _cell(r, "rmse"), r["paper_rmse"], r["rmse"], variant=variant, **cell))
        out.append(band(f"RMSEE {label} [m/s^2]", _cell(r, "rmsee"), r["paper_rmsee"], r["rmsee"], variant=variant,
                        **cell))
        out.append(band(f"FOE {label}", _cell(r, "foe"), r["paper_foe"], r["foe"], variant=variant,
                        note="see the FOE analysis", foe_ratio=r["foe_ratio"], **cell))
    for topo, d in per_topology.items():
        worst = max(r["foe"] for r in rows if r["topology"] == topo)
        out.append(no_value(f"{topo} error converges (max FOE)", SOURCE_CONSTRAINTS, worst, variant=variant,
                            ours=f"max FOE <= 1e-4: {'met' if worst <= 1e-4 else 'not met'}", topology=topo))
        out.append(statement(f"{topo} constraints (39)-(40) respected (violations)", SOURCE_CONSTRAINTS,
                             0, d["violations"], d["violations"] == 0, rule="0 violations", variant=variant,
                             fallbacks=d["fallbacks"], topology=topo))
    return out + comparative_claims(rows, variant)


def _values(rows: list[dict], follower: int, topo: str) -> list[float]:
    r = next(r for r in rows if r["follower"] == follower and r["topology"] == topo)
    return [r[m] for m in METRICS]


def _paper_values(follower: int, topo: str) -> list[float]:
    return list(TABLE_II[topo][follower - 1])


def _lower(a: list[float], b: list[float]) -> int:
    """How many of the metrics are strictly lower in ``a`` than in ``b``."""
    return sum(x < y for x, y in zip(a, b, strict=True))


MOST_RULE = ("the best (lowest) value of a cell is 'obtained for the PLF topology' when PLF attains it, shared "
             "or not: the sentence names where the best values are obtained, not that PLF alone obtains them; "
             "'most cases': more than 6 of the 12 (follower, metric) cells")
"""The rule of the PLF "most cases" claim, read from its sentence (:data:`SOURCE_MOST`)."""


def _best_cells(values, ties: bool = True) -> list[tuple[int, str]]:
    """(follower, metric) cells where PLF has the lowest value of the three topologies (``ties``:
    shared with another topology counts; else PLF strictly lowest)."""
    out = []
    for f in (1, 2, 3, 4):
        for k, m in enumerate(METRICS):
            v = {t: values(f, t)[k] for t in TOPOLOGIES}
            if all(v["PLF"] <= v[t] if ties else v["PLF"] < v[t] for t in TOPOLOGIES if t != "PLF"):
                out.append((f, m))
    return out


def _orderings(rows: list[dict]) -> int:
    """(follower, metric) cells whose ranking of the three topologies matches Table II's."""
    same = 0
    for f in (1, 2, 3, 4):
        for k in range(len(METRICS)):
            ours = sorted(TOPOLOGIES, key=lambda t: _values(rows, f, t)[k])
            paper = sorted(TOPOLOGIES, key=lambda t: _paper_values(f, t)[k])
            same += ours == paper
    return same


def comparative_claims(rows: list[dict], variant: str = "ours") -> list[dict[str, Any]]:
    """Each sentence of pereira2023 §IV that names a winner among the topologies, judged on our
    Table II (statements; the paper's own Table II satisfies each rule, checked in the tests) or,
    where it reads a figure, reported with our measure of it (no paper value)."""
    tag = {"variant": variant}
    ours = _best_cells(lambda f, t: _values(rows, f, t))
    strict = _best_cells(lambda f, t: _values(rows, f, t), ties=False)
    paper = _best_cells(_paper_values)
    out = [statement("PLF gives the best value in most (follower, metric) cells [cells of 12]", SOURCE_MOST,
                     len(paper), len(ours), len(ours) > 6,
                     rule=f"PLF has the lowest value, shared or not, in more than 6 of the 12 cells ({MOST_RULE}; "
                          f"Table II: {len(paper)})",
                     cells=[f"f{f} {m}" for f, m in ours], cells_with_ties=len(ours), cells_strict=len(strict),
                     table_ii_cells_with_ties=len(paper), table_ii_cells_strict=len(_best_cells(_paper_values, False)),
                     table_ii_ordering_reproduced=_orderings(rows),
                     note=f"judged on the count with ties ({len(ours)} of 12); PLF strictly lowest (no tie): "
                          f"{len(strict)} of 12 (PLF and TPLF are identical for followers 1-2 by construction, so "
                          f"they tie there); cells whose ranking of PLF / BDL / TPLF matches Table II's: "
                          f"{_orderings(rows)} of 12", **tag)]
    pairs = [("follower 1: PLF better than TPLF on Table II [metrics lower of 3]", SOURCE_F1, 1, "PLF", "TPLF", 2),
             ("follower 2: TPLF better than PLF on Table II [metrics lower of 3]", SOURCE_F2, 2, "TPLF", "PLF", 2),
             ("follower 4: PLF better than BDL on all criteria [metrics lower of 3]", SOURCE_F4, 4, "PLF", "BDL", 3)]
    for name, src, f, win, lose, need in pairs:
        got = _lower(_values(rows, f, win), _values(rows, f, lose))
        ref = _lower(_paper_values(f, win), _paper_values(f, lose))
        out.append(statement(name, src, ref, got, got >= need,
                             rule=f"{win} lower than {lose} on at least {need} of RMSE, RMSEE, FOE "
                                  f"(Table II: {ref} of 3)",
                             **{win: _values(rows, f, win), lose: _values(rows, f, lose)},
                             **tag))

    def per(f: int, key: str) -> dict[str, float]:
        return {t: next(r[key] for r in rows if r["follower"] == f and r["topology"] == t) for t in TOPOLOGIES}

    s4, o4 = per(4, "settling_time_s"), per(4, "overshoot_m")
    ok4 = s4["PLF"] < s4["BDL"] and o4["PLF"] < o4["BDL"]
    out.append(no_value("follower 4: PLF faster and with less overshoot than BDL (Fig. 7) [settling s, overshoot m]",
                        SOURCE_F4_FIG, [s4["PLF"], s4["BDL"], o4["PLF"], o4["BDL"]],
                        ours=f"PLF settles sooner (position error within {100 * SETTLING_FRACTION:g} % of its peak) "
                             f"and overshoots less: {'met' if ok4 else 'not met'}",
                        note="measured: [PLF settling, BDL settling, PLF overshoot, BDL overshoot]", **tag))
    osc3 = per(3, "input_sign_changes")
    out.append(no_value("follower 3: BDL's input oscillates most (Fig. 6) [input sign changes]", SOURCE_F3,
                        [osc3[t] for t in TOPOLOGIES],
                        ours=f"BDL has the most input sign changes: "
                             f"{'met' if all(osc3['BDL'] > osc3[t] for t in ('PLF', 'TPLF')) else 'not met'}",
                        note="measured: sign changes of the input, all axes, PLF / BDL / TPLF", **tag))
    osc2 = per(2, "input_sign_changes_x")
    out.append(no_value("follower 2: PLF's x input oscillates more than TPLF's (Fig. 5) [sign changes]",
                        SOURCE_F2_INPUT, [osc2["PLF"], osc2["TPLF"]],
                        ours=f"more x-input sign changes in PLF: {'met' if osc2['PLF'] > osc2['TPLF'] else 'not met'}",
                        note="measured: PLF / TPLF", **tag))
    settle = {t: float(np.mean([per(f, "settling_time_s")[t] for f in (1, 2, 3, 4)])) for t in TOPOLOGIES}
    out.append(no_value("TPLF has the best transient response in general [mean settling time s]", SOURCE_TRANSIENT,
                        [settle[t] for t in TOPOLOGIES],
                        ours=f"TPLF's mean settling time over the followers the lowest: "
                             f"{'met' if min(settle, key=settle.get) == 'TPLF' else 'not met'}",
                        note="measured: PLF / BDL / TPLF", **tag))
    if variant == "ours":
        out.append(no_value("the 1-hop algorithm more trustworthy than the convex step of pereira2022",
                            SOURCE_TRUSTWORTHY, None, note="the paper runs no comparison of the two algorithms; "
                            "neither do we (the pereira2022-platoon page runs the convex step on its own scenario)",
                            **tag))
    return out


def _variation_effect(foe_rows: list[dict] | None, prefix: str, what: str) -> str:
    row = next((r for r in foe_rows or [] if r["setting"].startswith(prefix)), None)
    if row is None:
        return "not measured in this result"
    return (f"{what} (FOE analysis): FOE / Table II {row['foe_ratio_min']:.3g}-{row['foe_ratio_max']:.3g}, "
            f"largest relative FOE change |FOE / ours - 1| = {row['max_change_vs_default']:.4g}, "
            f"{row['cells_within_10pct']}/12 FOE "
            f"cells within 10 %, worst RMSE error {100 * row['rmse_worst_rel_err']:.1f} %, violations "
            f"{row['violations']}")


def _published_effect(published: dict | None) -> str:
    if published is None:
        return "not measured in this result"
    rows = published["rows"]
    within = {m: sum(abs(r[m] / r[f"paper_{m}"] - 1) <= 0.1 for r in rows) for m in METRICS}
    viol = sum(d["violations"] for d in published["per_topology"].values())
    fb = sum(d["fallbacks"] for d in published["per_topology"].values())
    return (f"as-published run (all three together): cells within 10 % of Table II: RMSE {within['rmse']}/12, "
            f"RMSEE {within['rmsee']}/12, FOE {within['foe']}/12; violations {viol}, QP fallbacks {fb}")


def _cap_effect(per_topology: dict | None) -> str:
    if not per_topology or any("max_jacobi_iterations" not in d for d in per_topology.values()):
        return "not measured in this result"
    most = {t: d["max_jacobi_iterations"] for t, d in per_topology.items()}
    cap = next(iter(per_topology.values()))["jacobi_iteration_cap"]
    hit = [t for t, n in most.items() if n >= cap]
    return (f"most Jacobi iterations of one decision in our run: {most}; " +
            (f"the cap was reached ({', '.join(hit)}): not measured without it" if hit else
             "the cap was never reached, so it changes no claim"))


def departures(foe_rows: list[dict] | None = None, published: dict | None = None,
               per_topology: dict | None = None) -> list[dict[str, Any]]:
    """Where our run differs from Table I / §IV, with the effect measured in the FOE analysis and
    the as-published run (``published``: its rows and per-topology counts; ``per_topology``: ours)."""
    both = _published_effect(published)
    margin = next((r for r in foe_rows or [] if r["setting"].startswith("velocity margin")), None)
    effect = ("not measured in this result" if margin is None else
              f"without it (FOE analysis): FOE / Table II {margin['foe_ratio_min']:.2f}-{margin['foe_ratio_max']:.2f}, "
              f"largest FOE change {100 * margin['max_change_vs_default']:.2g} %, "
              f"{margin['cells_within_10pct']}/12 FOE cells within 10 %, velocity-bound violations "
              f"{margin['violations']} (ours: 0)")
    min_err = next((r for r in foe_rows or [] if r["setting"].startswith("minimum-error")), None)
    min_effect = ("not measured in this result" if min_err is None else
                  "with it (FOE analysis): FOE / Table II "
                  f"{min_err['foe_ratio_min']:.2f}-{min_err['foe_ratio_max']:.2f}, "
                  f"largest FOE change {100 * min_err['max_change_vs_default']:.2g} %, worst RMSE error "
                  f"{100 * min_err['rmse_worst_rel_err']:.1f} %, violations {min_err['violations']}")
    return [
        departure("minimum tracking-error constraint (41)-(42)", "imposed (Fig. 8: 'also satisfied')", "off "
                  "(the preset's min_error_constraint=False)",
                  "the platoon scenario's default (the preset does not turn it on); no "
                  "reason is recorded: its measured effect is beside", min_effect + "; " + both,
                  fields=["min_error_constraint"]),
        departure("velocity box (40) margin", "(g+d) v_max", "(g+d) v_max - 1e-4 m/s",
                  "the applied velocity also depends on the neighbours' final Jacobi iterates; without the margin "
                  "the bound was exceeded by 1e-8 m/s on 2-3 steps", effect + "; " + both, fields=["velocity_margin"]),
        departure("warm start of Algorithm 1 (line 6)", "Û_f(0) <- U*_f(k-1): the previous optimal sequence",
                  "the previous sequence shifted by one step, its last input repeated (warm_start='shift')",
                  "the shifted sequence is the usual MPC warm start (the previous one is one step stale); the paper's "
                  "reading changes where Algorithm 1's Jacobi iteration stops (sigma = 0.5), hence the FOE",
                  _variation_effect(foe_rows, "warm start", "with the paper's") + "; " + both,
                  fields=["warm_start"]),
        departure("where the velocity box (40) is imposed", "(g^f + d^f) v_min <= v_f <= (g^f + d^f) v_max on "
                  "v_f, the follower's relative velocity", "on the velocity rows of the QP's tracking-error state "
                  "E_f", "the QP is written in the error state of eq. 15", "not measured separately",
                  fields=["velocity_constraint"]),
        departure("Jacobi iteration cap of Algorithm 1", NOT_STATED + " (iterate until the stopping rule)",
                  "200 iterations per decision (DMPCConfig.max_iterations)", "a bound on each decision's work",
                  _cap_effect(per_topology), fields=["max_iterations"]),
        departure("solver fallback", NOT_STATED, "a failed QP keeps the agent's previous iterate (counted)",
                  "the paper assumes every QP solved", "no fallback in our run (per-topology counts beside)",
                  fields=["fallback"]),
        departure("QP solver", "CasADi solver(.) in MATLAB R2019A", "DAQP (exact active set)",
                  "exact optimum; OSQP at its default tolerance differed by up to 1.5 in U",
                  "not measured separately"),
        departure("random initial sequence of Algorithm 1", NOT_STATED, "seeded (seed 0)",
                  "the paper gives none", "FOE analysis: 'seed 1' and 'initial sequence zeros' rows"),
        departure("tracking error of the metrics", "E_f - E_d (FOE formula) with E_d of eq. 15",
                  "E_f - (g_f + d_f) E_d (eq. 15)", "the paper's two readings differ; rows also report the "
                  "unscaled RMSE (rmse_unscaled_ed)", "RMSE of the other reading: rmse_unscaled_ed per row",
                  fields=["tracking_error"]),
    ]


def format_table(result: dict[str, Any]) -> str:
    """The reproduced table beside Table II (plain text), the FOE analysis and the claims."""
    lines = [f"{'f':>2} {'net':>5} | {'RMSE':>8} {'paper':>8} {'err':>7} | {'RMSEE':>6} "
             f"{'paper':>6} {'err':>7} | {'FOE':>9} {'paper':>9} {'x':>5} {'behind':>6}"]
    lines.append("-" * len(lines[0]))
    for r in sorted(result["rows"], key=lambda r: (r["follower"], TOPOLOGIES.index(r["topology"]))):
        lines.append(
            f"{r['follower']:>2} {r['topology']:>5} | {r['rmse']:8.3f} {r['paper_rmse']:8.3f} "
            f"{100 * r['rmse_rel_err']:+6.1f}% | {r['rmsee']:6.3f} {r['paper_rmsee']:6.3f} "
            f"{100 * r['rmsee_rel_err']:+6.1f}% | {r['foe']:9.2e} {r['paper_foe']:9.2e} "
            f"{r['foe_ratio']:5.2f} {r['steps_behind']:6.1f}")
    for topo, d in result["per_topology"].items():
        lines.append(f"{topo}: min separation {d['min_separation_m']:.2f} m, collision flags "
                     f"{d['collision_steps']}, violations {d['violations']}, fallbacks "
                     f"{d['fallbacks']}, mean Jacobi iterations {d['mean_jacobi_iterations']:.2f}")
    if result.get("foe_analysis"):
        lines.append("FOE analysis (one setting varied at a time): FOE / Table II min-max, largest change vs default, "
                     "cells within 10 %")
        for a in result["foe_analysis"]:
            lines.append(f"  {a['setting']:<60} {a['foe_ratio_min']:6.2f}-{a['foe_ratio_max']:<6.2f} "
                         f"{100 * a['max_change_vs_default']:8.1f} % {a['cells_within_10pct']:>3}/12")
    lines.append(f"PLF vs TPLF, followers 1-2: largest state difference "
                 f"{result['plf_tplf_followers_1_2_max_state_difference']:.3g}")
    lines.append(format_claims(result["claims"]) + f" (wall time {result['wall_time_s']:.1f} s)")
    return "\n".join(lines)


def add_arguments(parser) -> None:
    """``satenv.bench.reproduce pereira2023`` options: ``--no-analysis`` (Table II only, about 1 s)."""
    parser.add_argument("--no-analysis", dest="analysis", action="store_false",
                        help="skip the FOE analysis (Table II and the claims only)")


def save_figures(runs: dict, out: Path) -> list[Path]:
    """Analogues of pereira2023 Fig. 4-7 (one PNG per follower: position error, velocity error
    and input per axis, the three topologies overlaid) and a 3-D trajectory plot per topology."""
    from satenv.render import new_figure, plot_trajectory

    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    n = next(iter(runs.values()))[1].scenario.n_followers
    axes_names = ("x", "y", "z")
    for f in range(n):
        fig = new_figure(figsize=(11, 8))
        axs = fig.subplots(3, 3, sharex=True)
        for topo, (traj, _env) in runs.items():
            e = traj.info["tracking_error"][:, f]
            u = traj.info["accel"][1:, f]
            for c in range(3):
                axs[0, c].plot(traj.t, e[:, c], label=topo)
                axs[1, c].plot(traj.t, e[:, 3 + c], label=topo)
                axs[2, c].step(traj.t[:-1], u[:, c], where="post", label=topo)
        for c in range(3):
            axs[0, c].set_title(f"{axes_names[c]}")
            axs[2, c].set_xlabel("t [s]")
        axs[0, 0].set_ylabel("position error [m]")
        axs[1, 0].set_ylabel("velocity error [m/s]")
        axs[2, 0].set_ylabel("input u [m/s$^2$]")
        axs[0, 0].legend()
        for a in axs.ravel():
            a.grid(alpha=0.3)
        fig.suptitle(f"pereira2023 Fig. {4 + f} analogue: follower {f + 1} "
                     "(tracking error E_f - (g+d)E_d, input)")
        fig.tight_layout()
        path = out / f"pereira2023_follower{f + 1}.png"
        fig.savefig(path, dpi=90)
        paths.append(path)
    for topo, (traj, _env) in runs.items():
        paths.append(plot_trajectory(traj, out / f"pereira2023_{topo}_trajectory.png",
                                     title=f"pereira2023 {topo}: DMPC trajectories (LVLH)"))
    return paths
