"""Reproduce li2022's claims: tube-based robust DMPC vs APF on the 10-satellite cluster.

``python -m benchmarks.reproduce li2022 --out FILE.json [--plots DIR] [--case 1|2]
[--variant ours|published|both]`` or ``python -m benchmarks.repro_li2022`` with the same options.
Expected run time on 2 cores (measured 2026-11-30, two solver threads): 1-1.5 min for our RDMPC
episode (2000 s, 400 decisions of 10 NLPs, ~6 ipopt iterations each with ``warm_duals``), 4 min
for the as-published one (1605 of its 4000 NLPs need the relaxed re-solve; the failing exact
solves stop at :data:`EXACT_MAX_ITER`), 12 s per APF episode, about 1 min for the
``lyapunov_tolerance`` sensitivity and the tube experiment: about 6 min for one case with both
variants, 12 min for both cases (was 18 min per case). The RDMPC solves its satellites' NLPs on
two threads where two cores exist (``workers``; the same decisions). Progress lines go to stderr.

Runs ``satenv.cluster_v0(preset="li2022-case<k>", terminate_on_collision=False)`` (so a safety
violation is counted, not hidden by an early end) with ``baselines.TubeRDMPC`` and
``baselines.APF`` through ``satenv.rollout`` for ``max_steps`` decisions (400 = 2000 s), and a
tube-only experiment for Fig. 13 (coasting nominal + κ on the truth for one period of the
disturbance, k1 in {1, 2, 4}, k2 = 4). Two RDMPC variants (:data:`VARIANTS`):

* ``ours`` (default ``TubeRDMPCConfig``): li2022 §4 plus the documented choices of
  ``baselines.tube_rdmpc`` (speed bound ``v_max = 2.5 m/s`` for the unspecified state set Ξ_i,
  stopping-distance terminal rows, 5 m Jacobi safety margin), Hungarian allocation at reset;
* ``published`` (``TubeRDMPCConfig.published()`` in ``cluster_v0(..., reallocate_every=1)``): no
  speed bound, only the terminal set (38), and the Hungarian allocation re-run at every decision
  as li2022's Step 4 says. The 5 m margin, the Lyapunov tolerance and the relaxed NLP stay.

One row per controller, variant and case: ``convergence_time_s`` (all satellites within 1 m of
their targets and staying there; ``None`` if not reached), ``final_error_m`` (max over
satellites), ``final_nominal_error_m`` (the nominal x~'s distance to its target at the end),
``satellites_within_1m_at_end``, ``reallocations`` (target changes), ``min_pair_distance_m``,
``min_obstacle_distance_m``, ``min_target_distance_m`` (centre distances, minima over the
physics steps), ``max_thrust_N``, ``delta_v_total_mps``, ``collisions`` ((decision, satellite)
safety flags), ``solve_ms_median`` (per satellite solve; APF: compute time per decision / M),
``max_tube_error_m`` (``||q - q~||``, RDMPC), plus fallback / relaxed-solve counts.

Accuracy. li2022's "about 0.071 m" is the tube bound (15) ``sqrt(eta / k1) w_bar`` with
``eta = 1``, ``k1 = 2`` and the disturbance bound ``w_bar = 0.1`` (the force amplitude, plugged
in as is): the nominal converges to the target and the true state stays within the tube. The
claim is checked in these terms: the true final error (nominal residual + tube error) must be
within ``sqrt(eta / k1) * 0.1`` m. Our nominal does not converge exactly: the
``lyapunov_tolerance`` rows let it rest at ``sqrt(tol / sigma)`` (2.2 cm at 1e-4 m^2), so the
``sensitivity`` table measures the accuracy against ``lyapunov_tolerance`` (case 1, starting at
rest on the targets, ``SENSITIVITY_STEPS`` decisions).

Other claims (li2022 §4.3): RDMPC converges in about 1000 s (target: <= 1500 s), no collisions,
thrust <= 1 N; APF collision-free and within 1 N too, but slower (later convergence, or none)
and less accurate (larger final error). Each claim record has ``paper``, ``measured``, ``met``
(:func:`benchmarks.reproduce.claim`); the command exits 0 only when all are met, the
as-published rows included.

Figures (``--plots DIR``): analogues of Fig. 5 (3-D trajectories, actual and nominal), Fig. 13
(tube error vs k1 with the bound (15); and ``||q - q~||`` along each RDMPC run), Fig. 14 (κ of
Sat 1), Fig. 15/16 (distance to target), Fig. 17/18 (to the obstacle), Fig. 19/20 (to the
nearest satellite), Fig. 21/22 (to the target spacecraft), Fig. 23/24 (thrust of Sat 1): one
column per RDMPC variant, APF right.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._io import progress, write_json
from benchmarks.claims import all_met, claim, format_claims

PAPER = "li2022"
CASES = (1, 2)
CONTROLLERS = ("tube_rdmpc", "apf")
VARIANTS = ("ours", "published")
"""RDMPC variants: our default configuration and li2022 as published (module docstring)."""
PAPER_W_BAR = 0.1
"""li2022's disturbance bound w_bar as it enters its tube bound (15) (0.1, the force amplitude)."""
CLAIMS = {"convergence_time_s": 1000.0, "accuracy_m": 0.071, "thrust_N": 1.0}
TARGETS = {"rdmpc_convergence_time_max_s": 1500.0, "thrust_max_N": 1.0}
SENSITIVITY_TOLERANCES = (1e-6, 1e-5, 1e-4, 1e-3)
SENSITIVITY_STEPS = 30
"""Decisions (150 s) of the accuracy-vs-``lyapunov_tolerance`` runs (started on the targets)."""


