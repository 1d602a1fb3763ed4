"""The ``scaling`` section of ``satenv.bench.perf``: per-agent cost of swarms of N spacecraft.

For N in :data:`SIZES` on two swarm families (cw truth):

* ``platoon`` — ``platoon_v0`` :func:`satenv.scenarios.platoon.swarm` (ring formation over the
  RING graph), distributed baseline DMPC;
* ``cluster`` — ``cluster_v0`` :func:`satenv.scenarios.cluster.swarm` (N satellites, N slots,
  Hungarian allocation), distributed baselines APF and, up to :data:`TUBE_MAX` satellites,
  tube-RDMPC (seconds per decision of the swarm beyond that),

it times

* ``pettingzoo``  agent-steps/s of the dict API (zero actions, one env);
* ``core``        agent-steps/s of the batched core (``step`` + ``observe``, ``COPIES`` copies;
  the cluster core with ``allocation="fixed"``: the Hungarian allocation runs only at reset and
  is timed apart, ``allocation_ms``);
* ``<baseline>_ms_per_agent``  median wall time of ``policy.act`` per agent over the first
  decisions of an episode;
* ``memory_mib``  the peak of Python/numpy allocations (``tracemalloc``) while building,
  resetting and stepping the ``COPIES``-copy core,

and fits the growth exponent ``c`` of ``cost per agent ~ N^c`` (0: flat) by least squares on
log-log. :func:`scaling_targets` lists the swarm targets; :func:`plot` draws the table.
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._common import _rate, act_times

SIZES = (4, 16, 64, 256, 1024)
COPIES = 64
TUBE_MAX = 16
"""Largest swarm on which tube-RDMPC is timed (about 2 s per decision at 16 satellites)."""


@dataclass(frozen=True)
class Family:
    """One swarm family: its env, keyword builder and distributed baselines."""

    env_id: str
    label: str
    baselines: tuple[str, ...]

    def kwargs(self, n: int, **overrides: Any) -> dict[str, Any]:
        if self.env_id == "platoon_v0":
            from satenv.scenarios.platoon import swarm

            return swarm(n, "ring", "RING" if n >= 3 else "PLF", **overrides)
        from satenv.scenarios.cluster import swarm

        return swarm(n, dynamics="cw", **overrides)

    def core(self, n: int, copies: int):
        """A ``copies``-copy core reset to the swarm's nominal start."""
        import satenv

        env = satenv.make(self.env_id, **self.kwargs(n, randomize=False, **self._core_overrides()))
        core = type(env.core)(env.scenario, batch=copies)
        core.reset(np.tile(env.scenario.initial_array(), (copies, 1, 1)))
        return core

    def _core_overrides(self) -> dict[str, Any]:
        return {"allocation": "fixed"} if self.env_id == "cluster_v0" else {}


FAMILIES = {"platoon": Family("platoon_v0", "platoon_v0 swarm(N, 'ring', 'RING'), cw", ("dmpc",)),
            "cluster": Family("cluster_v0", "cluster_v0 swarm(N), cw", ("apf", "tube_rdmpc"))}


def pettingzoo_rate(family: Family, n: int, min_time: float) -> float:
    import satenv

    env = satenv.make(family.env_id, **family.kwargs(n))
    env.reset(seed=0)
    zero = np.zeros(3)

    def step() -> None:
        if not env.agents:
            env.reset()
        env.step({a: zero for a in env.agents})

    return _rate(step, n, min_time)


def core_rate(family: Family, n: int, copies: int, min_time: float, repeats: int = 3) -> float:
    """Agent-steps/s of the batched core (``step`` + ``observe``)."""
    core = family.core(n, copies)
    accel = np.random.default_rng(0).uniform(-0.01, 0.01, (copies, n, 3))

    def step() -> None:
        core.step(accel)
        core.observe()

    return _rate(step, copies * n, min_time, repeats)


def core_memory_mib(family: Family, n: int, copies: int) -> float:
    """Peak allocations [MiB] of building, resetting and stepping the ``copies``-copy core."""
    tracemalloc.start()
    try:
        core_rate(family, n, copies, 0.0, repeats=0)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def allocation_ms(n: int) -> float:
    """Wall time [ms] of the Hungarian allocation of a cluster swarm's ``n`` satellites."""
    from satenv.allocation import hungarian_assignment
    from satenv.scenarios.cluster import resolve_scenario

    sc = resolve_scenario(**{k: v for k, v in FAMILIES["cluster"].kwargs(n).items() if k != "preset"})
    t0 = time.perf_counter()
    hungarian_assignment(sc.initial_array()[:, :3], sc.targets_array())
    return 1e3 * (time.perf_counter() - t0)


def decision_ms_per_agent(family: Family, baseline: str, n: int, decisions: int) -> float | None:
    """Median ``policy.act`` time per agent [ms] over the first decisions of one episode
    (``None`` when the baseline's extra is not installed)."""
    import satenv

    try:
        from satenv import baselines
        env = satenv.make(family.env_id, **family.kwargs(n))
        policy = baselines.make(baseline, env)
    except ImportError:
        return None
    return 1e3 * float(np.median(act_times(env, policy, decisions))) / n


def growth_exponent(sizes: list[int], per_agent_cost: list[float]) -> float:
    """``c`` of ``per_agent_cost ~ N^c`` (least squares on log-log)."""
    return float(np.polyfit(np.log(sizes), np.log(per_agent_cost), 1)[0])


