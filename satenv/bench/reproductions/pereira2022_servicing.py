"""Reproduce pereira2022 §5.2: cooperative NMPC on-orbit servicing (Fig. 4 and 5).

``python -m satenv.bench.reproduce pereira2022-servicing --out FILE.json [--plots DIR]``. Expected
run time on 2 shared cores: about 80 s per episode (2 x 1200 NLP solves, 25 ms median), two
episodes (ours and as published), plus about 25 s for the attitude step responses; a progress
line per phase goes to stderr.

Runs ``satenv.servicing_v0(preset="pereira2022")`` (2 spacecraft, waypoints of eq. 50 switching at
t = 40 s and 80 s, 120 s) under ``satenv.baselines.nmpc.NMPC`` (N = 30, eq. 39 weights of §5.2, ipopt;
q_d and omega_d of eq. 43-49 inside the NLP; our terminal attitude cost, weight 100)
through ``satenv.rollout`` and measures, per spacecraft: the time to reach each waypoint within
0.5 m (from the phase start), the final position error, the pointing error (body z axis vs the
line of sight to the object) at the end of each phase, its maximum over the last 10 s of each
phase and at the end, the minimum distance to the object centre and to the other spacecraft,
max |u_j|, max |v_j|, max |omega_j| (per axis), and the NMPC solve time per spacecraft.

The paper gives figures, no numbers. Claims (:mod:`satenv.bench.claims`), each quoting the §5.2
sentence "From Fig. 4 and 5 it is showcased not only that each spacecraft is able to follow the
re-planned flight trajectory but at the same time point to the desired attitude while satisfying
all the constraints considered in this scenario.":

* the constraints (eq. 40-42, input bounds) hold at every step: 0 violations;
  (the one gating claim);
* the waypoints of eq. (50) are followed: the distance to the waypoint at each phase end, with our
  test (within 10 % of the waypoint's norm, 1.5 m on the 15 m waypoints; §5.2 states no tolerance),
  reported, not counted;
* the pointing: the paper gives no value (figures of Euler angles only): the worst pointing error
  is reported with our test (<= 5 deg at every phase end and over its last 10 s), not counted.

Two runs: ``ours`` (NMPC default: the terminal attitude weight x100 and the sign-free quaternion
error ``1 - |eta~|``, both ours) and ``as published`` (``terminal_attitude_weight=0``,
``quaternion_error="signed"``: eq. 39's cost as printed); :func:`departures` lists every setting
that differs from the paper with its measured effect. Every solve is capped by ipopt's iterations
(:data:`SOLVE_CAP`), never by a clock; the failed solves are counted by stop reason (``stop_reasons``).

``diagnostics`` adds an attitude-only step response (30 deg initial error, spacecraft at rest)
with N = 30 and N = 100, which separates the horizon's effect on the attitude settling.
"""

from __future__ import annotations

import re
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from satenv.bench._io import progress
from satenv.bench.claims import (
    NOT_STATED,
    changed_claims,
    departure,
    format_claims,
    no_value,
    passed,
    statement,
)
from satenv.bench.reproductions import figure_paths

PAPER = "pereira2022-servicing"
COMMAND = "python -m satenv.bench.reproduce pereira2022-servicing --out FILE.json --plots DIR"
REACH_TOL = 0.5            # m, time_to_reach_s (reported, not a claim)
SOURCE = ("From Fig. 4 and 5 it is showcased not only that each spacecraft is able to follow the re-planned flight "
          "trajectory but at the same time point to the desired attitude while satisfying all the constraints "
          "considered in this scenario.")
VARIANTS = {"ours": {}, "as published": {"terminal_attitude_weight": 0.0, "quaternion_error": "signed"}}
"""Run -> NMPC options: our default and eq. 39's cost as printed (stage costs only, the signed
quaternion error ``1 - eta~``)."""
SOLVE_CAP = {"solve_time_limit": None}
"""NMPC options of every run here: a solve stops at ipopt's iteration cap (``NMPCConfig.max_iter``),
never on a wall clock, so which solves fail does not depend on the machine or its load."""
WAYPOINT_BAND = 0.10
"""Our test of "follow the re-planned flight trajectory": within 10 % of the waypoint's norm (1.5 m
on the 15 m waypoints). §5.2 gives the waypoints (eq. 50) and figures, no tolerance: the band is
ours, so the waypoint rows are reported, never gating."""
POINTING_TOL_DEG = 5.0     # our threshold for "pointing achieved"
SETTLE_WINDOW_S = 10.0     # last seconds of each phase
RUN_TIME = ("about 5-10 min on 2 shared cores (two episodes, the as-published one slower; "
            "the attitude step responses: --no-diagnostics)")