RUN_TIME = "about 6 min per case with both variants (1-1.5 min ours, 4 min as published); --variant ours: about 2.5 min"


def _progress(msg: str) -> None:
    progress(f"li2022: {msg}")


def label(controller: str, variant: str = "ours") -> str:
    """Row / figure label: ``"tube_rdmpc"``, ``"tube_rdmpc[published]"``, ``"apf"``."""
    return controller if variant == "ours" else f"{controller}[{variant}]"


def variant_setup(variant: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(env overrides, TubeRDMPC options)`` of an RDMPC variant (:data:`VARIANTS`)."""
    from baselines.tube_rdmpc import TubeRDMPCConfig

    if variant == "ours":
        return {}, {}
    if variant == "published":
        return {"reallocate_every": 1}, {"config": TubeRDMPCConfig.published()}
    raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")


def _preset(case: int) -> str:
    if case not in CASES:
        raise ValueError(f"case must be 1 or 2 (li2022 Table 2 / Table 3), got {case!r}")
    return f"li2022-case{case}"


def make_env(case: int, **overrides):
    import satenv

    return satenv.make("cluster_v0", preset=_preset(case), terminate_on_collision=False, **overrides)


EXACT_MAX_ITER = 60
"""ipopt iteration limit of the RDMPC's exact NLP here (``TubeRDMPCConfig.exact_max_iter``; the
relaxed NLP keeps 150): no exact solve that succeeded took over 50 in these episodes, so the
rows are those of the default 150, while the failing solves (80 % of the as-published run time at
150) stop sooner."""


def make_policy(controller: str, env, **options):
    """The controller; the RDMPC solves its satellites' NLPs on up to two threads (``workers``:
    the same decisions as one thread, faster on this project's 2-core machines) and caps the
    exact NLP at :data:`EXACT_MAX_ITER` iterations."""
    if controller == "tube_rdmpc":
        from baselines.tube_rdmpc import TubeRDMPC

        return TubeRDMPC(env, **{"workers": min(2, os.cpu_count() or 1), "exact_max_iter": EXACT_MAX_ITER,
                                 **options})
    if controller == "apf":
        from baselines.apf import APF

        return APF(env, **options)
    raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")


def run_controller(case: int, controller: str, seed: int = 0, max_steps: int | None = None,
                   env_overrides: dict | None = None, policy_options: dict | None = None,
                   variant: str = "ours", options: dict | None = None):
    """One episode; returns ``(trajectory, env, policy, wall_time_s)``."""
    from satenv.rollout import rollout

    env_v, pol_v = variant_setup(variant) if controller == "tube_rdmpc" else ({}, {})
    env = make_env(case, **{**env_v, **(env_overrides or {})})
    policy = make_policy(controller, env, **{**pol_v, **(policy_options or {})})
    start = time.perf_counter()
    traj = rollout(env, policy, seed=seed, max_steps=max_steps, options=options)
    return traj, env, policy, time.perf_counter() - start


def _none_if_nan(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def summarise(traj, env, policy, controller: str, case: int, wall: float,
              variant: str = "ours") -> dict[str, Any]:
    """The reproduction row of one episode (see the module docstring)."""
    from satenv import metrics

    sc = env.scenario
    m = sc.n_agents
    ttc = metrics.time_to_converge(traj, tol=1.0)
    final = metrics.final_position_error(traj)
    info = policy.info
    if controller == "tube_rdmpc":
        solve = np.asarray(info["solve_ms"], dtype=float)
    else:
        solve = np.asarray(traj.compute_time, dtype=float) * 1e3 / m
    idx = np.asarray(traj.info["target_index"])
    row = {
        "controller": controller,
        "variant": variant,
        "case": case,
        "convergence_time_s": _none_if_nan(float(np.max(ttc))) if np.all(np.isfinite(ttc)) else None,
        "convergence_time_per_sat_s": [_none_if_nan(v) for v in ttc.tolist()],
        "final_error_m": float(np.max(final)),
        "final_error_per_sat_m": final.tolist(),
        "satellites_within_1m_at_end": int(np.sum(final <= 1.0)),
        "reallocations": int(np.sum(idx[1:] != idx[:-1])),
        "min_pair_distance_m": float(np.min(traj.info["pair_distance"])),
        "min_obstacle_distance_m": float(np.min(traj.info["obstacle_distance"])),
        "min_target_distance_m": float(np.min(traj.info["target_distance"])),
        "max_thrust_N": float(np.max(traj.info["thrust_peak"]) * sc.mass),
        "delta_v_total_mps": float(np.sum(metrics.delta_v_total(traj))),
        "collisions": metrics.collisions(traj),
        "solve_ms_median": float(np.median(solve)) if solve.size else 0.0,
        "solve_ms_p90": float(np.percentile(solve, 90)) if solve.size else 0.0,
        "fallbacks": int(info.get("fallbacks", 0)),
        "sim_time_s": float(traj.t[-1]),
        "wall_time_s": float(wall),
        "options": {k: v for k, v in dataclasses.asdict(policy.cfg).items()},
    }
    if controller == "tube_rdmpc":
        nominal_err = np.linalg.norm(policy.tube.nominal[:, :3] - env.targets(), axis=-1)
        row.update({"max_tube_error_m": float(info["tube_error_max_m"]),
                    "final_nominal_error_m": float(np.max(nominal_err)),
                    "lyapunov_floor_m": math.sqrt(policy.cfg.lyapunov_tolerance / policy.cfg.sigma),
                    "tube_bound_m": float(info["tube_bound_m"]),
                    "relaxed_solves": int(info["relaxed"]), "nlp_solves": int(info["solves"])})
    else:
        row.update({"max_tube_error_m": None, "final_nominal_error_m": None})
    return row


def tube_experiment(k1_values=(1.0, 2.0, 4.0), k2: float = 4.0, steps: int = 64) -> dict[str, Any]:
    """Fig. 13: coasting nominal + κ on the J2 + drag + w truth for one disturbance period.

    Returns per k1 the largest ``||q - q~||`` over all satellites, Sat 1's series, and the bounds:
    (15) with eta = 1 and with the smallest eta Theorem 1 allows (1 / (4 k2)), and the exact
    peak gain ``w_bar / (1 + k1)`` of the κ of eq. (13).
    """
    from baselines.tube_rdmpc import TubeController

    out: dict[str, Any] = {"k2": k2, "steps": steps, "runs": []}
    for k1 in k1_values:
        env = make_env(1, max_steps=steps)
        env.reset(seed=0)
        sc = env.scenario
        tube = TubeController(sc.orbit.n, sc.physics_dt, k1=k1, k2=k2)
        tube.sync(env.state()[:6 * sc.n_agents].reshape(sc.n_agents, 6), 0.0)
        env.set_inner_loop(tube)
        for _ in range(steps):
            env.step({a: np.zeros(3) for a in env.agents})
        eps = np.array(tube.eps)
        w = sc.disturbance_bound
        out["runs"].append({
            "k1": k1, "max_error_m": float(eps.max()),
            "bound_15_eta1_m": math.sqrt(1.0 / k1) * w,
            "bound_15_eta_min_m": math.sqrt(1.0 / (4.0 * k2) / k1) * w,
            "exact_peak_m": w / (1.0 + k1),
            "sat1_error_m": eps[:, 0].tolist(), "dt": sc.physics_dt,
            "sat1_kappa_N": (np.array(tube.kappa)[:, 0] * sc.mass).tolist(),
        })
        out["disturbance_bound_mps2"] = w
    return out


def accuracy_bound(cfg) -> float:
    """li2022's accuracy in its own terms: the tube bound (15) ``sqrt(eta / k1) * w_bar``, w_bar = 0.1."""
    return math.sqrt(cfg.eta / cfg.k1) * PAPER_W_BAR


