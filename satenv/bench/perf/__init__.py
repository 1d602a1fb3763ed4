"""Speed benchmark: satenv beside its peers and the machine's memory limit, in one run.

``OPENBLAS_NUM_THREADS=1 python -m satenv.bench.perf --out perf.json``

Agent-steps per second (one agent advanced by one decision step) of

* ``api``     satenv's PettingZoo API: ``platoon_v0`` (4 followers, cw, the default preset) with
              uniform random actions, dict in / dict out, resets included;
* ``mpe2``    the PettingZoo reference multi-agent env ``mpe2.simple_spread_v3`` (3 agents,
              continuous actions, ``max_cycles=180`` like the platoon episode), the same loop;
* ``batched`` satenv's batched path at each batch size (env copies x 4 agents), for ``cw`` and
              ``j2``: ``dynamics`` = ``RelativeModel.step`` alone, ``core`` = the training path
              (``PlatoonCore.step_observe``: physics, rewards, infos, observations);
* ``vmas``    VMAS ``navigation`` (4 agents, continuous, CPU, one torch thread) at the same batch
              sizes, ``env.step`` (skipped with a note when ``vmas`` is not installed);
* ``limit``   the machine's limit: a numpy copy of the same state + action (+ chief) bytes;
* ``solvers`` per-decision solve times of the scripted MPC baselines (DMPC on
              ``platoon-PLF-cw``; tube-RDMPC, NMPC, C/GMRES on their scenarios), per agent too;
* ``guard``   the finiteness guard's cost: the check alone on one step's arrays as a share of the
              ``platoon_v0`` PettingZoo step (target < 5 %, plus an A/B of the step with the check
              on and off) and of the ``satenv.make_vec`` step at each batch size.

More sections run only when named in ``--sections`` (they take minutes):

* ``reproductions`` wall times of ``reproduce li2022 --case 1`` (our variant) and
              ``reproduce pereira2022-servicing`` (a subprocess each, plots off), against their
              targets (li2022 case 1 <= 120 s, servicing <= 20 s; our variant only);

* ``fast_solvers`` (stored as ``solvers.fast_vs_ipopt``) the fast paths of tube-RDMPC (compiled
              ``solver="ipopt-jit"`` with ``warm_duals``; one gcc compile, about 1 min) and NMPC
              (ipopt with its default Gauss-Newton Hessian) against the ipopt reference (primal
              warm start only; exact Hessian) on the same recorded decision problems (ms per agent
              decision, medians, targets 5 ms / 10 ms), and each one's closed-loop
              decision time; ``--solvers`` selects which;
* ``scaling`` the swarm table (:mod:`benchmarks.scaling`): for N = 4 ... 1024 spacecraft of
              the platoon and cluster swarms the PettingZoo step, the 64-copy batched core, its
              memory and the distributed baselines' decision per agent (DMPC; APF, tube-RDMPC up
              to 16), with fitted growth exponents and a plot next to ``--out`` (``*_scaling.png``);

* ``cgmres_ipopt`` one C/GMRES update against an ipopt solve (warm and cold) of the same NMPC
              problem along the closed loop on both kannan2022 scenarios, and the first-input gap;
* ``training`` SB3 PPO ``learn()`` on satenv's batched ``SatVecEnv`` against SB3's
              ``DummyVecEnv`` of one PettingZoo env per copy (env-steps/s, learning and raw);
* ``safety``  the safety filter (:mod:`satenv.bench.perf.safety`): its ms per agent decision
              beside the env step on the same states (cluster_v0 N = 10 at 1 and 64 copies, targets
              0.1 / 0.02 ms; pereira2022 platoon and servicing).
* ``policy_threads`` every shipped network's decision per agent (the filter excluded) beside
              its env's step (target <= 0.2 ms per agent), then a loaded policy's decision time
              with every core busy: torch's default threads, one thread (the peer) and
              ``satenv.training.load``'s one-thread guard (:mod:`satenv.bench.perf.policy_threads`, target
              guard <= 2x one thread).
* ``learning`` the native TorchRL env (``satenv.torchrl.make_env``, 256 copies) against TorchRL's
              generic ``PettingZooWrapper`` over the same ``platoon_v0`` (env only), and end-to-end
              training agent-steps/s of SB3 PPO, BenchMARL MAPPO and DAgger on each env with its
              fast configuration (:data:`satenv.bench.perf.learning.FAST_CONFIGS`, about ``16384 x
              --solver-scale`` agent-steps each) and the env / learner (/ expert) shares of the
              wall time, each skipped with a note when its extra is missing.
* ``learning_loop`` agent-steps/s of the lean PPO (:mod:`satenv.training.rl.ppo`) and SB3 PPO,
              updates included, with the same network and batch on each training task (TPLF
              platoon, cluster), the env's share of an iteration and the lean/SB3 ratio ``vs_sb3``
              (:mod:`satenv.bench.perf.learning_loop`; targets >= 4x, env >= 30 % on the platoon).
* ``experts`` DAgger expert labels per second (:mod:`satenv.bench.perf.experts`): each system's
              expert (NMPC on servicing, re-planning tube-RDMPC on the cluster) through
              :class:`satenv.baselines.experts.ExpertPool` with one worker and with two, and the targets
              (labels/s on two cores, :data:`satenv.bench.perf.experts.LABEL_TARGETS`: >= 100 on
              servicing, >= 200 on the cluster).

The default sections also include

* ``envs``    the envs' comparisons (:mod:`satenv.bench.perf.envs`): ``cluster_v0`` and
              ``servicing_v0`` PettingZoo steps beside mpe2, ``make_vec("cluster_v0")`` at 1024
              copies beside VMAS ``navigation``, and the ring swarm core at N = 1024 against N = 4.

One module per section (``satenv/bench/perf/<section>.py``); a section that is a single call is one
entry of :data:`REGISTRY` (a function of the :class:`Options` and the log returning its JSON
part, optionally with a ``targets`` list that the report collects).

Every rate is the best of 3 repeats of at least ``--min-time`` seconds, single-threaded
(``OPENBLAS_NUM_THREADS=1``, ``torch.set_num_threads(1)``). The JSON holds the figures, the
ratios satenv/peer and satenv/limit and the issue's targets with ``met`` flags.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from satenv.bench._env import single_thread_blas

from . import (
    cgmres,
    envs,
    experts,
    learning,
    learning_loop,
    policy_threads,
    reproductions,
    safety,
    scaling,
    training,
)
from ._common import AGENTS, PettingZooLoop, _loadavg, _machine, _rate
from .api import api_loops
from .batched import batched_core, batched_dynamics
from .guard import GUARD_TARGET, guard_cost
from .learning import learning_throughput
from .reproductions import REPRODUCTION_TARGETS_S, reproduction_times
from .solvers import FAST_SOLVER_TARGETS_MS, SOLVERS, fast_vs_ipopt, solver_times
from .targets import API_VS_MPE2, CORE_VS_VMAS, _ratios
from .vmas import VMAS_ENV, vmas_navigation

__all__ = ["AGENTS", "API_VS_MPE2", "CORE_VS_VMAS", "EXTRA_SECTIONS", "FAST_SOLVER_TARGETS_MS", "GUARD_TARGET",
           "REGISTRY", "REPRODUCTION_TARGETS_S", "SECTIONS", "SOLVERS", "VMAS_ENV", "Options", "PettingZooLoop",
           "api_loops", "batched_core", "batched_dynamics", "fast_vs_ipopt", "guard_cost", "learning_throughput",
           "main", "reproduction_times", "run", "solver_times", "vmas_navigation", "_rate", "_ratios"]

SECTIONS = ("api", "mpe2", "batched", "vmas", "solvers", "guard", "envs")
"""The default sections."""
EXTRA_SECTIONS = ("fast_solvers", "cgmres_ipopt", "training", "learning", "scaling", "reproductions", "safety",
                  "policy_threads", "experts", "learning_loop")
"""Sections that run only when named in ``--sections``."""
DEFAULT_BATCHES = "1,4,16,64,256,1024,4096"


@dataclass(frozen=True)
class Options:
    """The command line's settings, as the sections of :data:`REGISTRY` receive them."""

    batches: list[int]
    min_time: float = 0.2
    api_time: float = 0.5
    scale: float = 1.0
    """``--solver-scale``: shrinks the opt-in sections' loops (smoke runs)."""
    solvers: tuple[str, ...] | None = None


