"""Print the achieved errors of satenv.dynamics against the independent truth (tests/truth.py).

Usage:  python tests/report_dynamics_errors.py [--json FILE]

Runs the same computations as tests/test_dynamics_validation.py (one orbit, DT = 10 s, 500 km /
51.6 deg chief, circular and e = 0.05) and prints markdown tables of the errors in metres.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import test_dynamics_validation as V  # noqa: E402


def _fmt(x: float) -> str:
    return f"{x:.2e}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, default=None, help="also write all numbers to FILE")
    args = parser.parse_args(argv)
    report: dict = {"dt_s": V.DT, "orbit_cases": V.ORBIT_CASES}

    print(f"## CW (circular chief, one orbit, dt = {V.DT:g} s) vs own closed form / exact ZOH\n")
    cw, zoh = V.cw_discrete_errors(), V.cw_zoh_errors()
    report["cw_discrete"], report["cw_zoh"] = cw, zoh
    print("| check | relative error | max pos err [m] |")
    print("|---|---|---|")
    print(f"| simulate('cw') vs closed-form STM (no thrust) | "
          f"{_fmt(cw['simulate_cw_vs_own_closed_form_rel'])} | "
          f"{_fmt(cw['simulate_cw_vs_own_closed_form_max_pos_err_m'])} |")
    print(f"| cw_matrices A^k vs own STM | {_fmt(cw['A^k_vs_own_closed_form_rel'])} | - |")
    print(f"| cw_stm vs own STM | {_fmt(cw['satenv_cw_stm_vs_own_rel'])} | - |")
    print(f"| cw_matrices (A, B) vs expm ZOH | {_fmt(zoh['AB_vs_expm_rel'])} | - |")
    print(f"| simulate('cw', u) vs exact ZOH (|u_i| <= 1e-3) | {_fmt(zoh['simulate_vs_zoh_rel'])} | "
          f"{_fmt(zoh['simulate_vs_zoh_max_pos_err_m'])} |\n")

    print(f"## satenv.dynamics vs independent DOP853 truth (one orbit, dt = {V.DT:g} s)\n")
    print("LVLH position error, max over the orbit / at the end [m]; deputies at "
          "[0,1000,0], [100,0,50], [100,1000,50] m (zero LVLH velocity) and the CW-bounded "
          "[100,0,50, 0,-2n*100,0]\n")
    print("| model | chief | deputy | max pos err [m] | final pos err [m] | max vel err [m/s] |")
    print("|---|---|---|---|---|---|")
    report["truth"] = []
    for model in V.TRUTH_MODEL:
        for case in V.ORBIT_CASES:
            d = V.truth_errors(model, case)
            report["truth"].append(d)
            for k, dep in enumerate(d["deputies"]):
                label = "[" + ", ".join(f"{v:g}" for v in dep[:3]) + "]" + (" bounded" if dep[4] else "")
                print(f"| {model} | {case} | {label} | {_fmt(d['max_pos_err_m'][k])} | "
                      f"{_fmt(d['final_pos_err_m'][k])} | {_fmt(d['max_vel_err_mps'][k])} |")

    print("\n## J2 differential effect after one orbit ((J2 - Kepler) LVLH position)\n")
    print("| chief | deputy | truth effect [m] | satenv effect [m] | abs err [m] | rel err |")
    print("|---|---|---|---|---|---|")
    report["j2_differential"] = []
    for case in V.ORBIT_CASES:
        d = V.j2_differential_errors(case)
        report["j2_differential"].append(d)
        for k in range(len(d["rel_err"])):
            print(f"| {case} | {k + 1} | {d['truth_effect_m'][k]:.4f} | {d['satenv_effect_m'][k]:.4f} | "
                  f"{_fmt(d['abs_err_m'][k])} | {_fmt(d['rel_err'][k])} |")

    print("\n## CW (satenv 'cw') vs nonlinear truth after one orbit, circular chief\n")
    d = V.cw_scaling_errors()
    report["cw_scaling"] = d
    seps = d["separations_m"]
    print("| direction | " + " | ".join(f"{s:.0f} m" for s in seps) + " | log-log slope |")
    print("|---|" + "---|" * (len(seps) + 1))
    for name, row in d["directions"].items():
        print(f"| {name} | " + " | ".join(_fmt(e) for e in row["err_m"]) + f" | {row['slope']:.4f} |")

    print(f"\n## Thrust (|u_i| <= {V.THRUST_MAG:g} m/s^2 per axis, {V.THRUST_STEPS} steps of "
          f"{V.DT:g} s), held in the rotating LVLH frame\n")
    print("| model | max pos err dep 1 [m] | max pos err dep 2 [m] | thrust effect dep 1/2 [m] |")
    print("|---|---|---|---|")
    report["thrust"] = []
    for model in V.TRUTH_MODEL:
        d = V.thrust_truth_errors(model)
        report["thrust"].append(d)
        print(f"| {model} | {_fmt(d['max_pos_err_m'][0])} | {_fmt(d['max_pos_err_m'][1])} | "
              f"{d['thrust_effect_m'][0]:.2f} / {d['thrust_effect_m'][1]:.2f} |")

    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
