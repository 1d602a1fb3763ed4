"""Ratios of the collected figures and the issues' targets with ``met`` flags."""

from __future__ import annotations

from typing import Any

from .scaling import scaling_targets

API_VS_MPE2 = 10.0
"""The PettingZoo API at least 10x mpe2 ``simple_spread`` per agent-step."""
CORE_VS_VMAS = 20.0
"""The batched ``platoon_v0`` core (cw) at least 20x VMAS ``navigation`` at every batch
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
        for name, value, goal, op in scaling_targets(result["scaling"]):
            targets.append({"name": name, "value": value, "target": goal, "op": op,
                            "met": bool(value >= goal if op == ">=" else value <= goal)})
    for section in result.values():   # sections that list their own targets (e.g. ``envs``)
        if isinstance(section, dict) and isinstance(section.get("targets"), list):
            targets.extend(section["targets"])
    return ratios, targets
