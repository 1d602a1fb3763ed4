"""Speed benchmark: satenv beside its peers and the machine's memory limit, in one run.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.perf --out perf.json``

Agent-steps per second (one agent advanced by one decision step) of

* ``api``     satenv's PettingZoo API: ``platoon_v0`` (4 followers, cw, the default preset) with
              uniform random actions, dict in / dict out, resets included;
* ``mpe2``    the PettingZoo reference multi-agent env ``mpe2.simple_spread_v3`` (3 agents,
              continuous actions, ``max_cycles=180`` like the platoon episode), the same loop;
* ``batched`` satenv's batched path at each batch size (env copies x 4 agents), for ``cw`` and
              ``j2``: ``dynamics`` = ``RelativeModel.step`` alone, ``core`` = the training path
              (``PlatoonCore.step`` + ``observe``: physics, rewards, infos, observations);
* ``vmas``    VMAS ``navigation`` (4 agents, continuous, CPU, one torch thread) at the same batch
              sizes, ``env.step`` (skipped with a note when ``vmas`` is not installed);
* ``limit``   the machine's limit: a numpy copy of the same state + action (+ chief) bytes;
* ``solvers`` per-decision solve times of the scripted MPC baselines that exist (DMPC on
              ``platoon-PLF-cw``; tube-RDMPC, NMPC, C/GMRES on their scenarios when they land).

Every rate is the best of 3 repeats of at least ``--min-time`` seconds, single-threaded
(``OPENBLAS_NUM_THREADS=1``, ``torch.set_num_threads(1)``). The JSON holds the figures, the
ratios satenv/peer and satenv/limit and the issue's targets with ``met`` flags.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from satenv.dynamics import R_EARTH, Orbit, RelativeModel  # noqa: E402

AGENTS = 4
SECTIONS = ("api", "mpe2", "batched", "vmas", "solvers")
DEFAULT_BATCHES = "1,4,16,64,256,1024,4096"


def _rate(fn: Callable[[], Any], agent_steps: int, min_time: float = 0.2, repeats: int = 3) -> float:
    """Best-of-``repeats`` agent-steps per second of ``fn`` (each call = ``agent_steps`` agent-steps)."""
    fn()
    best = 0.0
    for _ in range(repeats):
        calls, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < min_time or calls < 3:
            fn()
            calls += 1
        best = max(best, calls * agent_steps / elapsed)
    return best


def _orbit() -> Orbit:
    return Orbit.circular(R_EARTH + 500e3, i=math.radians(51.6))


# ----------------------------------------------------------------------------------------------
# (b) + (e): the batched path and the memory limit.
# ----------------------------------------------------------------------------------------------
def batched_dynamics(model: str, batch: int, dt: float = 0.1, min_time: float = 0.2) -> dict:
    """Agent-steps/s of ``RelativeModel.step`` on ``batch`` copies x 4 agents, and of a memory copy
    of the same state, action and chief bytes (the machine's limit)."""
    prop = RelativeModel(model, _orbit(), dt)
    rng = np.random.default_rng(0)
    state = {"x": rng.normal(size=(batch, AGENTS, 6)) * 100.0,
             "chief": np.broadcast_to(prop.initial_chief(), (batch, 6)).copy()}
    u = rng.normal(size=(batch, AGENTS, 3)) * 1e-3

    def step() -> None:
        state["x"], state["chief"] = prop.step(state["x"], u, state["chief"])

    src = np.concatenate([state["x"].ravel(), u.ravel(), state["chief"].ravel()])
    dst = np.empty_like(src)
    sat = _rate(step, batch * AGENTS, min_time)
    limit = _rate(lambda: np.copyto(dst, src), batch * AGENTS, min_time)
    return {"model": model, "batch": batch, "agents": batch * AGENTS, "bytes": int(src.nbytes),
            "agent_steps_per_s": sat, "memory_limit_agent_steps_per_s": limit,
            "ratio_to_limit": sat / limit}


def batched_core(model: str, batch: int, min_time: float = 0.2) -> dict | None:
    """Agent-steps/s of the platoon training path: ``core.step`` + ``core.observe`` on ``batch`` copies."""
    try:
        from satenv.envs.platoon_v0 import PlatoonCore
        from satenv.scenarios.platoon import resolve_scenario
    except ModuleNotFoundError as exc:
        if not (exc.name or "").startswith("satenv"):
            raise
        return None
    scenario = resolve_scenario("pereira2023", dynamics=model, inclination=math.radians(51.6))
    core = PlatoonCore(scenario, batch=batch)
    rng = np.random.default_rng(0)
    core.reset(core.sample_initial_state(rng, batch), None, rng)
    accel = rng.uniform(-1.0, 1.0, size=(batch, core.n_agents, 3)) * 0.01 * scenario.u_max

    def step() -> None:
        core.step(accel, rng)
        core.observe()

    return {"model": model, "batch": batch, "agents": batch * core.n_agents,
            "agent_steps_per_s": _rate(step, batch * core.n_agents, min_time)}


# ----------------------------------------------------------------------------------------------
# (a) + (c): PettingZoo API loops.
# ----------------------------------------------------------------------------------------------
class PettingZooLoop:
    """Times a PettingZoo parallel env stepped with uniform random actions (resets included)."""

    def __init__(self, env, low: float, high: float, seed: int = 0) -> None:
        self.env, self.low, self.high = env, low, high
        self.rng = np.random.default_rng(seed)
        self.agents = list(env.possible_agents)
        self.dim = env.action_space(self.agents[0]).shape[0]
        env.reset(seed=seed)
        self.best = 0.0
        self._chunk()

    def _chunk(self) -> int:
        env, n = self.env, 0
        for _ in range(50):
            if not env.agents:
                env.reset()
            live = list(env.agents)
            acts = self.rng.uniform(self.low, self.high, size=(len(live), self.dim)).astype(np.float32)
            env.step({a: acts[i] for i, a in enumerate(live)})
            n += len(live)
        return n

    def measure(self, min_time: float) -> float:
        """One timing repeat; keeps the best agent-steps/s seen."""
        steps, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < min_time:
            steps += self._chunk()
        self.best = max(self.best, steps / elapsed)
        return self.best

    def result(self) -> dict:
        return {"agents": len(self.agents), "agent_steps_per_s": self.best,
                "us_per_env_step": 1e6 * len(self.agents) / self.best}


def api_loops(min_time: float, repeats: int = 3) -> tuple[dict, dict]:
    """(a) platoon_v0 (cw and j2) and (c) mpe2 simple_spread, timed in interleaved repeats so that
    a machine shared with other jobs affects both alike."""
    loops: dict[str, PettingZooLoop] = {}
    notes: dict[str, dict] = {}
    try:
        from satenv.envs.platoon_v0 import parallel_env
    except ModuleNotFoundError as exc:
        if not (exc.name or "").startswith("satenv"):
            raise
        notes["api"] = {"skipped": "satenv.envs.platoon_v0 not available"}
    else:
        loops["api"] = PettingZooLoop(parallel_env(), -1.0, 1.0)
        loops["api_j2"] = PettingZooLoop(parallel_env(dynamics="j2", inclination=math.radians(51.6)), -1.0, 1.0)
    try:
        from mpe2 import simple_spread_v3
    except ModuleNotFoundError as exc:
        notes["mpe2"] = {"skipped": f"mpe2 not installed ({exc}); pip install 'satenv[peers]'"}
    else:
        loops["mpe2"] = PettingZooLoop(simple_spread_v3.parallel_env(continuous_actions=True, max_cycles=180),
                                       0.0, 1.0)
    for _ in range(repeats):
        for loop in loops.values():
            loop.measure(min_time)
    api = notes.get("api") or {"env": "platoon_v0 (pereira2023, PLF, cw, 4 followers)", **loops["api"].result(),
                               "j2_agent_steps_per_s": loops["api_j2"].best}
    mpe = notes.get("mpe2") or {"env": "mpe2 simple_spread_v3 (3 agents, continuous, max_cycles=180)",
                                **loops["mpe2"].result()}
    return api, mpe


# ----------------------------------------------------------------------------------------------
# (d): VMAS.
# ----------------------------------------------------------------------------------------------
VMAS_ENV = "vmas navigation (4 agents, continuous actions, cpu, 1 torch thread)"


def vmas_navigation(batch: int, min_time: float) -> dict:
    """Agent-steps/s of VMAS ``navigation`` (``env.step``) with ``batch`` vectorised envs on CPU;
    ``{"skipped": why}`` when VMAS is not installed."""
    try:
        import torch
        import vmas
    except ModuleNotFoundError as exc:
        return {"skipped": f"{exc.name} not installed; pip install vmas"}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        env = vmas.make_env("navigation", num_envs=batch, device="cpu", continuous_actions=True,
                            n_agents=AGENTS, seed=0)
        env.reset()
        gen = torch.Generator().manual_seed(0)
        actions = [torch.rand((batch, 2), generator=gen) * 2 - 1 for _ in env.agents]
        rate = _rate(lambda: env.step(actions), batch * AGENTS, min_time)
    finally:
        torch.set_num_threads(threads)
    return {"batch": batch, "agents": batch * AGENTS, "agent_steps_per_s": rate,
            "version": getattr(vmas, "__version__", "?")}


# ----------------------------------------------------------------------------------------------
# Solver timings of the scripted baselines.
# ----------------------------------------------------------------------------------------------
SOLVERS = [  # (policy, scenario, decisions to time)
    ("dmpc", "platoon-PLF-cw", 180),
    ("tube_rdmpc", "cluster-case1", 6),
    ("nmpc", "servicing-pereira2022", 20),
    ("cgmres", "formation-kannan2022-position", 100),
]


def solver_times(max_decisions_scale: float = 1.0, max_seconds: float = 60.0,
                 policies: tuple[str, ...] | None = None) -> dict:
    """Median / p95 wall time of ``act()`` (all agents) and of the solver's own ``solve_ms`` /
    ``qp_ms`` entries, over the first decisions of one episode (seed 0)."""
    from benchmarks.registry import POLICIES, SCENARIOS, Unavailable

    out: dict[str, Any] = {}
    for pol_name, scen_name, decisions in SOLVERS:
        if policies is not None and pol_name not in policies:
            continue
        key = f"{pol_name}@{scen_name}"
        try:
            env = SCENARIOS[scen_name].make()
            policy = POLICIES[pol_name].make(env)
        except Unavailable as why:
            out[key] = {"skipped": str(why)}
            continue
        obs, _ = env.reset(seed=0)
        policy.reset(seed=0)
        times, start = [], time.perf_counter()
        for _ in range(max(1, int(decisions * max_decisions_scale))):
            t0 = time.perf_counter()
            act = policy.act(obs)
            times.append(1e3 * (time.perf_counter() - t0))
            obs, _, _, _, _ = env.step(act)
            if not env.agents or time.perf_counter() - start > max_seconds:
                break
        info = dict(getattr(policy, "info", {}) or {})
        n = env.core.n_agents if hasattr(env, "core") else len(env.possible_agents)
        row = {"decisions": len(times), "agents": n,
               "act_ms_median": float(np.median(times)), "act_ms_p95": float(np.percentile(times, 95)),
               "act_ms_per_agent_median": float(np.median(times)) / n,
               "fallbacks": int(info.get("fallbacks", 0))}
        for k in ("solve_ms", "qp_ms"):
            v = np.asarray(info.get(k, []), dtype=float).ravel()
            if v.size:
                row[f"{k}_median"] = float(np.median(v))
                row[f"{k}_p95"] = float(np.percentile(v, 95))
                row[f"{k}_count"] = int(v.size)
        out[key] = row
        env.close()
    return out


# ----------------------------------------------------------------------------------------------
# Ratios, targets, CLI.
# ----------------------------------------------------------------------------------------------
def _ratios(result: dict) -> tuple[dict, list[dict]]:
    ratios: dict[str, Any] = {}
    targets: list[dict] = []

    def target(name, value, goal, op=">="):
        if value is not None:
            targets.append({"name": name, "value": value, "target": goal, "op": op,
                            "met": bool(value >= goal)})

    api, mpe = result.get("api") or {}, result.get("mpe2") or {}
    if "agent_steps_per_s" in api and "agent_steps_per_s" in mpe:
        ratios["api_vs_mpe2"] = api["agent_steps_per_s"] / mpe["agent_steps_per_s"]
        target("(a) platoon_v0 API / mpe2 simple_spread, per agent-step", ratios["api_vs_mpe2"], 5.0)
    dyn = [r for r in result.get("batched", []) if r["kind"] == "dynamics"]
    for model, goal in (("cw", 1e7), ("j2", 1e6)):
        rows = [r for r in dyn if r["model"] == model]
        if not rows:
            continue
        best = max(rows, key=lambda r: r["agent_steps_per_s"])
        ratios[f"{model}_best_agent_steps_per_s"] = best["agent_steps_per_s"]
        ratios[f"{model}_best_batch"] = best["batch"]
        ratios[f"{model}_vs_limit_at_best_batch"] = best["ratio_to_limit"]
        ratios[f"{model}_vs_limit_max"] = max(r["ratio_to_limit"] for r in rows)
        ratios[f"{model}_vs_limit_by_batch"] = {str(r["batch"]): r["ratio_to_limit"] for r in rows}
        target(f"(b) {model} dynamics agent-steps/s at its best batch", best["agent_steps_per_s"], goal)
        if model == "cw":
            target("(b) cw dynamics / memory copy at its best batch", best["ratio_to_limit"], 0.25)
    vm = {r["batch"]: r["agent_steps_per_s"] for r in (result.get("vmas") or {}).get("rows", [])}
    if vm:
        for kind in ("core", "dynamics"):
            for model in ("cw", "j2"):
                rows = {r["batch"]: r["agent_steps_per_s"] for r in result.get("batched", [])
                        if r["kind"] == kind and r["model"] == model and r["batch"] in vm}
                if rows:
                    by_batch = {str(b): rows[b] / vm[b] for b in sorted(rows)}
                    ratios[f"{kind}_{model}_vs_vmas_by_batch"] = by_batch
                    target(f"(d) {kind} {model} / VMAS navigation, worst batch", min(by_batch.values()), 1.0)
    return ratios, targets


def _machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), cpu)
    except OSError:
        pass
    return {"platform": platform.platform(), "cpu": cpu, "cpus": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__,
            "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
            "load_average_at_start": _loadavg()}