class PhaseProgress:
    """A policy wrapper printing one stderr line at every phase switch and at the end."""

    def __init__(self, policy, switch_steps, steps: int, dt: float) -> None:
        self.policy, self.marks, self.steps, self.dt = policy, {*switch_steps, steps}, steps, dt
        self.k, self.start = 0, time.perf_counter()

    @property
    def info(self) -> dict:
        return self.policy.info

    def reset(self, seed=None) -> None:
        self.k, self.start = 0, time.perf_counter()
        self.policy.reset(seed=seed)

    def act(self, observations):
        out = self.policy.act(observations)
        self.k += 1
        if self.k in self.marks:
            progress(f"pereira2022-servicing: t = {self.k * self.dt:.0f} s of {self.steps * self.dt:.0f} s "
                     f"({time.perf_counter() - self.start:.0f} s wall)")
        return out


def _phase_bounds(scenario, steps: int) -> list[tuple[int, int]]:
    edges = [0, *[int(s) for s in scenario.switch_steps], steps]
    return [(edges[k], min(edges[k + 1], steps)) for k in range(len(edges) - 1) if edges[k] < steps]


def _f(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def analyse(traj, env, policy) -> dict[str, Any]:
    """Per-spacecraft numbers and the claim checks of one episode."""
    sc = env.scenario
    info, states, dt = traj.info, traj.states, traj.dt
    m = states.shape[1]
    err = np.linalg.norm(info["tracking_error"], axis=-1)            # (T+1, M)
    point = np.degrees(info["pointing_error"])
    att = np.degrees(info["attitude_error"])
    solve = np.asarray(policy.info["agent_solve_ms"]).reshape(-1, m)
    phases = _phase_bounds(sc, traj.steps)
    win = int(round(SETTLE_WINDOW_S / dt))
    rows = []
    for i in range(m):
        per_phase = []
        for k, (a, b) in enumerate(phases):
            seg = err[a + 1: b + 1, i]
            hit = np.nonzero(seg <= REACH_TOL)[0]
            per_phase.append({
                "phase": k,
                "t_start_s": a * dt,
                "waypoint_m": sc.waypoint_array()[k, i].tolist(),
                "time_to_reach_s": _f((hit[0] + 1) * dt) if hit.size else None,
                "error_at_phase_end_m": _f(err[b, i]),
                "position_at_phase_end_m": states[b, i, :3].tolist(),
                "pointing_at_phase_end_deg": _f(point[b, i]),
                "pointing_max_last_10s_deg": _f(point[max(a + 1, b + 1 - win): b + 1, i].max()),
                "attitude_error_at_phase_end_deg": _f(att[b, i]),
            })
        rows.append({
            "agent": traj.agents[i],
            "phases": per_phase,
            "final_position_error_m": _f(err[-1, i]),
            "final_pointing_error_deg": _f(point[-1, i]),
            "min_distance_object_m": _f(info["dist_object"][:, i].min()),
            "min_distance_other_m": _f(info["dist_other"][:, i].min()),
            "max_abs_u": _f(np.abs(info["thrust"][1:, i]).max()),
            "max_abs_v_axis_mps": _f(np.abs(states[:, i, 3:6]).max()),
            "max_speed_mps": _f(np.linalg.norm(states[:, i, 3:6], axis=-1).max()),
            "max_abs_omega_axis_radps": _f(np.abs(states[:, i, 10:]).max()),
            "violations": int(info["violations"][:, i].sum()),
            "solve_ms_median": _f(np.median(solve[:, i])),
            "solve_ms_p90": _f(np.percentile(solve[:, i], 90)),
            "solve_ms_max": _f(solve[:, i].max()),
        })
    tol = sc.contact_tolerance
    worst = {"min_distance_object_m": _f(info["dist_object"].min()),
             "min_distance_other_m": _f(info["dist_other"].min()),
             "max_abs_v_axis_mps": _f(np.abs(states[..., 3:6]).max()),
             "max_abs_omega_axis_radps": _f(np.abs(states[..., 10:]).max()),
             "max_abs_u": _f(np.abs(info["thrust"]).max()),
             "violations": int(info["violations"].sum()), "steps": int(traj.steps)}
    constraints_ok = bool(
        not traj.terminated and traj.steps == sc.max_steps
        and info["violations"].sum() == 0 and not info["collision"].any()
        and info["dist_object"].min() >= sc.keepout_radius - tol
        and info["dist_other"].min() >= sc.separation_radius - tol
        and np.abs(states[..., 3:6]).max() <= sc.v_max
        and np.abs(states[..., 10:]).max() <= sc.omega_max
        and np.abs(info["thrust"]).max() <= max(sc.u_max) + 1e-9)
    phases = [(r["agent"], p) for r in rows for p in r["phases"]]
    return {"rows": rows, "worst": worst, "constraints_ok": constraints_ok}


def claims_of(analysis: dict[str, Any], variant: str = "ours") -> list[dict[str, Any]]:
    """The claim records of one analysed run (module docstring)."""
    from satenv.scenarios.servicing import PRESETS

    sc = PRESETS["pereira2022"]
    worst = analysis["worst"]
    out = [statement("constraints (eq. 40-42, input bounds) at every step (violations)", SOURCE, 0,
                     worst["violations"], analysis["constraints_ok"],
                     rule=f"0 violations; |p| >= {sc.keepout_radius} m, d_ij >= {sc.separation_radius} m, "
                          f"|v_j| <= {sc.v_max}, |w_j| <= {sc.omega_max}", variant=variant, worst=worst)]
    for r in analysis["rows"]:
        for p in r["phases"]:
            radius = WAYPOINT_BAND * float(np.linalg.norm(p["waypoint_m"]))
            out.append(no_value(f"{r['agent']} phase {p['phase']}: distance to the waypoint at the phase end [m]",
                                SOURCE, p["error_at_phase_end_m"], variant=variant,
                                ours=f"within {100 * WAYPOINT_BAND:.0f} % of the waypoint's norm ({radius:.3g} m): "
                                     f"{'met' if p['error_at_phase_end_m'] <= radius else 'not met'}",
                                note="§5.2 gives the waypoints (eq. 50) and figures, no tolerance: the band is ours",
                                waypoint_m=p["waypoint_m"], position_m=p["position_at_phase_end_m"],
                                time_to_reach_0_5m_s=p["time_to_reach_s"]))
    point, where = max((max(p["pointing_at_phase_end_deg"], p["pointing_max_last_10s_deg"]), (r["agent"], p["phase"]))
                       for r in analysis["rows"] for p in r["phases"])
    out.append(no_value("pointing: worst error at a phase end or over its last 10 s [deg]", SOURCE, point,
                        ours=f"<= {POINTING_TOL_DEG} deg: {'met' if point <= POINTING_TOL_DEG else 'not met'}",
                        variant=variant, worst_at=f"{where[0]} phase {where[1]}"))
    return out


def stop_reason(reason: str) -> str:
    """The kind of a failed solve's recorded reason (``guarded_solve``'s text without its numbers):
    the solver's status (``Maximum_Iterations_Exceeded``), ``infeasible: constraint violated
    (<status>)``, ``time limit``, ``error``."""
    if reason.startswith("failed: "):
        return reason[len("failed: "):]
    if (m := re.match(r"(infeasible: \w+ violated) by \S+ \((.*)\)$", reason)):
        return f"{m[1]} ({m[2]})"
    return reason.split(":")[0]


def stop_reasons(policy) -> dict[str, int]:
    """Failed solves of an episode counted by :func:`stop_reason`."""
    return dict(Counter(stop_reason(r) for _, r in policy.info["fallback_steps"]))


def attitude_step_response(horizons=(30, 100), seconds: float = 25.0) -> dict[str, Any]:
    """Attitude error [deg] every 2.5 s from a 30 deg error at rest, per NMPC horizon."""
    import satenv
    from satenv.baselines.nmpc import NMPC
    from satenv.dynamics.attitude import matrix_to_quat, pointing_frame, quat_multiply
    from satenv.rollout import rollout

    p = np.array([[0.0, 40.0, 0.0]])
    steps = int(round(seconds / 0.1))
    out: dict[str, Any] = {"initial_error_deg": 30.0, "t_s": list(np.arange(0, steps + 1, 25) * 0.1)}
    for n_h in horizons:
        env = satenv.make("servicing_v0", initial_position=p, initial_velocity=[[0, 0, 0]],
                          initial_quaternion=[[1, 0, 0, 0]], initial_angular_velocity=[[0, 0, 0]],
                          waypoints=[p], waypoint_times=[], max_steps=steps)
        q_d = matrix_to_quat(pointing_frame(p, reference=env.scenario.pointing_reference))
        axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
        half = np.radians(30.0) / 2
        x0 = np.zeros((1, 13))
        x0[:, :3] = p
        x0[:, 6:10] = quat_multiply(q_d, np.r_[np.cos(half), np.sin(half) * axis])
        policy = NMPC(env, horizon=n_h, **SOLVE_CAP)
        traj = rollout(env, policy, seed=0, options={"initial_state": x0})
        err = np.degrees(traj.info["attitude_error"][:, 0])
        k_min = int(np.argmin(err[:150]))              # first minimum within 15 s
        out[f"N={n_h}"] = {"attitude_error_deg": [round(float(e), 3) for e in err[::25]],
                           "first_minimum_deg": float(err[k_min]),
                           "rebound_max_deg": float(err[k_min:].max()),
                           "final_deg": float(err[-1]),
                           "solve_ms_median": float(np.median(policy.info["agent_solve_ms"]))}
    return out


def plot_figures(traj, env, plots: Path) -> list[str]:
    """Fig. 4 analogue per spacecraft (velocities, Euler XYZ, angular velocity, inputs) and Fig. 5."""
    from satenv.dynamics.attitude import quat_to_euler_xyz
    from satenv.render import _draw_sphere, new_figure

    plots.mkdir(parents=True, exist_ok=True)
    sc = env.scenario
    t = traj.t
    files = []
    for i, agent in enumerate(traj.agents):
        x = traj.states[:, i]
        fig = new_figure(figsize=(8, 10))
        axes = fig.subplots(4, 1, sharex=True)
        for j, lab in enumerate("xyz"):
            axes[0].plot(t, x[:, 3 + j], label=f"v_{lab}")
        axes[0].axhline(sc.v_max, ls=":", c="k")
        axes[0].axhline(-sc.v_max, ls=":", c="k")
        axes[0].set_ylabel("velocity [m/s]")
        eul = np.degrees(quat_to_euler_xyz(x[:, 6:10]))
        for j, lab in enumerate(("roll (X)", "pitch (Y)", "yaw (Z)")):
            axes[1].plot(t, eul[:, j], label=lab)
        axes[1].plot(t, np.degrees(traj.info["pointing_error"][:, i]), "k--", lw=0.8, label="pointing error")
        axes[1].set_ylabel("attitude [deg]")
        for j, lab in enumerate("xyz"):
            axes[2].plot(t, x[:, 10 + j], label=f"w_{lab}")
        axes[2].axhline(sc.omega_max, ls=":", c="k")
        axes[2].axhline(-sc.omega_max, ls=":", c="k")
        axes[2].set_ylabel("ang. velocity [rad/s]")
        u = traj.info["thrust"][1:, i]
        for j in range(6):
            axes[3].step(t[1:], u[:, j], where="pre", lw=0.8, label=f"u{j + 1}")
        axes[3].set_ylabel("inputs u [m/s^2]")
        axes[3].set_xlabel("t [s]")
        for ax in axes:
            ax.legend(fontsize=7, ncol=4, loc="upper right")
            ax.grid(alpha=0.3)
            for ts in sc.waypoint_times:
                ax.axvline(ts, c="grey", lw=0.5)
        fig.suptitle(f"pereira2022 Fig. 4 analogue — {agent} (NMPC, N = 30)")
        fig.tight_layout()
        path = plots / f"servicing_fig4_{agent}.png"
        fig.savefig(path, dpi=110)
        files.append(str(path))
    fig = new_figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    _draw_sphere(ax, np.zeros(3), sc.object_radius, color="grey", alpha=0.3)
    _draw_sphere(ax, np.zeros(3), sc.keepout_radius, color="red", alpha=0.1)
    wp = sc.waypoint_array()
    for i, agent in enumerate(traj.agents):
        pos = traj.states[:, i, :3]
        ax.plot(*pos.T, color=f"C{i}", label=agent)
        ax.scatter(*pos[0], color=f"C{i}", marker="o")
        ax.scatter(*wp[:, i].T, color=f"C{i}", marker="x", s=50)
    lim = 1.2 * sc.keepout_radius
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_zlim(-lim, lim)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend()
    ax.set_title("pereira2022 Fig. 5 analogue: positions (o start, x waypoints)")
    path = plots / "servicing_fig5_positions.png"
    fig.savefig(path, dpi=110)
    files.append(str(path))
    fig = new_figure(figsize=(8, 6))
    axes = fig.subplots(2, 1, sharex=True)
    for i, agent in enumerate(traj.agents):
        axes[0].plot(t, traj.info["dist_object"][:, i], label=f"{agent}: |p|")
        axes[1].plot(t, np.degrees(traj.info["pointing_error"][:, i]), label=agent)
    axes[0].plot(t, traj.info["dist_other"][:, 0], label="between spacecraft")
    axes[0].axhline(sc.keepout_radius, c="r", ls=":", label="r_sigma + r_s")
    axes[0].axhline(sc.separation_radius, c="m", ls=":", label="r_i + r_j")
    axes[0].set_ylabel("distance [m]")
    axes[1].set_ylabel("pointing error [deg]")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("t [s]")
    for ax in axes:
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path = plots / "servicing_distances_pointing.png"
    fig.savefig(path, dpi=110)
    files.append(str(path))
    return files


def run_episode(seed: int = 0, **nmpc_options: Any):
    """One §5.2 episode under the NMPC; returns ``(trajectory, env, policy)``."""
    import satenv
    from satenv.baselines.nmpc import NMPC
    from satenv.rollout import rollout

    env = satenv.make("servicing_v0", preset="pereira2022")
    policy = NMPC(env, **nmpc_options)
    sc = env.scenario
    traj = rollout(env, PhaseProgress(policy, sc.switch_steps, sc.max_steps, sc.dt), seed=seed)
    return traj, env, policy


def departures(runs: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Every setting of our run that differs from §5.2, with its measured effect."""
    from satenv.baselines.nmpc import NMPCConfig

    cfg = NMPCConfig()
    ours, pub = runs.get("ours"), runs.get("as published")
    if ours and pub:
        changed = "; ".join(f"{c['claim']}: {c['status']}" for c in pub["claims"]
                            if c["claim"] in changed_claims(ours["claims"], pub["claims"])) or "no claim changes status"
        po, pp = (next(c for c in r["claims"] if c["claim"].startswith("pointing")) for r in (ours, pub))
        solves = {k: sum(r["solver_statuses"].values()) for k, r in (("ours", ours), ("pub", pub))}
        failed = {k: r["fallbacks"] for k, r in (("ours", ours), ("pub", pub))}
        effect = (f"as published (eq. 39 as printed: no terminal cost and the signed error, measured together): "
                  f"{failed['pub']} of {solves['pub']} solves fail (ours {failed['ours']} of {solves['ours']}); worst "
                  f"pointing {pp['measured']:.4g} deg ({pp['worst_at']}), ours {po['measured']:.3g} deg (our "
                  f"{POINTING_TOL_DEG:g} deg test: {'met' if pp['measured'] <= POINTING_TOL_DEG else 'not met'} as "
                  f"published, {'met' if po['measured'] <= POINTING_TOL_DEG else 'not met'} ours; the paper gives no "
                  f"pointing value); paper-valued claims changed: {changed}")
        fallback_effect = (f"failed solves: ours {failed['ours']} of {solves['ours']}, as published {failed['pub']} of "
                           f"{solves['pub']}; by stop reason: ours {ours['stop_reasons'] or 'none'}, as published "
                           f"{pub['stop_reasons'] or 'none'}")
    else:
        effect = fallback_effect = "not measured in this result"
    unmeasured = "not measured separately"
    return [
        departure("terminal attitude cost", "none (eq. 39: stage costs only)", f"x{cfg.terminal_attitude_weight:g} "
                  "the attitude weights (Q_q, Q_w) on x_N", "with N = 30 (3 s) the attitude settles slowly; the "
                  "terminal cost pulls it within the phase", effect, fields=["terminal_attitude_weight"]),
        departure("quaternion error in the cost (eq. 39)", "[1 - η̃, ε̃] (as printed)",
                  "[1 - |η̃|, ε̃] (sign-free: q_d and -q_d cost the same)",
                  "q and -q are the same attitude; with 1 - η̃ the reference's sign flips (the branch of eq. 43-49) "
                  "make the NLP see the same attitude as the worst one", effect, fields=["quaternion_error"]),
        departure("spacecraft mass", NOT_STATED + " (eq. 35 has F_t u and F_r u without a mass)",
                  "1 kg: F_t u is an acceleration [m/s^2] and F_r u a torque [N m] with the same u",
                  "the paper gives no mass; u_max = 3 then bounds both", unmeasured + " (the paper gives no mass to "
                  "compare with)", fields=["mass"]),
        departure("prediction model (translation)", "the nonlinear relative dynamics (4) in model (35)",
                  "Clohessy-Wiltshire, exact zero-order hold", "a linear model of the translation; at the 15-30 m of "
                  "§5.2 the linearisation changes the acceleration by < 1e-9 m/s^2 (satenv/baselines/nmpc.py)",
                  unmeasured + " (the truth is the nonlinear model (4))", fields=["prediction_model"]),
        departure("solver fallback", NOT_STATED, "a failed solve applies the next input of the last successful plan, "
                  "then brake-and-hold", "the paper assumes every NLP solved; zero thrust is not safe here (the "
                  "spacecraft start on the keep-out sphere)", fallback_effect, fields=["fallback"]),
        departure("warm start", NOT_STATED, "the previous solution shifted by one step; an arc on the sphere towards a "
                  f"new waypoint ('{cfg.initial_guess}')", "a spacecraft exactly opposite its goal otherwise starts on "
                  "a stationary point of the keep-out problem", unmeasured, fields=["warm_start", "initial_guess"]),
        departure("constraint margins", "r_sigma + r_s, r_i + r_j, v_max, omega_max as stated",
                  f"+{cfg.keepout_margin:g} m keep-out / separation, bounds tightened by {cfg.bound_margin:g}",
                  "the integrator between samples; keeps the env's checks clean", unmeasured,
                  fields=["keepout_margin", "separation_margin", "bound_margin"]),
        departure("solver", "CasADi (solver not named)", f"ipopt, Gauss-Newton Hessian, tol {cfg.tol:g}, "
                  f"{cfg.order} (Gauss-Seidel) agents, a solve capped at {cfg.max_iter} iterations (no wall-clock "
                  "limit here)",
                  "the same optimum faster (satenv/baselines/nmpc.py)", unmeasured,
                  fields=["solver", "hessian", "tol", "max_iter", "order", "formulation", "solve_time_limit"]),
        departure("episode length", NOT_STATED, "120 s (three 40 s phases)", "eq. (50) switches at 40 s and 80 s",
                  unmeasured),
        departure("thruster frame", NOT_STATED, "LVLH (eq. 35 as written)", "satenv/scenarios/servicing.py",
                  unmeasured),
        departure("pointing roll reference", NOT_STATED, "a fixed reference axis", "eq. 44 is degenerate for a "
                  "target at the object's centre", unmeasured),
        departure("initial quaternion", "q(0) as printed (norm 0.989)", "normalised", "a unit quaternion",
                  unmeasured),
    ]


def reproduce(plots: str | Path | None = None, seed: int = 0, diagnostics: bool = True,
              variant: str = "both", **nmpc_options: Any) -> dict[str, Any]:
    """Run §5.2 ours and (``variant="both"``) as published (``nmpc_options`` replace fields of both)
    and check the claims."""
    if variant not in ("ours", "both"):
        raise ValueError(f"variant must be 'ours' or 'both', got {variant!r}")
    start = time.perf_counter()
    runs: dict[str, dict[str, Any]] = {}
    for name, opts in VARIANTS.items():
        if variant == "ours" and name != "ours":
            continue
        progress(f"pereira2022-servicing: {name} ...")
        traj, env, policy = run_episode(seed=seed, **{**SOLVE_CAP, **opts, **nmpc_options})
        analysis = analyse(traj, env, policy)
        runs[name] = {"rows": analysis["rows"], "claims": claims_of(analysis, name),
                      "fallbacks": int(policy.info["fallbacks"]),
                      "stop_reasons": stop_reasons(policy),
                      "solver_statuses": dict(policy.info["statuses"]),
                      "iteration_cap": policy.cfg.max_iter, "solve_time_limit": policy.cfg.solve_time_limit,
                      "terminal_attitude_weight": policy.cfg.terminal_attitude_weight,
                      "quaternion_error": policy.cfg.quaternion_error}
        if name == "ours":
            setup = {"preset": "pereira2022", "steps": traj.steps, "dt_s": traj.dt,
                     "horizon": policy.N, "solver": policy.solver, "hessian": policy.hessian, "order": policy.order,
                     "thrust_frame": env.scenario.thrust_frame, "dynamics": env.scenario.dynamics,
                     "pointing_reference": list(env.scenario.pointing_reference),
                     "terminal_attitude_weight": policy.cfg.terminal_attitude_weight,
                     "reach_tolerance_m": REACH_TOL, "pointing_tolerance_deg": POINTING_TOL_DEG}
            ours_run = (traj, env)
    result: dict[str, Any] = {
        "paper": PAPER, "command": COMMAND, "setup": setup, "rows": runs["ours"]["rows"],
        "claims": [c for r in runs.values() for c in r["claims"]],
        "departures": departures(runs),
        "runs": {k: {kk: vv for kk, vv in v.items() if kk != "claims"} for k, v in runs.items()},
        "fallbacks": runs["ours"]["fallbacks"], "solver_statuses": runs["ours"]["solver_statuses"], "seed": seed,
        "stop_reasons": {k: v["stop_reasons"] for k, v in runs.items()},
    }
    result["pass"] = passed(result)
    if diagnostics:
        result["attitude_step_response"] = attitude_step_response()
    if plots is not None:
        result["plots"] = figure_paths(plot_figures(*ours_run, Path(plots)), plots)
    result["wall_time_s"] = round(time.perf_counter() - start, 1)
    return result


def format_table(result: dict[str, Any]) -> str:
    """A plain-text summary beside the paper's claims."""
    lines = [f"pereira2022 §5.2 on-orbit servicing, NMPC N = {result['setup']['horizon']} "
             f"({result['setup']['solver']}), {result['setup']['steps']} steps"]
    head = (f"{'agent':6s} {'phase':>5s} {'reach[s]':>8s} {'err_end[m]':>10s} "
            f"{'point_end[deg]':>14s} {'point_max10s':>12s}")
    for name, run in result["runs"].items():
        lines.append(f"{name} (terminal_attitude_weight = {run['terminal_attitude_weight']:g}, quaternion error "
                     f"{run.get('quaternion_error', 'sign-free')}, failed solves {run['fallbacks']}):")
        lines.append(head)
        for r in run["rows"]:
            for p in r["phases"]:
                reach = "-" if p["time_to_reach_s"] is None else f"{p['time_to_reach_s']:.1f}"
                lines.append(f"{r['agent']:6s} {p['phase']:5d} {reach:>8s} {p['error_at_phase_end_m']:10.4f} "
                             f"{p['pointing_at_phase_end_deg']:14.2f} {p['pointing_max_last_10s_deg']:12.2f}")
    lines.append(f"ours: {'agent':6s} {'min|p|':>7s} {'min d_ij':>8s} {'max|u|':>7s} {'max|v|':>7s} "
                 f"{'max|w|':>7s} {'final err':>9s} {'solve ms (median/p90)':>22s}")
    for r in result["rows"]:
        lines.append(f"{r['agent']:6s} {r['min_distance_object_m']:7.3f} {r['min_distance_other_m']:8.3f} "
                     f"{r['max_abs_u']:7.3f} {r['max_abs_v_axis_mps']:7.3f} "
                     f"{r['max_abs_omega_axis_radps']:7.3f} {r['final_position_error_m']:9.4f} "
                     f"{r['solve_ms_median']:10.1f} / {r['solve_ms_p90']:.1f}")
    lines.append(format_claims(result["claims"]))
    lines.append(f"fallbacks: {result['fallbacks']}; solver statuses: {result['solver_statuses']}")
    diag = result.get("attitude_step_response")
    if diag:
        for key in [k for k in diag if k.startswith("N=")]:
            lines.append(f"attitude step response {key}: error every 2.5 s "
                         f"{diag[key]['attitude_error_deg']}")
    return "\n".join(lines)


def add_arguments(parser) -> None:
    """``satenv.bench.reproduce pereira2022-servicing`` options (and the run time in ``--help``)."""
    group = parser.add_argument_group("pereira2022-servicing", f"expected run time: {RUN_TIME}")
    group.add_argument("--no-diagnostics", dest="diagnostics", action="store_false",
                       help="skip the attitude step responses (N = 30 and 100)")
    group.add_argument("--variant", choices=("ours", "both"), default="both",
                       help="ours only, or ours and as published (eq. 39's cost; default)")
