"""Speed benchmark: satenv beside its peers and the machine's memory limit, in one run.

``OPENBLAS_NUM_THREADS=1 python -m benchmarks.perf --out perf.json``

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

Six more sections run only when named in ``--sections`` (they take minutes):

* ``reproductions`` issue 17's wall times of ``reproduce li2022 --case 1`` (both variants) and
              ``reproduce pereira2022-servicing`` (a subprocess each, plots off), against their
              targets (60 s / 20 s);

* ``fast_solvers`` (stored as ``solvers.fast_vs_ipopt``) the fast paths of tube-RDMPC (compiled
              ``solver="ipopt-jit"`` with ``warm_duals``; one gcc compile, about 1 min) and NMPC
              (ipopt with its default Gauss-Newton Hessian) against the ipopt reference (primal
              warm start only; exact Hessian) on the same recorded decision problems (ms per agent
              decision, medians, issue 17's targets 5 ms / 10 ms), and each one's closed-loop
              decision time; ``--solvers`` selects which;
* ``scaling`` issue 19's swarm table (:mod:`benchmarks.scaling`): for N = 4 ... 1024 spacecraft of
              the platoon and cluster swarms the PettingZoo step, the 64-copy batched core, its
              memory and the distributed baselines' decision per agent (DMPC; APF, tube-RDMPC up
              to 16), with fitted growth exponents and a plot next to ``--out`` (``*_scaling.png``);

* ``cgmres_ipopt`` one C/GMRES update against an ipopt solve (warm and cold) of the same NMPC
              problem along the closed loop on both kannan2022 scenarios, and the first-input gap;
* ``training`` SB3 PPO ``learn()`` on satenv's batched ``SatVecEnv`` against SB3's
              ``DummyVecEnv`` of one PettingZoo env per copy (env-steps/s, learning and raw);
* ``learning`` the native TorchRL env (``satenv.torchrl.make_env``, 256 copies) against TorchRL's
              generic ``PettingZooWrapper`` over the same ``platoon_v0`` (env only), and end-to-end
              training agent-steps/s (env + learner, MLP 64-64, 16 copies, ``20000 x
              --solver-scale`` env steps of one copy each) of SB3 PPO, BenchMARL MAPPO and RLlib
              PPO, each skipped with a note when its extra is missing.

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
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks._env import single_thread_blas
from satenv.dynamics import R_EARTH, Orbit, RelativeModel

AGENTS = 4
SECTIONS = ("api", "mpe2", "batched", "vmas", "solvers", "guard")
"""The default sections."""
EXTRA_SECTIONS = ("fast_solvers", "cgmres_ipopt", "training", "learning", "scaling", "reproductions")
"""Sections that run only when named in ``--sections``."""
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
    """Agent-steps/s of the platoon training path: ``core.step_observe`` (the step and its
    observations, as ``satenv.make_vec`` calls it) on ``batch`` copies."""
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
        core.step_observe(accel, rng)

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
    import satenv

    loops["api"] = PettingZooLoop(satenv.make("platoon_v0"), -1.0, 1.0)
    loops["api_j2"] = PettingZooLoop(satenv.make("platoon_v0", dynamics="j2",
                                                 inclination=math.radians(51.6)), -1.0, 1.0)
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
# the finiteness guard (issue 13): its cost in the PettingZoo step and the make_vec step.
# ----------------------------------------------------------------------------------------------
GUARD_TARGET = 0.05
"""The guard must cost under 5 % of the PettingZoo step time."""


def _best_call_s(fn: Callable[[], Any], number: int = 2000, repeats: int = 7) -> float:
    import timeit

    return min(timeit.repeat(fn, number=number, repeat=repeats)) / number


def _fused_check_s(core, number: int = 2000) -> float:
    """Seconds the compiled kernel's fused finiteness check adds to its pass: the best time of
    the kernel with the check on minus off, interleaved three times (0 if not measurable)."""
    accel = np.zeros(core.x.shape[:-1] + (3,))
    timed: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(3):
        for flag in (True, False):
            core.fused_check = flag
            timed[flag].append(_best_call_s(lambda: core._evaluate_kernel(core.x, accel, observe=True),
                                            number=number))
    core.fused_check = True
    return max(min(timed[True]) - min(timed[False]), 0.0)


def guard_cost(min_time: float = 0.5, batches: list[int] = (1, 64, 1024),
               log: Callable[[str], None] = print) -> dict:
    """The finiteness guard's cost (``satenv.dynamics._checks``): the check alone on one step's
    arrays (best of repeats, so the machine's load barely matters) as a share of the step time,
    for the ``platoon_v0`` PettingZoo step (also an A/B: the median of paired ratios of blocks of
    steps with the check on and off, interleaved) and the ``make_vec`` step of each batch size.
    With the compiled platoon kernel the check is fused into its pass
    (``PlatoonCore.fused_check``): its cost is the kernel's time with it on minus off, plus the
    env's read of the flag."""
    import satenv
    from satenv.dynamics._checks import all_finite

    env = satenv.make("platoon_v0")
    core = env.core
    loop, guard, fused = PettingZooLoop(env, -1.0, 1.0), env._finite_step, core.fused_check

    def enable(on: bool) -> None:   # the kernel's fused check, else the env's StepGuard
        env._finite_step = guard if on else (lambda *args: True)
        if fused:
            core.fused_check = on

    on, off, start = [], [], time.perf_counter()
    while time.perf_counter() - start < 4 * min_time or len(on) < 10:
        for enabled in ((True, False) if len(on) % 2 else (False, True)):
            enable(enabled)
            t0 = time.perf_counter()
            n = loop._chunk()
            (on if enabled else off).append((time.perf_counter() - t0) / n * AGENTS)
    enable(True)
    env.reset(seed=0)
    res, obs = core.step(np.zeros((1, AGENTS, 3))), core.observe()
    if fused:
        check = _fused_check_s(core) + _best_call_s(lambda: res.finite[0])
    else:
        check = _best_call_s(lambda: guard(obs, res.info["state"], sum(res.rewards[0].tolist())))
    step = float(np.median(off))
    pz = {"step_us": 1e6 * step, "step_us_fastest": 1e6 * min(off), "check_us": 1e6 * check,
          "check": "fused in the compiled kernel" if fused else "StepGuard",
          "check_share": check / step, "check_share_of_fastest": check / min(off),
          "ab_overhead": float(np.median(np.array(on) / np.array(off)) - 1), "ab_pairs": len(on)}
    rows = []
    for batch in batches:
        vec = satenv.make_vec("platoon_v0", batch, seed=0)
        vec.reset()
        acts = np.random.default_rng(0).uniform(-1.0, 1.0, vec.action_shape)
        rate = _rate(lambda vec=vec, acts=acts: vec.step(acts), batch * AGENTS, min_time / 2)
        o, r, _, _, info = vec.step(acts)
        if vec.core.fused_check:
            ok = np.ones(batch, bool)
            check_b = _fused_check_s(vec.core, number=200) + _best_call_s(ok.all, number=200)
        else:
            check_b = _best_call_s(lambda o=o, s=info["state"], r=r: all_finite(o, s, r), number=200)
        step_b = batch * AGENTS / rate
        rows.append({"batch": batch, "step_us": 1e6 * step_b, "check_us": 1e6 * check_b,
                     "check_share": check_b / step_b})
        log(f"guard make_vec batch {batch:>5}: check {1e6 * check_b:.2f} us = "
            f"{100 * rows[-1]['check_share']:.2f} % of the {1e6 * step_b:.0f} us step")
    log(f"guard PettingZoo: check {pz['check_us']:.2f} us = {100 * pz['check_share']:.2f} % of the median "
        f"{pz['step_us']:.0f} us step ({100 * pz['check_share_of_fastest']:.2f} % of the fastest); "
        f"A/B {100 * pz['ab_overhead']:+.2f} % over {pz['ab_pairs']} pairs")
    return {"pettingzoo": pz, "make_vec": rows, "target_share": GUARD_TARGET,
            "met": bool(pz["check_share_of_fastest"] < GUARD_TARGET)}


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
    from benchmarks.scoreboard.registry import POLICIES, SCENARIOS
    from benchmarks.scoreboard.specs import Unavailable

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
        for k in ("solve_ms", "qp_ms", "agent_solve_ms"):
            v = np.asarray(info.get(k, []), dtype=float).ravel()
            if v.size:
                row[f"{k}_median"] = float(np.median(v))
                row[f"{k}_p95"] = float(np.percentile(v, 95))
                row[f"{k}_count"] = int(v.size)
        out[key] = row
        env.close()
    return out


FAST_SOLVER_TARGETS_MS = {"tube_rdmpc@cluster-case1": 5.0, "nmpc@servicing-pereira2022": 10.0}
"""Issue 17's targets: ms per agent decision of the fast solver path."""


def _record(scen_name: str, make: Callable, hook: str, decisions: int) -> tuple[Any, list[tuple]]:
    """Run ``make(env)`` (the ipopt reference) for ``decisions`` and record the arguments of every
    call of its solve method ``hook`` (``"nlp.solve"`` or ``"_run_nlp"``)."""
    from benchmarks.scoreboard.registry import SCENARIOS

    env = SCENARIOS[scen_name].make()
    ref = make(env)
    owner_path, name = hook.rsplit(".", 1) if "." in hook else ("", hook)
    owner = ref if not owner_path else getattr(ref, owner_path)
    inner, calls = getattr(owner, name), []

    def recording(*args, **kwargs):  # copies: the controller reuses its warm-start rows
        calls.append(tuple(a.copy() if isinstance(a, np.ndarray) else a for a in (*args, *kwargs.values())))
        return inner(*args, **kwargs)

    setattr(owner, name, recording)
    obs, _ = env.reset(seed=0)
    ref.reset(seed=0)
    for _ in range(decisions):
        obs, *_ = env.step(ref.act(obs))
        if not env.agents:
            break
    setattr(owner, name, inner)
    return ref, calls


def fast_vs_ipopt(decisions_scale: float = 1.0, policies: tuple[str, ...] | None = None) -> dict:
    """ms per agent decision of the fast path and of the ipopt reference on the same recorded
    decision problems (tube-RDMPC li2022 case 1, N = 10; NMPC pereira2022 §5.2, N = 30), medians,
    the compile time and the largest first-control gap.

    Tube-RDMPC: the reference is ipopt with the primal warm start only (``warm_duals=False``); the
    fast path is ``solver="ipopt-jit"`` with ``warm_duals`` (each satellite's multipliers chained
    through the recorded decisions, as in the controller); ``warm_duals_ms_...`` is the
    interpreted ipopt with ``warm_duals`` alone. NMPC: the default ``hessian="gauss-newton"``
    against ``hessian="exact"``, and both one's median NLP time along the closed loop
    (:func:`nmpc_closed_loop`)."""
    from baselines.nmpc import NMPC
    from baselines.tube_rdmpc import TubeRDMPC

    out: dict[str, Any] = {}
    for key, cls, hook, decisions in (("tube_rdmpc@cluster-case1", TubeRDMPC, "nlp.solve", 3),
                                      ("nmpc@servicing-pereira2022", NMPC, "_run_nlp", 10)):
        if policies is not None and key.split("@")[0] not in policies:
            continue
        tube = cls is TubeRDMPC
        ref_options = {"warm_duals": False} if tube else {"hessian": "exact"}
        ref, calls = _record(key.split("@")[1], lambda env, c=cls, o=ref_options: c(env, solver="ipopt", **o),
                             hook, max(1, int(decisions * decisions_scale)))
        start = time.perf_counter()
        pols = {"ipopt": ref, "fast": cls(ref.env, solver="ipopt-jit") if tube else cls(ref.env)}
        slots = [ref.nlp.slots(args[1]) for args in calls] if tube else []
        if tube:   # build (compile) the NLPs of the recorded problems' slot counts before timing
            pols["fast"].nlp.prepare(slots)
        compile_s = time.perf_counter() - start
        if tube:
            pols["warm_duals"] = cls(ref.env, solver="ipopt")
            for pol in (ref, pols["warm_duals"]):
                pol.nlp.prepare(slots)
        times: dict[str, list[float]] = {label: [] for label in pols}
        duals = {label: [{} for _ in range(ref.m)] for label in pols}
        gap = 0.0
        for k, args in enumerate(calls):
            first = []
            for label, pol in pols.items():
                if tube:
                    warm = duals[label][k % ref.m] if pol.cfg.warm_duals else None
                    t0 = time.perf_counter()
                    w = pol.nlp.solve({}, *args[1:4], warm)
                    times[label].append(time.perf_counter() - t0)
                    first.append(None if w is None else w[:3] * pol.u_nom)
                else:
                    res: dict[str, Any] = {}
                    t0 = time.perf_counter()
                    w, _, _ = pol._run_nlp(args[0], res)
                    times[label].append(time.perf_counter() - t0)
                    first.append(w[pol._u_idx[0]])
            if all(f is not None for f in first):
                gap = max(gap, max(float(np.abs(first[0] - f).max()) for f in first[1:]))
        ms = {label: float(np.median(t) * 1e3) for label, t in times.items()}
        out[key] = {"problems": len(calls), "ipopt_ms_per_agent_decision_median": ms["ipopt"],
                    "fast_ms_per_agent_decision_median": ms["fast"], "speedup": ms["ipopt"] / ms["fast"],
                    "fast_solver": "ipopt-jit + warm_duals" if tube else "ipopt + gauss-newton",
                    "compile_s": compile_s,
                    "max_first_control_diff": gap, "target_ms": FAST_SOLVER_TARGETS_MS[key]}
        if tube:
            out[key]["warm_duals_ms_per_agent_decision_median"] = ms["warm_duals"]
            out[key]["closed_loop_ms_per_agent_decision"] = tube_closed_loop(ref.env)
        else:
            out[key]["closed_loop_ms_per_agent_decision"] = nmpc_closed_loop(
                ref.env, max(10, int(300 * decisions_scale)))
    return out


def nmpc_closed_loop(env, decisions: int = 300) -> dict[str, float]:
    """Median ms per NLP solve of the NMPC along its own closed loop (the first ``decisions``
    steps of §5.2 from seed 0: the first waypoint phase is 400), per Hessian."""
    from baselines.nmpc import NMPC

    out = {}
    for hessian in ("exact", "gauss-newton"):
        pol = NMPC(env, hessian=hessian)
        act_times(env, pol, decisions)
        out[hessian.replace("-", "_")] = float(np.median(pol.info["agent_solve_ms"]))
    return out


def tube_closed_loop(env, decisions: int = 6, workers: tuple[int, ...] = (1, 2)) -> dict[str, float]:
    """Wall time of whole ``TubeRDMPC.act`` calls (ipopt with ``warm_duals``) divided by the number
    of satellites, median over ``decisions`` from the same start, for each thread count (the
    decisions are identical; ``tests/test_tube_rdmpc.py``)."""
    from baselines.tube_rdmpc import TubeRDMPC

    return {f"workers_{n}": float(np.median(act_times(env, TubeRDMPC(env, workers=n), decisions)) * 1e3 / len(env.possible_agents))
            for n in workers}


def act_times(env, policy, decisions: int, seed: int = 0) -> list[float]:
    """Wall time [s] of each ``policy.act`` over the first ``decisions`` of one episode from
    ``reset(seed)`` (fewer if it ends)."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed=seed)
    times = []
    for _ in range(decisions):
        t0 = time.perf_counter()
        act = policy.act(obs)
        times.append(time.perf_counter() - t0)
        obs, *_ = env.step(act)
        if not env.agents:
            break
    return times


# ----------------------------------------------------------------------------------------------
# C/GMRES against ipopt on the same problem (kannan2022).
# ----------------------------------------------------------------------------------------------
def _ms_stats(seconds: list[float]) -> tuple[float, float]:
    return float(np.median(seconds) * 1e3), float(np.percentile(seconds, 95) * 1e3)


def _cgmres_loop(env, pol, steps: int, stride: int) -> dict[str, list[float]]:
    """Closed loop of ``steps`` C/GMRES updates; at every ``stride``-th one, the same problem
    (state, horizon ``T(t)``, N, cost) solved by ipopt (tol 1e-8) warm- and cold-started."""
    ocp, warm = pol.ocp, None
    times: dict[str, list[float]] = {"cgmres": [], "warm": [], "cold": [], "diff": []}
    for k in range(steps):
        x, t = env.state(), pol.time
        start = time.perf_counter()
        w = pol.update(x)
        times["cgmres"].append(time.perf_counter() - start)
        if k % stride == 0 and k > 0:
            ref = ocp.solve_ipopt(x, pol.horizon_at(t), guess=warm, tol=1e-8)
            cold = ocp.solve_ipopt(x, pol.horizon_at(t), tol=1e-8)
            warm = ref["U"]
            times["warm"].append(ref["time_s"])
            times["cold"].append(cold["time_s"])
            times["diff"].append(float(np.abs(w - ref["w0"]).max() * env.scenario.u_max))
        act = w.reshape(ocp.m, 3)
        env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
    return times


def cgmres_vs_ipopt(preset: str, steps: int = 1000, stride: int = 10) -> dict:
    """Median / p95 ms of one C/GMRES update and of ipopt solves of the same NMPC problem on
    ``formation_v0(preset=preset)``, their ratios and the largest first-input gap [m/s^2]."""
    import satenv
    from baselines.cgmres import CGMRES

    env = satenv.make("formation_v0", preset=preset)
    pol = CGMRES(env)
    env.reset(seed=0)
    pol.reset(seed=0)
    pol.ocp.solve_ipopt(np.zeros(pol.ocp.nx), 1.0, tol=1e-8)  # build the NLP outside the timings
    times = _cgmres_loop(env, pol, steps, stride)
    (cg, cg95), (ipw, ipw95), (ipc, ipc95) = (_ms_stats(times[k]) for k in ("cgmres", "warm", "cold"))
    return {"scenario": preset, "steps": steps, "ipopt_solves": len(times["warm"]),
            "unknowns": pol.ocp.dim, "horizon_steps": pol.ocp.N, "kmax": pol.options["kmax"],
            "cgmres_update_ms_median": cg, "cgmres_update_ms_p95": cg95,
            "ipopt_warm_ms_median": ipw, "ipopt_warm_ms_p95": ipw95,
            "ipopt_cold_ms_median": ipc, "ipopt_cold_ms_p95": ipc95,
            "speedup_vs_ipopt_warm": ipw / cg, "speedup_vs_ipopt_cold": ipc / cg,
            "max_first_input_diff_mps2": max(times["diff"]), "fallbacks": pol.info["fallbacks"]}


# ----------------------------------------------------------------------------------------------
# Training throughput: SB3 PPO on the batched env against DummyVecEnv.
# ----------------------------------------------------------------------------------------------
def _ppo(venv, n_steps: int, n_epochs: int, seed: int):
    from stable_baselines3 import PPO

    rollout = n_steps * venv.num_envs
    return PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=max(rollout // 4, 2), n_epochs=n_epochs,
               seed=seed, device="cpu", verbose=0, policy_kwargs={"net_arch": [64, 64]})


def _raw_rate(venv, steps: int) -> float:
    """Vector steps per second with uniform random actions."""
    venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, venv.num_envs, *venv.action_space.shape)).astype(np.float32)
    t0 = time.perf_counter()
    for k in range(steps):
        venv.step(actions[k])
    return steps / (time.perf_counter() - t0)


def _learn_rates(venv, rows_per_copy: int, agents: int, copies: int, n_steps: int, rollouts: int,
                 n_epochs: int, seed: int) -> dict:
    rate = _raw_rate(venv, 200)
    model = _ppo(venv, n_steps, n_epochs, seed)
    t0 = time.perf_counter()
    model.learn(total_timesteps=rollouts * n_steps * venv.num_envs)
    wall = time.perf_counter() - t0
    env_steps = model.num_timesteps // rows_per_copy
    return {"rows": venv.num_envs, "learn_wall_s": round(wall, 3), "learn_scenario_steps": int(env_steps),
            "learn_env_steps_per_s": env_steps / wall, "learn_agent_steps_per_s": env_steps * agents / wall,
            "raw_env_steps_per_s": rate * copies, "raw_agent_steps_per_s": rate * copies * agents}


def training_throughput(env_id: str = "platoon_v0", env_kwargs: dict | None = None, copies: int = 64,
                        n_steps: int = 128, rollouts: int = 3, n_epochs: int = 10, seed: int = 0) -> dict:
    """SB3 PPO ``learn()`` env-steps/s on ``SatVecEnv`` (one batched core step for all copies,
    one row per agent) and on ``DummyVecEnv`` of ``CentralisedEnv`` (one PettingZoo env per copy,
    one row per copy), same PPO settings; and their raw stepping rates (random actions)."""
    import torch
    from stable_baselines3.common.vec_env import DummyVecEnv

    from training.gym_view import CentralisedEnv
    from training.vec_env import SatVecEnv, make_env

    env_kwargs = {"randomize": True} if env_kwargs is None else env_kwargs
    torch.set_num_threads(1)
    m = len(make_env(env_id, **env_kwargs).possible_agents)
    venvs = {"satenv": (lambda: SatVecEnv(make_env(env_id, **env_kwargs), copies, seed=seed), m),
             "dummy": (lambda: DummyVecEnv([lambda: CentralisedEnv(make_env(env_id, **env_kwargs))
                                            for _ in range(copies)]), 1)}
    out: dict[str, Any] = {"env_id": env_id, "env_kwargs": env_kwargs, "copies": copies}
    for name, (make, rows_per_copy) in venvs.items():
        venv = make()
        out[name] = _learn_rates(venv, rows_per_copy, m, copies, n_steps, rollouts, n_epochs, seed)
        venv.close()
    for kind in ("learn", "raw"):
        out[f"ratio_{kind}_env_steps_per_s"] = (out["satenv"][f"{kind}_env_steps_per_s"]
                                                / out["dummy"][f"{kind}_env_steps_per_s"])
    return out


REPRODUCTION_TARGETS_S: dict[str, tuple[list[str], float]] = {
    "li2022 --case 1": (["li2022", "--case", "1"], 60.0),
    "pereira2022-servicing": (["pereira2022-servicing"], 20.0),
}
"""Issue 17's reproduction commands (``benchmarks.reproduce`` arguments) and wall-time targets [s]."""


def reproduction_times(log: Callable[[str], None] = print) -> dict[str, dict]:
    """Wall time of each command of :data:`REPRODUCTION_TARGETS_S`, run as a subprocess (JSON to a
    temporary folder; its exit status is recorded, a claim not met does not stop the section)."""
    import subprocess
    import tempfile

    out = {}
    for name, (args, target) in REPRODUCTION_TARGETS_S.items():
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "benchmarks.reproduce", *args, "--out",
                                   os.path.join(tmp, "out.json")], capture_output=True, text=True)
            wall = time.perf_counter() - start
        out[name] = {"wall_s": wall, "target_s": target, "exit_status": proc.returncode}
        log(f"reproduce {name}: {wall:.0f} s (target {target:.0f} s, exit status {proc.returncode})")
    return out