Log = Callable[[str], None]


def _cgmres(o: Options, log: Log) -> list[dict]:
    steps = max(2, int(1000 * o.scale))
    rows = [cgmres.cgmres_vs_ipopt(p, steps, max(1, min(10, steps - 1)))
            for p in ("kannan2022-position", "kannan2022-collision")]
    for r in rows:
        log(f"C/GMRES {r['scenario']}: update {r['cgmres_update_ms_median']:.2f} ms, ipopt warm "
            f"{r['ipopt_warm_ms_median']:.1f} ms / cold {r['ipopt_cold_ms_median']:.1f} ms")
    return rows


def _training(o: Options, log: Log) -> dict:
    out = training.training_throughput(copies=max(2, int(64 * o.scale)), n_steps=max(8, int(128 * o.scale)),
                                       rollouts=1 if o.scale < 1 else 3, n_epochs=1 if o.scale < 1 else 10)
    log(f"training: satenv/dummy learn x{out['ratio_learn_env_steps_per_s']:.1f}, "
        f"raw x{out['ratio_raw_env_steps_per_s']:.1f}")
    return out


def _scaling(o: Options, log: Log) -> dict:
    out = scaling.scaling(scaling.SIZES, scaling.COPIES, decisions=max(2, int(5 * o.scale)), log=log)
    for key in scaling.FAMILIES:
        log(f"scaling {key}: growth exponents {out[key]['growth_exponent']}")
    return out