def check_claims(rows: list[dict]) -> list[dict[str, Any]]:
    """Each paper claim per case and RDMPC variant (:func:`benchmarks.reproduce.claim` records)."""
    from baselines.tube_rdmpc import TubeRDMPCConfig

    bound = accuracy_bound(TubeRDMPCConfig())
    checks: list[dict[str, Any]] = []
    for case in sorted({r["case"] for r in rows}):
        rdmpc = [r for r in rows if r["case"] == case and r["controller"] == "tube_rdmpc"]
        apf = next((r for r in rows if r["case"] == case and r["controller"] == "apf"), None)
        thrust_ok = TARGETS["thrust_max_N"] * (1 + 1e-9)
        for rd in rdmpc:
            v = rd["variant"]
            tag = {"case": case, "variant": v}
            pre = f"case {case} RDMPC {v}:"
            ct = rd["convergence_time_s"]
            checks.append(claim(
                f"{pre} converges in about 1000 s (all within 1 m)", CLAIMS["convergence_time_s"], ct,
                ct is not None and ct <= TARGETS["rdmpc_convergence_time_max_s"],
                target=f"<= {TARGETS['rdmpc_convergence_time_max_s']:.0f} s",
                satellites_within_1m_at_end=rd["satellites_within_1m_at_end"],
                relaxed_solves=rd["relaxed_solves"], fallbacks=rd["fallbacks"], **tag))
            checks.append(claim(
                f"{pre} accuracy about 0.071 m (tube bound sqrt(eta/k1) w_bar, w_bar = 0.1)",
                CLAIMS["accuracy_m"], rd["final_error_m"], rd["final_error_m"] <= bound,
                target=f"final error <= {bound:.4f} m",
                breakdown={"nominal_residual_m": rd["final_nominal_error_m"],
                           "max_tube_error_m": rd["max_tube_error_m"],
                           "lyapunov_floor_m": rd["lyapunov_floor_m"]}, **tag))
            checks.append(claim(f"{pre} no collisions", 0, rd["collisions"], rd["collisions"] == 0,
                                target="0", **tag))
            checks.append(claim(f"{pre} thrust within 1 N", TARGETS["thrust_max_N"], rd["max_thrust_N"],
                                rd["max_thrust_N"] <= thrust_ok, target="<= 1 N", **tag))
        if apf is None:
            continue
        pre = f"case {case} APF:"
        checks.append(claim(f"{pre} no collisions", 0, apf["collisions"], apf["collisions"] == 0,
                            target="0", case=case, variant="ours"))
        checks.append(claim(f"{pre} thrust within 1 N", TARGETS["thrust_max_N"], apf["max_thrust_N"],
                            apf["max_thrust_N"] <= thrust_ok, target="<= 1 N", case=case, variant="ours"))
        for rd in rdmpc:
            ct_r, ct_a = rd["convergence_time_s"], apf["convergence_time_s"]
            checks.append(claim(
                f"{pre} slower than RDMPC {rd['variant']} [s]", "APF converges later", [ct_r, ct_a],
                ct_r is not None and (ct_a is None or ct_a > ct_r), target="apf > rdmpc (measured: rdmpc, apf)",
                case=case, variant=rd["variant"]))
            checks.append(claim(
                f"{pre} less accurate than RDMPC {rd['variant']} [m]", "APF final error larger",
                [rd["final_error_m"], apf["final_error_m"]],
                apf["final_error_m"] > rd["final_error_m"], target="apf > rdmpc (measured: rdmpc, apf)",
                case=case, variant=rd["variant"]))
    return checks