def _extra_sections(result: dict, sections: tuple[str, ...], scale: float, log: Callable[[str], None]) -> None:
    """The opt-in sections (:data:`EXTRA_SECTIONS`); ``scale`` shrinks their loops (smoke runs)."""
    if "reproductions" in sections:
        result["reproductions"] = reproduction_times(log)
    if "cgmres_ipopt" in sections:
        steps = max(2, int(1000 * scale))
        result["cgmres_ipopt"] = [cgmres_vs_ipopt(p, steps, max(1, min(10, steps - 1)))
                                  for p in ("kannan2022-position", "kannan2022-collision")]
        for r in result["cgmres_ipopt"]:
            log(f"C/GMRES {r['scenario']}: update {r['cgmres_update_ms_median']:.2f} ms, ipopt warm "
                f"{r['ipopt_warm_ms_median']:.1f} ms / cold {r['ipopt_cold_ms_median']:.1f} ms")
    if "training" in sections:
        copies = max(2, int(64 * scale))
        result["training"] = training_throughput(copies=copies, n_steps=max(8, int(128 * scale)),
                                                 rollouts=1 if scale < 1 else 3, n_epochs=1 if scale < 1 else 10)
        log(f"training: satenv/dummy learn x{result['training']['ratio_learn_env_steps_per_s']:.1f}, "
            f"raw x{result['training']['ratio_raw_env_steps_per_s']:.1f}")
    if "scaling" in sections:
        from benchmarks import scaling

        result["scaling"] = scaling.scaling(scaling.SIZES, scaling.COPIES, decisions=max(2, int(5 * scale)),
                                            log=log)
        for key in scaling.FAMILIES:
            log(f"scaling {key}: growth exponents {result['scaling'][key]['growth_exponent']}")
    if "learning" in sections:
        result["learning"] = learning_throughput(frames=max(64, int(20_000 * scale)),
                                                 steps=max(3, int(100 * scale)), log=log)