def _loadavg() -> list[float] | None:
    """1/5/15-minute load averages (a shared machine slows every figure down alike)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


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
                                   f"act median {v['act_ms_median']:.3g} ms ({v['act_ms_per_agent_median']:.3g} ms/agent)"))
    result["ratios"], result["targets"] = _ratios(result)
    result["machine"]["load_average_at_end"] = _loadavg()
    return result


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="perf.json", help="output JSON file")
    parser.add_argument("--batches", default=DEFAULT_BATCHES, help="comma-separated batch sizes")
    parser.add_argument("--sections", default=",".join(SECTIONS),
                        help=f"comma-separated subset of {','.join(SECTIONS)}")
    parser.add_argument("--min-time", type=float, default=0.2, help="seconds per timing repeat (batched)")
    parser.add_argument("--api-time", type=float, default=0.5, help="seconds per timing repeat (PettingZoo loops)")
    parser.add_argument("--solver-scale", type=float, default=1.0,
                        help="fraction of the default number of solver decisions to time")
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
    bad = sorted(set(sections) - set(SECTIONS))
    if bad:
        parser.error(f"unknown --sections {bad}; choose from {list(SECTIONS)}")
    if args.min_time <= 0 or args.api_time <= 0 or args.solver_scale <= 0:
        parser.error("--min-time, --api-time and --solver-scale must be > 0")
    solvers = tuple(s.strip() for s in args.solvers.split(",") if s.strip())
    unknown = sorted(set(solvers) - {p for p, _, _ in SOLVERS})
    if unknown:
        parser.error(f"unknown --solvers {unknown}; choose from {[p for p, _, _ in SOLVERS]}")
    result = run(batches, sections, args.min_time, args.api_time, args.solver_scale, solvers)
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print("ratios: " + json.dumps(result["ratios"], indent=1))
    for t in result["targets"]:
        print(f"[{'met' if t['met'] else 'MISSED'}] {t['name']}: {t['value']:.3g} (target {t['op']} {t['target']:g})")
    print(f"wrote {args.out}", file=sys.stderr)
    return result


if __name__ == "__main__":
    main()
