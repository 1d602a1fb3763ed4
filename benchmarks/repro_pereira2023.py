"""Reproduce pereira2023 Table II: the 1-hop DMPC on the Table I platoon, PLF / BDL / TPLF.

Runs ``satenv.platoon_v0(preset="pereira2023", topology=T, terminate_on_collision=False)`` with
``baselines.dmpc.DMPC`` (defaults: DAQP, sigma = 0.5, seeded random initial sequence, shifted
warm start) through ``satenv.rollout`` and measures RMSE / RMSEE / FOE with ``satenv.metrics``
(the tracking error is ``E_f - (g_f + d_f) E_d``, eq. 15). The formation of Table I brings bodies
closer than ``2 r_f`` (see ``satenv.envs.platoon_v0``), hence ``terminate_on_collision=False``;
the collision flags are reported, not hidden.

Claims (``result["claims"]``, :mod:`benchmarks.claims`): every RMSE within 10 % of Table II,
every RMSEE within 25 % (issue 3), every FOE within 1.5x (issue 16; not met, see
:data:`FOE_NOTE`), per topology FOE <= 1e-4 (converged) and no violation of the velocity bound (40)
(§IV: "respecting the constraints"). :data:`PLF_TPLF_NOTE` explains why followers 1-2 are
identical in PLF and TPLF.
Also reported per row: ``rmse_unscaled_ed``, the RMSE of ``E_f - E_d`` (E_d not multiplied by
``g_f + d_f``), the other reading of the paper's metric.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._io import progress
from benchmarks.claims import all_met, claim, format_claims, within

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
TARGETS = {"rmse_rel_tol": 0.10, "rmsee_rel_tol": 0.25, "foe_max": 1e-4, "foe_factor": 1.5}
RUN_TIME = "about 1 s"

FOE_NOTE = (
    "FOE is the tail of a mode that decays by the measured rate (0.905 a step = exp(-T_s * 1.005/s), "
    "the slow closed-loop pole of Q = 13 I, W = 0.1 I) over the whole episode, so it is the "
    "slow-mode amplitude times ~e^-18: 'steps_behind' = ln(FOE / paper) / ln(1 / rate) is the "
    "delay of our tail behind the paper's. It does not move with the Jacobi stopping rule "
    "(per-agent or all), sigma (0.5 or 1e-6), the warm start (shift / previous, PLF and TPLF), "
    "the random initial sequence (seeds, zeros) or the minimum-error constraint (41)-(42); it "
    "moves with the horizon (N = 40: 1.3-2.4x) and with the constraints (unconstrained: 8-53x), "
    "i.e. with how the saturated transient ends, which the RMSE (within 6 %) does not resolve.")
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
    from baselines.dmpc import DMPC
    from satenv.rollout import rollout

    env = satenv.make("platoon_v0", preset=PAPER, topology=topology, terminate_on_collision=False)
    policy = DMPC(env, seed=seed, **dmpc_options)
    traj = rollout(env, policy, seed=seed)
    return traj, env, policy


def reproduce(plots: str | Path | None = None, seed: int = 0) -> dict[str, Any]:
    """Run the three topologies, compare with Table II; optionally save the figures to ``plots``."""
    from satenv import metrics

    start = time.perf_counter()
    rows, runs, per_topology = [], {}, {}
    for topo in TOPOLOGIES:
        progress(f"pereira2023: {topo} ...")
        traj, env, policy = run_topology(topo, seed=seed)
        runs[topo] = (traj, env)
        rmse, rmsee, foe = metrics.rmse(traj), metrics.rmsee(traj), metrics.foe(traj)
        e_d = np.asarray(env.scenario.desired_error)
        unscaled = traj.info["neighbourhood_error"][:-1] - e_d
        rmse_unscaled = np.sqrt(np.mean(np.sum(unscaled**2, axis=-1), axis=0))
        err = np.linalg.norm(traj.info["tracking_error"], axis=-1)
        rate = err[-1] / err[-2]
        for f in range(env.scenario.n_followers):
            p_rmse, p_rmsee, p_foe = TABLE_II[topo][f]
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
            })
        qp_ms = np.asarray(policy.info["qp_ms"])
        per_topology[topo] = {
            "collision_steps": metrics.collisions(traj),
            "min_separation_m": metrics.min_separation(traj),
            "violations": metrics.violations(traj),
            "fallbacks": int(policy.info["fallbacks"]),
            "not_converged": int(policy.info["not_converged"]),
            "mean_jacobi_iterations": float(np.mean(policy.info["iterations"])),
            "median_qp_ms": float(np.median(qp_ms)) if qp_ms.size else 0.0,
            "median_decision_ms": float(np.median(policy.info["solve_ms"])),
            "steps": traj.steps,
        }
    wall = time.perf_counter() - start
    checks = check_claims(rows, per_topology)
    result = {
        "paper": PAPER, "rows": rows, "claims": checks, "targets": TARGETS,
        "pass": all_met(checks), "per_topology": per_topology, "wall_time_s": wall, "seed": seed,
        "notes": {"foe": FOE_NOTE, "plf_tplf_followers_1_2": PLF_TPLF_NOTE},
        "settings": {"env": "platoon_v0(preset='pereira2023', terminate_on_collision=False)",
                     "policy": "baselines.dmpc.DMPC (one_hop, daqp, sigma=0.5, per-agent stopping, "
                               "warm_start='shift')",
                     "metric": "tracking error E_f - (g_f + d_f) E_d (eq. 15)"},
    }
    if plots is not None:
        result["figures"] = [str(p) for p in save_figures(runs, Path(plots))]
    return result


def check_claims(rows: list[dict], per_topology: dict[str, dict]) -> list[dict[str, Any]]:
    """Table II per cell (RMSE, RMSEE within the targets, FOE within ``foe_factor``), and per
    topology: converged (FOE <= ``foe_max``) and the constraints respected (§IV)."""
    t = TARGETS
    out = []
    for r in rows:
        cell = {"topology": r["topology"], "follower": r["follower"]}
        label = f"{r['topology']} follower {r['follower']}"
        out.append(claim(f"RMSE {label}", r["paper_rmse"], r["rmse"],
                         abs(r["rmse_rel_err"]) <= t["rmse_rel_tol"],
                         target=f"+-{100 * t['rmse_rel_tol']:.0f}%", **cell))
        out.append(claim(f"RMSEE {label}", r["paper_rmsee"], r["rmsee"],
                         abs(r["rmsee_rel_err"]) <= t["rmsee_rel_tol"],
                         target=f"+-{100 * t['rmsee_rel_tol']:.0f}%", **cell))
        out.append(claim(f"FOE {label}", r["paper_foe"], r["foe"],
                         within(r["foe"], r["paper_foe"], t["foe_factor"]),
                         target=f"within {t['foe_factor']}x", note="see notes.foe", **cell))
    for topo, d in per_topology.items():
        worst = max(r["foe"] for r in rows if r["topology"] == topo)
        out.append(claim(f"{topo} converges (max FOE)", "error converges", worst,
                         worst <= t["foe_max"], target=f"<= {t['foe_max']:.0e}", topology=topo))
        out.append(claim(f"{topo} constraints (39)-(40) respected (violations)",
                         "respected", d["violations"], d["violations"] == 0 and d["fallbacks"] == 0,
                         target="0 violations, 0 fallbacks", topology=topo))
    return out


def format_table(result: dict[str, Any]) -> str:
    """The reproduced table beside Table II (plain text)."""
    lines = [f"{'f':>2} {'net':>5} | {'RMSE':>8} {'paper':>8} {'err':>7} | {'RMSEE':>6} "
             f"{'paper':>6} {'err':>7} | {'FOE':>9} {'paper':>9} {'x':>5} {'behind':>6}"]
    lines.append("-" * len(lines[0]))
    for r in sorted(result["rows"], key=lambda r: (r["follower"], TOPOLOGIES.index(r["topology"]))):
        lines.append(
            f"{r['follower']:>2} {r['topology']:>5} | {r['rmse']:8.3f} {r['paper_rmse']:8.3f} "
            f"{100 * r['rmse_rel_err']:+6.1f}% | {r['rmsee']:6.3f} {r['paper_rmsee']:6.3f} "
            f"{100 * r['rmsee_rel_err']:+6.1f}% | {r['foe']:9.2e} {r['paper_foe']:9.2e} "
            f"{r['foe_ratio']:5.2f} {r['steps_behind']:6.1f}")
    t = result["targets"]
    worst_rmse = max(abs(r["rmse_rel_err"]) for r in result["rows"])
    worst_rmsee = max(abs(r["rmsee_rel_err"]) for r in result["rows"])
    worst_foe = max(r["foe"] for r in result["rows"])
    lines.append(
        f"worst: RMSE {100 * worst_rmse:.1f}% (target {100 * t['rmse_rel_tol']:.0f}%), RMSEE "
        f"{100 * worst_rmsee:.1f}% (target {100 * t['rmsee_rel_tol']:.0f}%), FOE {worst_foe:.1e} "
        f"(target {t['foe_max']:.0e}); wall time {result['wall_time_s']:.2f} s")
    for topo, d in result["per_topology"].items():
        lines.append(f"{topo}: min separation {d['min_separation_m']:.2f} m, collision flags "
                     f"{d['collision_steps']}, violations {d['violations']}, fallbacks "
                     f"{d['fallbacks']}, mean Jacobi iterations {d['mean_jacobi_iterations']:.2f}")
    lines.append(f"FOE: {result['notes']['foe']}")
    lines.append(format_claims(result["claims"]))
    return "\n".join(lines)


def save_figures(runs: dict, out: Path) -> list[Path]:
    """Analogues of pereira2023 Fig. 4-7 (one PNG per follower: position error, velocity error
    and input per axis, the three topologies overlaid) and a 3-D trajectory plot per topology."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from satenv.render import plot_trajectory

    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    n = next(iter(runs.values()))[1].scenario.n_followers
    axes_names = ("x", "y", "z")
    for f in range(n):
        fig, axs = plt.subplots(3, 3, figsize=(11, 8), sharex=True)
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
        plt.close(fig)
        paths.append(path)
    for topo, (traj, _env) in runs.items():
        paths.append(plot_trajectory(traj, out / f"pereira2023_{topo}_trajectory.png",
                                     title=f"pereira2023 {topo}: DMPC trajectories (LVLH)"))
    return paths
