"""The ``scaling`` section of ``benchmarks.perf`` (issue 19): per-agent cost of swarms of N spacecraft.

For N in :data:`SIZES` on ``platoon_v0`` swarms (:func:`satenv.scenarios.platoon.swarm`, ring
formation over the RING graph, cw) it times

* ``pettingzoo``  agent-steps/s of the dict API (zero actions, one env);
* ``core``        agent-steps/s of the batched core (``step`` + ``observe``, ``COPIES`` copies);
* ``dmpc``        median wall time of ``DMPC.act`` per agent (the distributed baseline);
* ``memory_mib``  the peak of Python/numpy allocations (``tracemalloc``) while building, resetting
  and stepping the ``COPIES``-copy core,

and fits the growth exponent ``c`` of ``cost per agent ~ N^c`` (0: flat) by least squares on
log-log. The cluster's tube-RDMPC / APF are not timed here: ``cluster_v0``'s separation and
graph searches are still the dense O(M^2) kernels (a follow-up; see the README).
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.perf import _rate

SIZES = (4, 16, 64, 256, 1024)
COPIES = 64


def _swarm_kwargs(n: int) -> dict[str, Any]:
    from satenv.scenarios.platoon import swarm

    return swarm(n, "ring", "RING" if n >= 3 else "PLF")


def pettingzoo_rate(n: int, min_time: float) -> float:
    import satenv

    env = satenv.make("platoon_v0", **_swarm_kwargs(n))
    env.reset(seed=0)
    zero = np.zeros(3)

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step({a: zero for a in env.agents})

    return _rate(step, n, min_time)


def core_memory_mib(n: int, copies: int) -> float:
    """Peak allocations [MiB] of building, resetting and stepping the ``copies``-copy core."""
    tracemalloc.start()
    try:
        core_rate(n, copies, 0.0, repeats=0)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def core_rate(n: int, copies: int, min_time: float, repeats: int = 3) -> float:
    """Agent-steps/s of the batched core (``step`` + ``observe``)."""
    from satenv.envs.platoon_v0 import PlatoonCore
    from satenv.scenarios.platoon import resolve_scenario

    sc = resolve_scenario(**_swarm_kwargs(n))
    core = PlatoonCore(sc, batch=copies)
    rng = np.random.default_rng(0)
    core.reset(np.tile(sc.initial_array(), (copies, 1, 1)))
    accel = rng.uniform(-0.01, 0.01, (copies, n, 3))

    def step() -> None:
        core.step(accel)
        core.observe()

    return _rate(step, copies * n, min_time, repeats)


def dmpc_ms_per_agent(n: int, decisions: int) -> float | None:
    """Median ``DMPC.act`` time per agent [ms] over the first decisions of one episode."""
    import satenv

    try:
        import baselines
        env = satenv.make("platoon_v0", **_swarm_kwargs(n))
        policy = baselines.make("dmpc", env)
    except ImportError:
        return None
    obs, _ = env.reset(seed=0)
    policy.reset(seed=0)
    times = []
    for _ in range(decisions):
        t0 = time.perf_counter()
        act = policy.act(obs)
        times.append(time.perf_counter() - t0)
        obs, *_ = env.step(act)
        if not env.agents:
            break
    return 1e3 * float(np.median(times)) / n


def growth_exponent(sizes: list[int], per_agent_cost: list[float]) -> float:
    """``c`` of ``per_agent_cost ~ N^c`` (least squares on log-log)."""
    return float(np.polyfit(np.log(sizes), np.log(per_agent_cost), 1)[0])


def scaling(sizes: tuple[int, ...] = SIZES, copies: int = COPIES, min_time: float = 0.2,
            decisions: int = 5, log: Callable[[str], None] = print) -> dict:
    """The scaling table (module docstring) with growth exponents."""
    rows = []
    for n in sizes:
        row: dict[str, Any] = {"n": n, "pettingzoo_agent_steps_per_s": pettingzoo_rate(n, min_time)}
        row["pettingzoo_ms_per_step"] = 1e3 * n / row["pettingzoo_agent_steps_per_s"]
        row["core_agent_steps_per_s"] = core_rate(n, copies, min_time)
        row["core_memory_mib"] = core_memory_mib(n, copies)
        row["dmpc_ms_per_agent"] = dmpc_ms_per_agent(n, decisions)
        rows.append(row)
        log(f"scaling N={n:>5}: PettingZoo {row['pettingzoo_agent_steps_per_s']:.3g} agent-steps/s "
            f"({row['pettingzoo_ms_per_step']:.2f} ms/step), core x{copies} "
            f"{row['core_agent_steps_per_s']:.3g}, DMPC {row['dmpc_ms_per_agent'] or float('nan'):.3f} ms/agent")
    ns = [r["n"] for r in rows]
    exps = {"pettingzoo": growth_exponent(ns, [1 / r["pettingzoo_agent_steps_per_s"] for r in rows]),
            "core": growth_exponent(ns, [1 / r["core_agent_steps_per_s"] for r in rows])}
    if all(r["dmpc_ms_per_agent"] for r in rows):
        exps["dmpc"] = growth_exponent(ns, [r["dmpc_ms_per_agent"] for r in rows])
    return {"env": "platoon_v0 swarm(N, 'ring', 'RING'), cw", "copies": copies, "rows": rows,
            "growth_exponent": exps}


def scaling_targets(result: dict) -> list[tuple[str, float, float, str]]:
    """``(name, value, goal, op)`` of issue 19's targets that the table covers."""
    rows = {r["n"]: r for r in result["rows"]}
    out = []
    lo, hi = min(rows), max(rows)
    out.append((f"(19) core agent-steps/s N={hi} / N={lo} (platoon, cw)",
                rows[hi]["core_agent_steps_per_s"] / rows[lo]["core_agent_steps_per_s"], 1 / 3, ">="))
    if 256 in rows:
        out.append(("(19) PettingZoo step at N=256 [ms]", rows[256]["pettingzoo_ms_per_step"], 5.0, "<="))
    if rows[lo]["dmpc_ms_per_agent"] and rows[hi]["dmpc_ms_per_agent"]:
        out.append((f"(19) DMPC per-agent decision N={hi} / N={lo}",
                    rows[hi]["dmpc_ms_per_agent"] / rows[lo]["dmpc_ms_per_agent"], 2.0, "<="))
    if 1024 in rows and result["copies"] == 64:
        out.append(("(19) memory of a 1024-follower core x 64 copies [MiB]", rows[1024]["core_memory_mib"],
                    1024.0, "<="))
    return out


def plot(result: dict, path: str) -> None:
    """Per-agent cost against N (log-log) of the three measurements."""
    import matplotlib.pyplot as plt

    rows = result["rows"]
    ns = [r["n"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    exps = result["growth_exponent"]
    ax.loglog(ns, [1e6 / r["pettingzoo_agent_steps_per_s"] for r in rows], "o-",
              label=f"PettingZoo step (N^{exps['pettingzoo']:.2f})")
    ax.loglog(ns, [1e6 / r["core_agent_steps_per_s"] for r in rows], "s-",
              label=f"batched core x{result['copies']} (N^{exps['core']:.2f})")
    if "dmpc" in exps:
        ax.loglog(ns, [1e3 * r["dmpc_ms_per_agent"] for r in rows], "^-", label=f"DMPC decision (N^{exps['dmpc']:.2f})")
    ax.set_xlabel("followers N")
    ax.set_ylabel("us per agent-step")
    ax.set_title(result["env"])
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