REGISTRY: dict[str, Callable[[Options, Log], Any]] = {
    "guard": lambda o, log: guard_cost(o.api_time, o.batches, log),
    "envs": lambda o, log: envs.env_speed(o.min_time, o.api_time, log=log),
    "reproductions": lambda o, log: reproductions.reproduction_times(log),
    "safety": safety.run,
    "experts": experts.run,
    "learning_loop": learning_loop.run,
    "policy_threads": policy_threads.run,
    "cgmres_ipopt": _cgmres,
    "training": _training,
    "scaling": _scaling,
    "learning": lambda o, log: learning.learning_throughput(agent_steps=max(64, int(16384 * o.scale)),
                                                            steps=max(3, int(100 * o.scale)), log=log),
}
"""Sections that are one call each: ``name -> section(options, log) -> JSON part``, run in this
order after the built-in ones (``api``, ``mpe2``, ``batched``, ``vmas``, ``solvers``,
``fast_solvers``). A new section is a module and one entry here (plus its name in
:data:`SECTIONS` or :data:`EXTRA_SECTIONS`)."""


def run(batches: list[int], sections: tuple[str, ...] = SECTIONS, min_time: float = 0.2,
        api_time: float = 0.5, solver_scale: float = 1.0, solvers: tuple[str, ...] | None = None,
        log: Callable[[str], None] = print) -> dict:
    """Run the selected sections; returns the JSON-able result."""
    result: dict[str, Any] = {"machine": _machine(), "config": {"batches": batches, "agents_per_copy": AGENTS,
                                                                "min_time_s": min_time, "sections": list(sections)}}
    if "api" in sections or "mpe2" in sections:
        api, mpe = api_loops(api_time)
        if "api" in sections:
            result["api"] = api
            log(f"(a) platoon_v0 API: {api.get('agent_steps_per_s', math.nan):.3g} agent-steps/s "
                f"({api.get('us_per_env_step', math.nan):.0f} us per env step; j2: "
                f"{api.get('j2_agent_steps_per_s', math.nan):.3g})")
        if "mpe2" in sections:
            result["mpe2"] = mpe
            log(f"(c) mpe2 simple_spread: {mpe.get('agent_steps_per_s', math.nan):.3g} agent-steps/s")
    if "batched" in sections or "vmas" in sections:
        rows, vrows, vskip = [], [], None
        for batch in batches:   # every measurement of one batch size back to back
            if "batched" in sections:
                for model in ("cw", "j2"):
                    row = {"kind": "dynamics", **batched_dynamics(model, batch, min_time=min_time)}
                    rows.append(row)
                    log(f"(b) {model:>2} dynamics batch {batch:>5}: {row['agent_steps_per_s']:.3g} agent-steps/s "
                        f"({100 * row['ratio_to_limit']:.1f} % of the memory copy "
                        f"{row['memory_limit_agent_steps_per_s']:.3g})")
                    core = batched_core(model, batch, min_time=min_time)
                    if core is not None:
                        rows.append({"kind": "core", **core})
                        log(f"(b) {model:>2} core     batch {batch:>5}: {core['agent_steps_per_s']:.3g} agent-steps/s")
            if "vmas" in sections and vskip is None:
                v = vmas_navigation(batch, min_time)
                if "skipped" in v:
                    vskip = v["skipped"]
                    log(f"(d) vmas: skipped ({vskip})")
                else:
                    vrows.append(v)
                    log(f"(d) vmas navigation batch {batch:>5}: {v['agent_steps_per_s']:.3g} agent-steps/s")
        if "batched" in sections:
            result["batched"] = rows
        if "vmas" in sections:
            result["vmas"] = {"skipped": vskip} if vskip else {"env": VMAS_ENV, "rows": vrows}
    if "solvers" in sections:
        result["solvers"] = solver_times(solver_scale, policies=solvers)
        for k, v in result["solvers"].items():
            log(f"solver {k}: " + (f"skipped ({v['skipped']})" if "skipped" in v else
                                   f"act median {v['act_ms_median']:.3g} ms "
                                   f"({v['act_ms_per_agent_median']:.3g} ms/agent)"))
    if "fast_solvers" in sections and (solvers is None or {"tube_rdmpc", "nmpc"} & set(solvers)):
        fast = result.setdefault("solvers", {})["fast_vs_ipopt"] = fast_vs_ipopt(solver_scale, solvers)
        for k, v in fast.items():
            log(f"fast solver {k}: {v['fast_ms_per_agent_decision_median']:.3g} ms/agent decision, "
                f"ipopt {v['ipopt_ms_per_agent_decision_median']:.3g} ms on the same {v['problems']} "
                f"problems (compile {v['compile_s']:.0f} s)")
    opts = Options(batches, min_time, api_time, solver_scale, solvers)
    for name, section in REGISTRY.items():
        if name in sections:
            result[name] = section(opts, log)
    result["ratios"], result["targets"] = _ratios(result)
    result["machine"]["load_average_at_end"] = _loadavg()
    return result


