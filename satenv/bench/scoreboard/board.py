"""``run_scoreboard``: select, preflight, resume, run, aggregate, write — one step per function."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator, Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from satenv.bench.scoreboard.backends import stream
from satenv.bench.scoreboard.headline import headline
from satenv.bench.scoreboard.plan import (
    PERTURBATION_SEP,
    Plan,
    Selection,
    board_seeds,
    make_plan,
    select,
    split_names,
)
from satenv.bench.scoreboard.registry import (
    POLICIES,
    QUICK,
    TASKS,
    discover_trained_policies,
    user_policies,
)
from satenv.bench.scoreboard.report import (
    RANKING,
    Board,
    aggregate,
    git_revision,
    machine,
    rank,
    render_markdown,
    satenv_version,
    summarize,
    write_outputs,
)
from satenv.bench.scoreboard.runner import EPISODES_FILE, EpisodeLog, Job, read_episodes
from satenv.bench.scoreboard.specs import PolicySpec, ScoreboardError, TaskSpec

__all__ = ["reaggregate", "run_scoreboard"]

Key = tuple[str, str, int]
Record = dict[str, Any]


def _check_options(workers: int, backend: str, resume: bool, overwrite: bool) -> None:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ScoreboardError(f"--workers must be a positive integer, got {workers!r}")
    if backend not in ("process", "ray"):
        raise ScoreboardError(f"--backend must be 'process' or 'ray', got {backend!r}")
    if resume and overwrite:
        raise ScoreboardError("--resume and --overwrite contradict each other: pick one")


def _registries(task_registry: Mapping[str, TaskSpec] | None,
                policy_registry: Mapping[str, PolicySpec] | None
                ) -> tuple[dict[str, TaskSpec], dict[str, PolicySpec]]:
    task_reg = dict(TASKS if task_registry is None else task_registry)
    pol_reg = dict(POLICIES if policy_registry is None else policy_registry)
    for reg in (task_reg, pol_reg):
        for key, spec in reg.items():
            if key != spec.name:
                raise ScoreboardError(f"registry entry {key!r} holds a spec named {spec.name!r}: "
                                      "the key must be the spec's name")
    if policy_registry is None:
        for name, spec in discover_trained_policies().items():
            pol_reg.setdefault(name, spec)
    return task_reg, pol_reg


def _user_specs(paths: list[str], pol_reg: Mapping[str, PolicySpec]) -> list[PolicySpec]:
    """The ``--policy`` folders' specs; a folder of a shipped policy is its ``trained:<name>``
    entry (so it is ranked once, not also as ``user:<name>``)."""
    shipped = {Path(spec.checkpoint).resolve(): spec for spec in pol_reg.values() if spec.checkpoint}
    same = [shipped[Path(p).resolve()] for p in paths if Path(p).resolve() in shipped]
    return user_policies([p for p in paths if Path(p).resolve() not in shipped], pol_reg) + same


def _selections(scenarios, policies, quick: bool, user: list[PolicySpec], task_reg, pol_reg,
                notes: list[str]) -> tuple[Selection, Selection]:
    """The selected tasks (``scenarios``: the ``--scenarios`` names or globs) and policies."""
    req_task, req_pol = split_names(scenarios), split_names(policies)
    if quick:
        req_task = req_task if req_task is not None else list(QUICK["scenarios"])
        req_pol = req_pol if req_pol is not None else list(QUICK["policies"])
    if req_pol is not None and user:
        req_pol = req_pol + [s.name for s in user if s.name not in req_pol]
    task = select(req_task, task_reg, "task", notes, strict=not quick or scenarios is not None)
    pol = select(req_pol, pol_reg, "policy", notes, strict=not quick or policies is not None)
    pol.explicit |= {spec.name for spec in user}
    for kind, sel in (("task", task), ("policy", pol)):
        if not sel.names:
            raise ScoreboardError(f"no {kind} to run: none of the selected {kind}s is available "
                                  f"({'; '.join(notes) or 'empty selection'})")
    return task, pol


def _check_log_free(log_path: Path, resume: bool, overwrite: bool) -> None:
    if log_path.exists() and not resume and not overwrite and log_path.stat().st_size > 0:
        raise ScoreboardError(f"{log_path} already holds episodes of an earlier run: pass --resume to "
                              "continue it, --overwrite to discard it, or choose another --out")


def _prepare_out(out: Path, overwrite: bool) -> None:
    if overwrite:
        (out / EPISODES_FILE).unlink(missing_ok=True)
        for f in (out / "trajectories").glob("*.npz"):
            f.unlink()
    out.mkdir(parents=True, exist_ok=True)


def _resumed(log_path: Path, plan: Plan, fps: dict[str, str]) -> dict[Key, Record]:
    """The planned episodes already in the log (whose definitions must match today's)."""
    planned, done = set(plan.keys), {}
    for rec in read_episodes(log_path, repair=True):
        key = (rec["scenario"], rec["policy"], rec["seed"])
        if key not in planned:
            continue
        for kind, field, fp in (("task", "scenario", "scenario_fp"), ("policy", "policy", "policy_fp")):
            if rec.get(fp) != fps[rec[field]]:
                raise ScoreboardError(f"{log_path} holds episodes of a different definition of {kind} "
                                      f"{rec[field]!r} (fingerprint {rec.get(fp)} != {fps[rec[field]]}): "
                                      "pass --overwrite or choose another --out")
        done[key] = rec
    return done


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def trajectory_path(out: Path, task: str, pol: str, seed: int) -> Path:
    return out / "trajectories" / f"{_safe(task)}__{_safe(pol)}__seed{seed}.npz"


def _jobs(plan: Plan, done: Mapping[Key, Record], task_reg, pol_reg, out: Path, plots: bool) -> list[Job]:
    return [Job(task_reg[s], pol_reg[p], seed,
                str(trajectory_path(out, s, p, seed)) if plots and plan.is_example((s, p, seed)) else None)
            for s, p, seed in plan.keys if (s, p, seed) not in done]


def _header(plan: Plan, task_reg, pol_reg, pol_names: list[str], notes: list[str], done: int,
            quick: bool, backend: str, workers: int, argv: list[str] | None) -> dict[str, Any]:
    return {
        "title": "satenv scoreboard" + (" (quick)" if quick else ""),
        "satenv_version": satenv_version(), "git": git_revision(),
        "generated": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": "python -m satenv.bench.scoreboard " + " ".join(argv if argv is not None else []),
        "machine": machine(), "backend": backend, "workers": workers, "seeds": plan.seeds,
        "scenario_seeds": plan.caps, "env_versions": sorted(set(plan.env_ids.values())),
        "scenarios": {n: {"env": env, "kwargs": dict(task_reg[n].kwargs),
                          "description": task_reg[n].description, **task_reg[n].success_rule()}
                      for n, env in plan.env_ids.items()},
        "policies": {n: {"description": pol_reg[n].description,
                         **({"checkpoint": pol_reg[n].checkpoint} if pol_reg[n].checkpoint else {})}
                     for n in pol_names},
        "episodes_planned": len(plan.keys), "episodes_resumed": done,
        "ranking": RANKING,
        "notes": notes,
    }


def _run(records: Iterator[Record], log_path: Path, done: dict[Key, Record], total: int, progress: bool,
         on_record: Callable[[Record], None] | None) -> None:
    """Append each record to the log as it arrives (with a progress bar)."""
    from tqdm import tqdm

    bar = tqdm(total=total, initial=len(done), desc="scoreboard", unit="ep", disable=not progress,
               file=sys.stderr, dynamic_ncols=True)
    log = EpisodeLog(log_path)
    try:
        for rec in records:
            log.append(rec)
            done[(rec["scenario"], rec["policy"], rec["seed"])] = rec
            bar.update(1)
            bar.set_postfix_str(f"{rec['scenario']} / {rec['policy']}", refresh=False)
            if on_record is not None:
                on_record(rec)
    finally:
        close = getattr(records, "close", None)
        if close is not None:
            close()
        log.close()
        bar.close()


def _finish(out: Path, header: dict[str, Any], records: list[Record], notes: list[str], plots: bool) -> Board:
    """Aggregate, rank and write ``records`` (in plan order: tasks in that order)."""
    agg = aggregate(records)
    agg = {s: agg[s] for s in dict.fromkeys(r["scenario"] for r in records)}
    board = Board(out, header, records, agg, {s: rank(agg[s]) for s in agg}, notes)
    board.summary = summarize(records, {s: header["scenarios"][s]["env"] for s in agg  # nominal tasks only
                                        if PERTURBATION_SEP not in s})
    board.headline = headline(records, board.ranking)
    board.markdown = render_markdown(board, plots=plots)
    write_outputs(board, plots=plots)
    return board


def _with_filter_counts(records: list[Record], tasks: Mapping[str, Any]) -> list[Record]:
    """``records`` (read through :func:`satenv.scoring.upgrade_record`) with the filter's decision
    counts of the one record where an older record has its ``safety_interventions`` but not them:
    ``safety_steps`` = ``steps`` (the filter decides once per step for every agent),
    ``safety_agent_steps`` = steps x agents (counted on the task's env: header kwargs) and
    ``interventions_per_agent_step`` their ratio."""
    import satenv

    agents: dict[str, int] = {}
    out = []
    for rec in records:
        if rec.get("safety_interventions") is not None and "safety_agent_steps" not in rec and rec.get("steps"):
            task = tasks[rec["scenario"]]
            if rec["scenario"] not in agents:
                agents[rec["scenario"]] = len(satenv.make(task["env"], **task["kwargs"]).possible_agents)
            agent_steps = int(rec["steps"]) * agents[rec["scenario"]]
            rec = {**rec, "safety_steps": int(rec["steps"]), "safety_agent_steps": agent_steps,
                   "interventions_per_agent_step": rec["safety_interventions"] / agent_steps}
        out.append(rec)
    return out


def reaggregate(out: str | Path, plots: bool = True) -> Board:
    """Re-write a finished board's outputs in ``out`` from its ``episodes.jsonl`` and the header of
    its ``scoreboard.json`` (running no episode, checking no fingerprint): e.g. after the report
    code changed. Episodes (the first line of each key, as ``--resume`` reads them) are ordered as
    the header lists scenarios and policies, then by seed; scenarios not in the header are left out."""
    out = Path(out)
    try:
        header = json.loads((out / "scoreboard.json").read_text())["header"]
    except (OSError, ValueError, KeyError) as exc:
        raise ScoreboardError(f"{out}/scoreboard.json: no board header to re-aggregate with ({exc}); "
                              "finish the run first (--resume)") from None
    names, pol = list(header["scenarios"]), list(header["policies"])

    def order(r: Record) -> tuple:
        return names.index(r["scenario"]), pol.index(r["policy"]) if r["policy"] in pol else len(pol), \
            r["policy"], r["seed"]

    records = sorted((r for r in read_episodes(out / EPISODES_FILE) if r["scenario"] in names), key=order)
    records = _with_filter_counts(records, header["scenarios"])
    header["ranking"] = RANKING       # re-ranked by the current rule
    return _finish(out, header, records, list(header.get("notes", [])), plots)


def run_scoreboard(out: str | Path = "results/scoreboard", *, scenarios: str | list[str] | None = None,
                   policies: str | list[str] | None = None, seeds: list[int] | str | None = None,
                   checkpoints: list[str] = (), quick: bool = False,
                   scenario_seeds: dict[str, list[int]] | None = None, workers: int = 1,
                   backend: str = "process", ray_address: str | None = None, resume: bool = False,
                   overwrite: bool = False, plots: bool = True, progress: bool = True,
                   task_registry: Mapping[str, TaskSpec] | None = None,
                   policy_registry: Mapping[str, PolicySpec] | None = None,
                   on_record: Callable[[Record], None] | None = None,
                   on_plan: Callable[[Plan, Mapping[Key, Record]], None] | None = None,
                   argv: list[str] | None = None) -> Board:
    """Run the board and write its files (see :mod:`satenv.bench.scoreboard`); returns the :class:`Board`.

    ``seeds`` default to the board's (``FULL`` or ``QUICK``); ``scenario_seeds`` caps the seeds of
    expensive scenarios (``{name: seeds}``, intersected with ``seeds``), by default the board's
    caps unless ``seeds`` were given; ``task_registry`` / ``policy_registry`` replace the
    registry's dicts (tests, plugins); ``on_plan(plan, done)`` is called once the plan is made
    (``done``: the records already in the log), before any episode runs; ``on_record`` is called
    after each record is written.
    ``scenarios`` and ``scenario_seeds`` name tasks (the command line's ``--scenarios``).
    """
    _check_options(workers, backend, resume, overwrite)
    seed_list, caps = board_seeds(seeds, quick, scenario_seeds)
    task_reg, pol_reg = _registries(task_registry, policy_registry)
    user = _user_specs(list(checkpoints), pol_reg)
    pol_reg.update({spec.name: spec for spec in user})
    notes: list[str] = []
    task_sel, pol_sel = _selections(scenarios, policies, quick, user, task_reg, pol_reg, notes)
    out = Path(out)
    _check_log_free(out / EPISODES_FILE, resume, overwrite)
    plan = make_plan(task_reg, pol_reg, task_sel, pol_sel, seed_list, caps, notes)
    _prepare_out(out, overwrite)
    fps = {n: task_reg[n].fingerprint() for n in task_sel.names} | {n: pol_reg[n].fingerprint()
                                                                   for n in pol_sel.names}
    done = _resumed(out / EPISODES_FILE, plan, fps)
    jobs = _jobs(plan, done, task_reg, pol_reg, out, plots)
    header = _header(plan, task_reg, pol_reg, pol_sel.names, notes, len(done), quick, backend, workers, argv)
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    if on_plan is not None:
        on_plan(plan, done)
    _run(stream(jobs, backend, workers, ray_address), out / EPISODES_FILE, done, len(plan.keys),
         progress, on_record)
    records = [done[k] for k in plan.keys if k in done]       # plan order: registry order, then seed
    return _finish(out, header, records, notes, plots)