def accuracy_sensitivity(tolerances=SENSITIVITY_TOLERANCES, case: int = 1,
                         steps: int = SENSITIVITY_STEPS, seed: int = 0) -> list[dict[str, Any]]:
    """Accuracy vs ``lyapunov_tolerance``: our RDMPC started at rest on its targets.

    Per tolerance: the floor ``sqrt(tol / sigma)``, the largest final error and the largest error
    over the last 10 decisions (true state), the nominal's residual, the tube error, relaxed
    solves and fallbacks.
    """
    env = make_env(case)
    targets = env.scenario.targets_array()[: env.scenario.n_agents]
    x0 = np.concatenate([targets, np.zeros_like(targets)], axis=1)
    out = []
    for k, tol in enumerate(tolerances):
        _progress(f"sensitivity {k + 1}/{len(tolerances)}: lyapunov_tolerance = {tol:g}, {steps} decisions")
        traj, env, pol, wall = run_controller(case, "tube_rdmpc", seed=seed, max_steps=steps,
                                              policy_options={"lyapunov_tolerance": tol},
                                              options={"initial_state": x0})
        err = np.linalg.norm(traj.info["tracking_error"][..., :3], axis=-1)
        nominal = np.linalg.norm(pol.tube.nominal[:, :3] - env.targets(), axis=-1)
        out.append({"lyapunov_tolerance": tol,
                    "floor_m": math.sqrt(tol / pol.cfg.sigma),
                    "final_error_m": float(err[-1].max()),
                    "max_error_last_10_m": float(err[-10:].max()),
                    "nominal_residual_m": float(nominal.max()),
                    "max_tube_error_m": float(pol.info["tube_error_max_m"]),
                    "relaxed_solves": int(pol.info["relaxed"]), "fallbacks": int(pol.info["fallbacks"]),
                    "wall_time_s": round(wall, 1)})
    return out