def main(argv: list[str] | None = None) -> dict:
    """The command line; sets one BLAS thread (``satenv.bench._env.single_thread_blas``) first."""
    single_thread_blas()
    from satenv.cliargs import new_parser

    parser = new_parser(prog="satenv perf", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="perf.json", help="output JSON file")
    parser.add_argument("--batches", default=DEFAULT_BATCHES, help="comma-separated batch sizes")
    parser.add_argument("--sections", default=",".join(SECTIONS),
                        help=f"comma-separated subset of {','.join(SECTIONS)} (the default), or of the "
                             f"opt-in {','.join(EXTRA_SECTIONS)}")
    parser.add_argument("--min-time", type=float, default=0.2, help="seconds per timing repeat (batched)")
    parser.add_argument("--api-time", type=float, default=0.5, help="seconds per timing repeat (PettingZoo loops)")
    parser.add_argument("--solver-scale", type=float, default=1.0,
                        help="fraction of the default number of solver decisions (and of the opt-in "
                             "sections' loops) to time")
    parser.add_argument("--solvers", default=",".join(p for p, _, _ in SOLVERS),
                        help="comma-separated baselines whose solve times to measure")
    args = parser.parse_args(argv)
    try:
        batches = [int(b) for b in args.batches.split(",")]
        if not batches or min(batches) < 1:
            raise ValueError
    except ValueError:
        parser.error(f"--batches must be comma-separated positive integers, got {args.batches!r}")
    sections = tuple(s.strip() for s in args.sections.split(",") if s.strip())
    bad = sorted(set(sections) - set(SECTIONS + EXTRA_SECTIONS))
    if bad:
        parser.error(f"unknown --sections {bad}; choose from {list(SECTIONS + EXTRA_SECTIONS)}")
    if args.min_time <= 0 or args.api_time <= 0 or args.solver_scale <= 0:
        parser.error("--min-time, --api-time and --solver-scale must be > 0")
    solvers = tuple(s.strip() for s in args.solvers.split(",") if s.strip())
    unknown = sorted(set(solvers) - {p for p, _, _ in SOLVERS})
    if unknown:
        parser.error(f"unknown --solvers {unknown}; choose from {[p for p, _, _ in SOLVERS]}")
    result = run(batches, sections, args.min_time, args.api_time, args.solver_scale, solvers)
    if "scaling" in result:
        result["scaling"]["plot"] = os.path.splitext(args.out)[0] + "_scaling.png"
        scaling.plot(result["scaling"], result["scaling"]["plot"])
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print("ratios: " + json.dumps(result["ratios"], indent=1))
    for t in result["targets"]:
        print(f"[{'met' if t['met'] else 'MISSED'}] {t['name']}: {t['value']:.3g} (target {t['op']} {t['target']:g})")
    print(f"wrote {args.out}", file=sys.stderr)
    return result