def learning_throughput(batch: int = 256, frames: int = 20_000, steps: int = 100,
                        log: Callable[[str], None] = print) -> dict:
    """The ``learning`` section: TorchRL envs (env only) and end-to-end training, agent-steps/s."""
    out: dict[str, Any] = {"env_id": "platoon_v0", "agents": AGENTS, "net_arch": [64, 64]}
    try:
        import torch
        from torchrl.envs.libs.pettingzoo import PettingZooWrapper

        import satenv
        from satenv.torchrl import make_env

        torch.set_num_threads(1)

        def rollout_rate(env, n: int, copies: int) -> float:
            td = env.reset()
            t0 = time.perf_counter()
            env.rollout(n, break_when_any_done=False, tensordict=td, auto_reset=False)
            return n * copies * AGENTS / (time.perf_counter() - t0)

        native = rollout_rate(make_env("platoon_v0", batch, seed=0), steps, batch)
        wrapper = rollout_rate(PettingZooWrapper(satenv.make("platoon_v0"), use_mask=False,
                                                 categorical_actions=False, done_on_any=True), steps, 1)
        out["torchrl"] = {"batch": batch, "native_agent_steps_per_s": native,
                          "pettingzoo_wrapper_agent_steps_per_s": wrapper, "ratio": native / wrapper}
        log(f"(e) torchrl native batch {batch}: {native:.3g} agent-steps/s; PettingZooWrapper: "
            f"{wrapper:.3g} ({native / wrapper:.0f}x)")
    except ImportError as err:
        out["torchrl"] = {"skipped": f"torchrl not installed ({err})"}
    out["training"] = {name: _train_rate(name, frames) for name in ("sb3_ppo", "benchmarl_mappo", "rllib_ppo")}
    for name, row in out["training"].items():
        log(f"(f) {name}: " + (f"skipped ({row['skipped']})" if "skipped" in row
                               else f"{row['agent_steps_per_s']:.3g} agent-steps/s end to end"))
    return out