def run(case: int | None = None, out: str | Path | None = None, plots_dir: str | Path | None = None,
        seed: int = 0, max_steps: int | None = None, controllers=CONTROLLERS,
        policy_options: dict[str, dict] | None = None, tube: bool = True,
        variants=VARIANTS, sensitivity: bool = True) -> dict[str, Any]:
    """Run the reproduction for ``case`` (1, 2, or ``None`` for both); write JSON / figures."""
    cases = CASES if case is None else (int(case),)
    for c in cases:
        _preset(c)
    for v in variants:
        variant_setup(v)
    start = time.perf_counter()
    rows, episodes = [], {}
    jobs = [(c, ctrl, v) for c in cases for ctrl in controllers
            for v in (variants if ctrl == "tube_rdmpc" else ("ours",))]
    for k, (c, ctrl, v) in enumerate(jobs):
        _progress(f"episode {k + 1}/{len(jobs)}: case {c}, {label(ctrl, v)} "
                  f"({('~4 min' if v == 'published' else '~1.5 min') if ctrl == 'tube_rdmpc' else '~15 s'}) ...")
        traj, env, pol, wall = run_controller(c, ctrl, seed=seed, max_steps=max_steps, variant=v,
                                              policy_options=(policy_options or {}).get(ctrl))
        rows.append(summarise(traj, env, pol, ctrl, c, wall, variant=v))
        episodes[(c, label(ctrl, v))] = (traj, env, pol)
        _progress(f"  done in {wall:.0f} s: t_conv {rows[-1]['convergence_time_s']}, "
                  f"final error {rows[-1]['final_error_m']:.4f} m")
    tube_res = tube_experiment() if tube else None
    sens = accuracy_sensitivity(seed=seed) if sensitivity and "tube_rdmpc" in controllers else None
    checks = check_claims(rows)
    result: dict[str, Any] = {
        "paper": PAPER, "cases": list(cases), "variants": list(variants), "rows": rows,
        "claims": checks, "pass": all_met(checks), "paper_claims": CLAIMS, "targets": TARGETS,
        "seed": seed, "wall_time_s": time.perf_counter() - start,
        "settings": {
            "env": "cluster_v0(preset='li2022-case<k>', terminate_on_collision=False): J2 + drag "
                   "truth, 500 km / 45 deg chief, w_bar = 0.1 N on 50 kg (0.002 m/s^2), dt 5 s, "
                   "physics 0.25 s; published variant: reallocate_every=1",
            "tube_rdmpc_exact_max_iter": EXACT_MAX_ITER,
            "policies": {c: dict((policy_options or {}).get(c) or {}) for c in controllers},
        },
    }
    if sens is not None:
        result["sensitivity"] = sens
    if tube_res is not None:
        result["tube_experiment"] = {k: v for k, v in tube_res.items() if k != "runs"}
        result["tube_experiment"]["runs"] = [
            {k: v for k, v in r.items() if not k.startswith("sat1_")} for r in tube_res["runs"]]
    if plots_dir is not None:
        result["figures"] = [str(p) for p in save_figures(episodes, tube_res, Path(plots_dir))]
    if out is not None:
        out = Path(out)
        write_json(out, result)
    return result