def _row(family: Family, n: int, copies: int, min_time: float, decisions: int, tube_max: int) -> dict:
    row: dict[str, Any] = {"n": n, "pettingzoo_agent_steps_per_s": pettingzoo_rate(family, n, min_time)}
    row["pettingzoo_ms_per_step"] = 1e3 * n / row["pettingzoo_agent_steps_per_s"]
    row["core_agent_steps_per_s"] = core_rate(family, n, copies, min_time)
    row["core_memory_mib"] = core_memory_mib(family, n, copies)
    if family.env_id == "cluster_v0":
        row["allocation_ms"] = allocation_ms(n)
    for name in family.baselines:
        if name != "tube_rdmpc" or n <= tube_max:
            row[f"{name}_ms_per_agent"] = decision_ms_per_agent(family, name, n, decisions)
    return row


def _exponents(family: Family, rows: list[dict]) -> dict[str, float]:
    ns = [r["n"] for r in rows]
    exps = {"pettingzoo": growth_exponent(ns, [1 / r["pettingzoo_agent_steps_per_s"] for r in rows]),
            "core": growth_exponent(ns, [1 / r["core_agent_steps_per_s"] for r in rows])}
    for name in family.baselines:
        pts = [(r["n"], r[f"{name}_ms_per_agent"]) for r in rows if r.get(f"{name}_ms_per_agent")]
        if len(pts) >= 2:
            exps[name] = growth_exponent(*zip(*pts, strict=True))
    return exps


def scaling(sizes: tuple[int, ...] = SIZES, copies: int = COPIES, min_time: float = 0.2,
            decisions: int = 5, tube_max: int = TUBE_MAX, families: tuple[str, ...] = tuple(FAMILIES),
            log: Callable[[str], None] = print) -> dict:
    """The scaling table of each family (module docstring) with growth exponents."""
    out: dict[str, Any] = {"copies": copies}
    for key in families:
        family = FAMILIES[key]
        rows = []
        for n in sizes:
            rows.append(row := _row(family, n, copies, min_time, decisions, tube_max))
            times = ", ".join(f"{b} {row[f'{b}_ms_per_agent'] or float('nan'):.3g}" for b in family.baselines
                              if f"{b}_ms_per_agent" in row)
            log(f"scaling {key} N={n:>5}: PettingZoo {row['pettingzoo_agent_steps_per_s']:.3g} agent-steps/s "
                f"({row['pettingzoo_ms_per_step']:.2f} ms/step), core x{copies} "
                f"{row['core_agent_steps_per_s']:.3g}; ms per agent-decision: {times}")
        out[key] = {"env": family.label, "rows": rows, "growth_exponent": _exponents(family, rows)}
    return out


def scaling_targets(result: dict) -> list[tuple[str, float, float, str]]:
    """``(name, value, goal, op)`` of the swarm targets that the table covers."""
    out = []
    for key in ("platoon", "cluster"):
        if key not in result:
            continue
        rows = {r["n"]: r for r in result[key]["rows"]}
        lo, hi = min(rows), max(rows)
        out.append((f"(19) core agent-steps/s N={hi} / N={lo} ({key}, cw)",
                    rows[hi]["core_agent_steps_per_s"] / rows[lo]["core_agent_steps_per_s"], 1 / 3, ">="))
        if key != "platoon":
            continue
        if 256 in rows:
            out.append(("(19) PettingZoo step at N=256 [ms] (platoon)", rows[256]["pettingzoo_ms_per_step"], 5.0, "<="))
        if rows[lo].get("dmpc_ms_per_agent") and rows[hi].get("dmpc_ms_per_agent"):
            out.append((f"(19) DMPC per-agent decision N={hi} / N={lo}",
                        rows[hi]["dmpc_ms_per_agent"] / rows[lo]["dmpc_ms_per_agent"], 2.0, "<="))
        if 1024 in rows and result["copies"] == 64:
            out.append(("(19) memory of a 1024-follower core x 64 copies [MiB]", rows[1024]["core_memory_mib"],
                        1024.0, "<="))
    return out


_CURVES = (("pettingzoo", "o-", "PettingZoo step"), ("core", "s-", "batched core"),
           ("dmpc", "^-", "DMPC decision"), ("apf", "v-", "APF decision"), ("tube_rdmpc", "d-", "tube-RDMPC decision"))


def _per_agent_us(row: dict, key: str) -> float | None:
    if key in ("pettingzoo", "core"):
        return 1e6 / row[f"{key}_agent_steps_per_s"]
    ms = row.get(f"{key}_ms_per_agent")
    return None if ms is None else 1e3 * ms


def plot(result: dict, path: str) -> None:
    """Per-agent cost against N (log-log), one panel per family."""
    from satenv.render import new_figure

    keys = [k for k in FAMILIES if k in result]
    fig = new_figure(figsize=(6 * len(keys), 4))
    axes = fig.subplots(1, len(keys), squeeze=False)
    for ax, key in zip(axes[0], keys, strict=True):
        part = result[key]
        for curve, style, label in _CURVES:
            pts = [(r["n"], v) for r in part["rows"] if (v := _per_agent_us(r, curve)) is not None]
            if pts:
                exp = part["growth_exponent"].get(curve)
                ax.loglog(*zip(*pts, strict=True), style,
                          label=label + (f" x{result['copies']}" if curve == "core" else "")
                          + ("" if exp is None else f" (N^{exp:.2f})"))
        ax.set_xlabel("agents N")
        ax.set_ylabel("us per agent-step / agent-decision")
        ax.set_title(part["env"], fontsize=9)
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