def _train_rate(name: str, frames: int) -> dict:
    """Agent-steps/s of one training stack on platoon_v0 (``frames`` env steps of one copy)."""
    import tempfile

    copies = 16
    with tempfile.TemporaryDirectory() as tmp:
        try:
            if name == "sb3_ppo":
                from stable_baselines3 import PPO

                import satenv
                from training.vec_env import SatVecEnv

                vec = SatVecEnv(satenv.make("platoon_v0"), copies, seed=0)
                model = PPO("MlpPolicy", vec, n_steps=64, batch_size=1024, n_epochs=5, device="cpu", seed=0,
                            policy_kwargs={"net_arch": [64, 64]})
                t0 = time.perf_counter()
                model.learn(total_timesteps=frames * AGENTS)
                return {"agent_steps": model.num_timesteps, "agent_steps_per_s": model.num_timesteps / (time.perf_counter() - t0)}
            if name == "benchmarl_mappo":
                from training.benchmarl_train import BenchMARLConfig, build_experiment

                exp = build_experiment(BenchMARLConfig(max_frames=frames, frames_per_batch=min(frames, 64 * copies),
                                                       num_envs=copies, minibatch_size=1024 // AGENTS,
                                                       minibatch_iters=5, out_dir=tmp))
                t0 = time.perf_counter()
                exp.run()
                return {"agent_steps": exp.total_frames * AGENTS,
                        "agent_steps_per_s": exp.total_frames * AGENTS / (time.perf_counter() - t0)}
            from training.rllib_train import RLlibConfig, run

            batch = min(frames, 64 * copies)
            rows = run(RLlibConfig(iterations=max(1, frames // batch), train_batch_size=batch,
                                   minibatch_size=min(batch, 1024 // AGENTS), num_epochs=5, out_dir=tmp), verbose=False)
            return {"agent_steps": rows[-1]["env_steps"] * AGENTS,
                    "agent_steps_per_s": rows[-1]["env_steps"] * AGENTS / rows[-1]["wall_s"]}
        except ImportError as err:
            return {"skipped": f"{name}: extra not installed ({err})"}


# ----------------------------------------------------------------------------------------------
# Ratios, targets, CLI.
# ----------------------------------------------------------------------------------------------
API_VS_MPE2 = 10.0
"""Issue 17: the PettingZoo API at least 10x mpe2 ``simple_spread`` per agent-step."""
CORE_VS_VMAS = 20.0
"""Issue 17: the batched ``platoon_v0`` core (cw) at least 20x VMAS ``navigation`` at every batch
size (the truth models' cores, e.g. j2, are bounded by their RK4 propagation: target 1x)."""


def _ratios(result: dict) -> tuple[dict, list[dict]]:
    ratios: dict[str, Any] = {}
    targets: list[dict] = []

    def target(name, value, goal, op=">="):
        if value is not None:
            targets.append({"name": name, "value": value, "target": goal, "op": op,
                            "met": bool(value >= goal if op == ">=" else value <= goal)})

    api, mpe = result.get("api") or {}, result.get("mpe2") or {}
    if "agent_steps_per_s" in api and "agent_steps_per_s" in mpe:
        ratios["api_vs_mpe2"] = api["agent_steps_per_s"] / mpe["agent_steps_per_s"]
        target("(a) platoon_v0 API / mpe2 simple_spread, per agent-step", ratios["api_vs_mpe2"], API_VS_MPE2)
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
                    goal = CORE_VS_VMAS if (kind, model) == ("core", "cw") else 1.0
                    target(f"(d) {kind} {model} / VMAS navigation, worst batch", min(by_batch.values()), goal)
    for key, row in ((result.get("solvers") or {}).get("fast_vs_ipopt") or {}).items():
        ratios[f"{key}_fast_vs_ipopt_speedup"] = row["speedup"]
        target(f"(e) {key} fast solver ms per agent decision", row["fast_ms_per_agent_decision_median"],
               row["target_ms"], op="<=")
    for name, row in (result.get("reproductions") or {}).items():
        target(f"(f) reproduce {name} wall time [s]", row["wall_s"], row["target_s"], op="<=")
    if "scaling" in result:
        from benchmarks.scaling import scaling_targets

        for name, value, goal, op in scaling_targets(result["scaling"]):
            targets.append({"name": name, "value": value, "target": goal, "op": op,
                            "met": bool(value >= goal if op == ">=" else value <= goal)})
    return ratios, targets


def _machine() -> dict:
    from benchmarks.scoreboard.report import machine

    return {**machine(), "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
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
    if "fast_solvers" in sections and (solvers is None or {"tube_rdmpc", "nmpc"} & set(solvers)):
        fast = result.setdefault("solvers", {})["fast_vs_ipopt"] = fast_vs_ipopt(solver_scale, solvers)
        for k, v in fast.items():
            log(f"fast solver {k}: {v['fast_ms_per_agent_decision_median']:.3g} ms/agent decision, "
                f"ipopt {v['ipopt_ms_per_agent_decision_median']:.3g} ms on the same {v['problems']} "
                f"problems (compile {v['compile_s']:.0f} s)")
    if "guard" in sections:
        result["guard"] = guard_cost(api_time, batches, log)
    _extra_sections(result, sections, solver_scale, log)
    result["ratios"], result["targets"] = _ratios(result)
    result["machine"]["load_average_at_end"] = _loadavg()
    return result


def main(argv: list[str] | None = None) -> dict:
    """The command line; sets one BLAS thread (``benchmarks._env.single_thread_blas``) first."""
    single_thread_blas()
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf", description=__doc__,
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
        from benchmarks.scaling import plot

        result["scaling"]["plot"] = os.path.splitext(args.out)[0] + "_scaling.png"
        plot(result["scaling"], result["scaling"]["plot"])
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print("ratios: " + json.dumps(result["ratios"], indent=1))
    for t in result["targets"]:
        print(f"[{'met' if t['met'] else 'MISSED'}] {t['name']}: {t['value']:.3g} (target {t['op']} {t['target']:g})")
    print(f"wrote {args.out}", file=sys.stderr)
    return result


if __name__ == "__main__":
    main()