def reproduce(plots: str | Path | None = None, seed: int = 0, case: int | None = None,
              variant: str = "both") -> dict[str, Any]:
    """The ``benchmarks.reproduce`` entry point (both cases unless ``case`` is given)."""
    return run(case=case, plots_dir=plots, seed=seed,
               variants=VARIANTS if variant == "both" else (variant,))


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def format_table(result: dict[str, Any]) -> str:
    """The rows, the claim checks and the sensitivity table as plain text."""
    head = (f"{'case':>4} {'controller':>21} | {'t_conv[s]':>9} {'final[m]':>9} {'nom[m]':>8} {'<1m':>3} | "
            f"{'pair[m]':>7} {'obst[m]':>7} {'tgt[m]':>7} | {'F_max[N]':>8} {'dv[m/s]':>8} {'coll':>4} | "
            f"{'solve[ms]':>9} {'tube[m]':>8} {'fallb':>5} {'relax':>5} {'realloc':>7}")
    lines = [head, "-" * len(head)]
    for r in result["rows"]:
        lines.append(
            f"{r['case']:>4} {label(r['controller'], r.get('variant', 'ours')):>21} | "
            f"{_fmt(r['convergence_time_s'], '9.0f')} {r['final_error_m']:9.4f} "
            f"{_fmt(r.get('final_nominal_error_m'), '8.4f')} {r['satellites_within_1m_at_end']:>3} | "
            f"{r['min_pair_distance_m']:7.1f} {r['min_obstacle_distance_m']:7.1f} "
            f"{r['min_target_distance_m']:7.1f} | {r['max_thrust_N']:8.3f} {r['delta_v_total_mps']:8.2f} "
            f"{r['collisions']:>4} | {r['solve_ms_median']:9.2f} {_fmt(r['max_tube_error_m'], '8.5f')} "
            f"{r['fallbacks']:>5} {r.get('relaxed_solves', 0):>5} {r.get('reallocations', 0):>7}")
    lines.append("")
    sens = result.get("sensitivity")
    if sens:
        lines.append("")
        lines.append(f"accuracy vs lyapunov_tolerance (case 1, start on the targets, "
                     f"{SENSITIVITY_STEPS} decisions):")
        lines.append(f"{'tol[m^2]':>9} {'floor[m]':>9} {'final[m]':>9} {'max10[m]':>9} {'nom[m]':>9} "
                     f"{'tube[m]':>9} {'relax':>5} {'fallb':>5}")
        for r in sens:
            lines.append(f"{r['lyapunov_tolerance']:9.0e} {r['floor_m']:9.4f} {r['final_error_m']:9.4f} "
                         f"{r['max_error_last_10_m']:9.4f} {r['nominal_residual_m']:9.4f} "
                         f"{r['max_tube_error_m']:9.5f} {r['relaxed_solves']:>5} {r['fallbacks']:>5}")
    te = result.get("tube_experiment")
    if te:
        for r in te["runs"]:
            lines.append(f"tube (15): k1 = {r['k1']:.0f}: max ||q - q~|| = {r['max_error_m']:.5f} m; "
                         f"exact peak w/(1+k1) = {r['exact_peak_m']:.5f}; (15) eta=1: "
                         f"{r['bound_15_eta1_m']:.5f}; (15) eta=1/(4k2): {r['bound_15_eta_min_m']:.5f}")
    lines.append(format_claims(result["claims"]) + f" (wall time {result['wall_time_s']:.0f} s)")
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Figures
# ----------------------------------------------------------------------------------------------
def save_figures(episodes: dict, tube_res: dict | None, out: Path) -> list[Path]:
    """Analogues of li2022 Fig. 5, 13-24 (PNG)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from satenv.render import draw_scene

    out.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []

    def save(fig, name):
        p = out / name
        fig.savefig(p, bbox_inches="tight", dpi=100)
        plt.close(fig)
        paths.append(p)

    cases = sorted({c for c, _ in episodes})
    for c in cases:
        labels = [lab for cc, lab in episodes if cc == c]
        for ctrl in labels:
            traj, env, pol = episodes[(c, ctrl)]
            sc = env.scenario
            fig = plt.figure(figsize=(7, 6))
            ax = fig.add_subplot(projection="3d")
            pos = traj.states[..., :3]
            tmin = int(np.argmin(traj.info["obstacle_distance"].min(axis=1)))
            scene = {"positions": pos[-1], "targets": sc.targets_array()[traj.info["target_index"][-1]],
                     "labels": [f"s{i + 1}" for i in range(sc.n_agents)],
                     "spheres": [(sc.obstacle_at(traj.t[tmin]), sc.obstacle_distance, "obstacle keep-out"),
                                 (np.asarray(sc.target_spacecraft), sc.target_distance, "target keep-out")],
                     "title": f"case {c}, {ctrl}: trajectories (obstacle at t = {traj.t[tmin]:.0f} s)"}
            draw_scene(ax, scene, pos)
            obs_path = sc.obstacle_at(traj.t)
            ax.plot(obs_path[:, 0], obs_path[:, 1], obs_path[:, 2], "k--", lw=1, label="obstacle path")
            if ctrl.startswith("tube_rdmpc") and pol.history["nominal"]:
                nom = np.array(pol.history["nominal"])[..., :3]
                for i in range(sc.n_agents):
                    ax.plot(nom[:, i, 0], nom[:, i, 1], nom[:, i, 2], ":", color="grey", lw=0.8)
            save(fig, f"fig05_trajectories_case{c}_{ctrl.replace('[', '_').rstrip(']')}.png")

        # Fig. 15-22: distances vs time, RDMPC left / APF right
        panels = [("fig15_16", "tracking_error", "distance to target [m]", True),
                  ("fig17_18", "obstacle_distance", "distance to obstacle [m]", False),
                  ("fig19_20", "pair_distance", "distance to nearest satellite [m]", False),
                  ("fig21_22", "target_distance", "distance to target spacecraft [m]", False)]
        for name, key, label, is_err in panels:
            fig, axes = plt.subplots(1, len(labels), figsize=(6 * len(labels), 4), sharey=True,
                                     squeeze=False)
            axes = axes[0]
            for ax, ctrl in zip(axes, labels, strict=True):
                traj, env, _ = episodes[(c, ctrl)]
                sc = env.scenario
                y = traj.info[key]
                y = np.linalg.norm(y[..., :3], axis=-1) if is_err else y
                for i in range(y.shape[1]):
                    ax.plot(traj.t, y[:, i], lw=1, label=f"sat {i + 1}")
                limit = {"obstacle_distance": sc.obstacle_distance, "pair_distance": sc.pair_distance,
                         "target_distance": sc.target_distance}.get(key)
                if limit is not None:
                    ax.axhline(limit, color="r", ls="--", lw=1, label="safety distance")
                if is_err:
                    ax.set_yscale("log")
                ax.set_title(f"case {c}, {ctrl}")
                ax.set_xlabel("t [s]")
                ax.grid(alpha=0.3)
            axes[0].set_ylabel(label)
            axes[-1].legend(fontsize=7, ncol=2)
            save(fig, f"{name}_{key}_case{c}.png")

        # Fig. 23/24: thrust of Sat 1
        fig, axes = plt.subplots(1, len(labels), figsize=(6 * len(labels), 4), sharey=True, squeeze=False)
        axes = axes[0]
        for ax, ctrl in zip(axes, labels, strict=True):
            traj, env, pol = episodes[(c, ctrl)]
            sc = env.scenario
            if ctrl.startswith("tube_rdmpc") and pol.tube.u_total:
                u = np.array(pol.tube.u_total)[:, 0] * sc.mass
                t = np.arange(len(u)) * sc.physics_dt
            else:
                u = traj.info["accel"][1:, 0] * sc.mass
                t = traj.t[:-1]
            for k, axis in enumerate("xyz"):
                ax.plot(t, u[:, k], lw=0.8, label=f"F_{axis}")
            ax.axhline(sc.thrust_max, color="r", ls="--", lw=1)
            ax.axhline(-sc.thrust_max, color="r", ls="--", lw=1)
            ax.set_title(f"case {c}, {ctrl}: thrust of Sat 1")
            ax.set_xlabel("t [s]")
            ax.grid(alpha=0.3)
        axes[0].set_ylabel("force [N]")
        axes[-1].legend(fontsize=8)
        save(fig, f"fig23_24_thrust_sat1_case{c}.png")

        # Fig. 13 along the runs: ||q - q~|| of every satellite per RDMPC variant
        rd = [lab for lab in labels if lab.startswith("tube_rdmpc")]
        if rd:
            fig, axes = plt.subplots(1, len(rd), figsize=(6 * len(rd), 4), sharey=True, squeeze=False)
            for ax, ctrl in zip(axes[0], rd, strict=True):
                _, env, pol = episodes[(c, ctrl)]
                eps = pol.tube_errors()
                t = np.arange(len(eps)) * env.scenario.physics_dt
                for i in range(eps.shape[1]):
                    ax.plot(t, eps[:, i] * 1e3, lw=0.6)
                ax.axhline(pol.info["tube_bound_m"] * 1e3, color="k", ls="--", lw=1, label="(15), SI w_bar")
                ax.axhline(accuracy_bound(pol.cfg) * 1e3, color="r", ls=":", lw=1,
                           label="li2022 0.071 m (w_bar = 0.1)")
                ax.set_yscale("log")
                ax.set_title(f"case {c}, {ctrl}: ||q - q~|| per satellite")
                ax.set_xlabel("t [s]")
                ax.grid(alpha=0.3)
            axes[0][0].set_ylabel("tube error [mm]")
            axes[0][-1].legend(fontsize=8)
            save(fig, f"fig13_run_tube_error_case{c}.png")

    if tube_res is not None:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
        for r in tube_res["runs"]:
            e = np.array(r["sat1_error_m"])
            t = np.arange(len(e)) * r["dt"]
            line, = ax1.plot(t, e * 1e3, lw=1, label=f"k1 = {r['k1']:.0f}")
            ax1.axhline(r["bound_15_eta1_m"] * 1e3, color=line.get_color(), ls="--", lw=0.8)
            ax1.axhline(r["bound_15_eta_min_m"] * 1e3, color=line.get_color(), ls=":", lw=0.8)
            if r["k1"] == 2.0:
                kap = np.array(r["sat1_kappa_N"])
                for k, axis in enumerate("xyz"):
                    ax2.plot(t, kap[:, k], lw=1, label=f"kappa_{axis}")
        ax1.set_title("Fig. 13: ||q - q~|| of Sat 1 (dashed: (15) eta=1, dotted: eta=1/(4 k2))")
        ax1.set_xlabel("t [s]")
        ax1.set_ylabel("error [mm]")
        ax1.legend()
        ax1.grid(alpha=0.3)
        ax2.set_title("Fig. 14: tube control force of Sat 1 (k1 = 2, k2 = 4)")
        ax2.set_xlabel("t [s]")
        ax2.set_ylabel("force [N]")
        ax2.legend()
        ax2.grid(alpha=0.3)
        save(fig, "fig13_14_tube.png")
    return paths


def add_arguments(parser) -> None:
    """``benchmarks.reproduce li2022`` options: ``--case 1|2`` (default: both), ``--variant``."""
    group = parser.add_argument_group("li2022", f"expected run time: {RUN_TIME}")
    group.add_argument("--case", type=int, choices=CASES, default=None,
                       help="li2022 case (Table 2 = 1, Table 3 = 2); default: both")
    group.add_argument("--variant", choices=(*VARIANTS, "both"), default="both",
                       help="RDMPC variant: ours, published (li2022 as published) or both (default)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.repro_li2022",
                                     description=__doc__.splitlines()[0], epilog=f"expected run time: {RUN_TIME}")
    add_arguments(parser)
    parser.add_argument("--out", type=Path, default=None, help="write the result JSON here")
    parser.add_argument("--plots", type=Path, default=None, help="save the figures (PNG) here")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-steps", type=int, default=None, help="decisions per episode (default 400)")
    args = parser.parse_args(argv)
    result = run(case=args.case, out=args.out, plots_dir=args.plots, seed=args.seed,
                 max_steps=args.max_steps,
                 variants=VARIANTS if args.variant == "both" else (args.variant,))
    print(format_table(result))
    if args.out is not None:
        print(f"wrote {args.out}")
    return 0 if result["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
