"""``satenv imitate``: run, resume, validate and ship imitation (DAgger and its safe variants).

    satenv imitate --task platoon-pereira2022-random --rounds 8 --out-dir runs/platoon_dagger
    satenv imitate --env-id formation_v0 --expert cgmres --rounds 4 --out-dir runs/formation_dagger
    satenv imitate --system platoon-pereira2022 \\
        --warm-start satenv/training/policies/platoon_pereira2022_dagger_shield \\
        --fly filtered --label filtered --lr 1e-4 --epochs 4 --out-dir runs/p22_safe
    satenv imitate --config satenv/training/policies/<name>/config.json --out-dir runs/replay
    satenv imitate --out-dir runs/p22_safe --ship satenv/training/policies/<new name>

The same command resumes a run folder after its last finished round (its ``config.json``; flags
given again override it). ``--ship DEST`` copies the round chosen on validation (or
``--ship-round k``) to a new policy folder; ``--validate-round k`` scores round ``k`` (``-1``: the
warm start) on ``--validate-seeds`` validation seeds (``--shield-seeds`` of them behind the filter).
"""

from __future__ import annotations

import argparse
import os
import sys
import typing
from pathlib import Path

from satenv import tasks
from satenv.training.imitation.config import ImitationConfig, from_json, system_defaults

__all__ = ["build_parser", "main", "parse"]

PROG = "satenv imitate"
ALIASES = {"--run-dir": "--out-dir", "--val-seeds": "--eval-seeds", "--learning-rate": "--lr",
           "--val-shield-seeds": "--shield-seeds"}
"""Flags of earlier commands -> the flag they mean."""


class _Parser(argparse.ArgumentParser):
    """A parser whose errors are one ``ValueError`` line (``main`` prints it, no usage dump)."""

    def error(self, message: str) -> typing.NoReturn:
        raise ValueError(f"{message} (see {PROG} --help)")


def build_parser() -> argparse.ArgumentParser:
    """The run options and every :class:`ImitationConfig` field as a flag (:mod:`satenv.cliargs`)."""
    from satenv.cliargs import add_config_flags, int_at_least, plain

    p = _Parser(prog=PROG, description=plain(__doc__.split("\n\n")[0]), allow_abbrev=False,
                epilog=plain("\n\n".join(__doc__.split("\n\n")[1:])),
                formatter_class=argparse.RawDescriptionHelpFormatter)
    run = p.add_argument_group("run")
    run.add_argument("--config", type=Path, help="replay a saved config.json (any release's)")
    run.add_argument("--system", help="a satenv.tasks system: its training task and hyper-parameters")
    run.add_argument("--resume", action="store_true", help="require an existing run folder to continue")
    run.add_argument("--allow-code-env-id", action="store_true", help="admit a module:callable env id in --config")
    run.add_argument("--ship", type=Path, help="ship a round of the run to this new policy folder, then stop")
    run.add_argument("--ship-round", type=int, help="the round to ship (default: chosen on validation)")
    run.add_argument("--ship-filter", action="store_true", help="the shipped folder names the safety filter")
    run.add_argument("--validate-round", type=int, help="score this round (-1: the warm start), then stop")
    run.add_argument("--validate-seeds", type=int_at_least(1), default=100,
                     help="validation seeds of --validate-round")
    add_config_flags(p, ImitationConfig, title="config fields (ImitationConfig)")
    return p


def parse(argv: list[str] | None = None) -> tuple[argparse.Namespace, ImitationConfig | None, bool]:
    """``(options, config, resume)`` of a command line: the config is ``--config``'s, else the run
    folder's ``config.json`` (then ``resume``), else the task's system defaults, with the given
    flags on top; ``None`` for ``--ship``."""
    from satenv.cliargs import config_from_args

    args = [ALIASES.get(a.partition("=")[0], a.partition("=")[0]) + a.partition("=")[1] + a.partition("=")[2]
            for a in (sys.argv[1:] if argv is None else argv)]
    parser = build_parser()
    ns = parser.parse_args(args)
    if getattr(ns, "warm_start", None):   # given on this command line: checked before anything runs
        from satenv.training.imitation.setup import warm_start_folder

        try:
            warm_start_folder(ns.warm_start)
        except ValueError as err:
            raise type(err)(f"--warm-start: {err}") from None
    out = Path(getattr(ns, "out_dir", ImitationConfig.out_dir))
    if ns.ship is not None:
        return ns, None, True
    saved = out / "config.json"
    resume = ns.config is None and os.path.lexists(saved)
    if ns.resume and not resume:
        raise ValueError(f"--resume: {saved} is missing (a run folder's config.json)")
    if ns.system is not None and not hasattr(ns, "task"):
        from satenv.training.recipes import system_name

        ns.task = tasks.training_task(system_name(ns.system)).name
    if ns.config is not None:
        base = _saved(ns.config, ns.allow_code_env_id, f"--config {ns.config}")
    elif resume:
        base = _saved(saved, ns.allow_code_env_id, str(saved))
    else:
        base = _fresh_base(getattr(ns, "task", None), hasattr(ns, "env_id"))
    return ns, config_from_args(parser, ImitationConfig, ns, base), resume


def _saved(path: Path, allow_code: bool, source: str) -> ImitationConfig:
    """The config of a saved ``config.json`` (its names vetted before anything is built); an error
    names ``source`` (``--config PATH``, or the run folder's file)."""
    from satenv.training.imitation.config import upgrade
    from satenv.training.trust import check_replayed_config, read_json

    try:
        data = read_json(path.parent, path.name)
        if not isinstance(data, dict):
            raise ValueError(f"expected a JSON object of config fields, got {type(data).__name__}")
        check_replayed_config(upgrade(data), allow_code_env_id=allow_code, source=source)
        return from_json(data)
    except (ValueError, TypeError) as err:
        text = str(err).removeprefix(f"{path}: ").removeprefix(f"{os.path.abspath(path)}: ")
        raise (err if text.startswith(source) else type(err)(f"{source}: {text}")) from None


def _fresh_base(task_name: str | None, env_id_given: bool) -> ImitationConfig | None:
    """A new run's base: the task's system hyper-parameters (``None``, the field defaults, for an
    env id without a task and for a task of no system)."""
    from satenv.training.config import DEFAULT_TASK

    if task_name is None and env_id_given:
        return None
    task = tasks.get(task_name or DEFAULT_TASK)
    return ImitationConfig(task=task.name, **system_defaults(task.system)) if task.system else None


def main(argv: list[str] | None = None) -> int:
    """The command (module docstring); 0 on success, 2 with one line naming a bad input."""
    try:
        ns, cfg, resume = parse(argv)
    except (ValueError, TypeError) as err:   # a bad flag, or a saved config's value of the wrong kind
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2
    try:
        return _act(ns, cfg, resume)
    except ValueError as err:               # satenv's input errors, run-folder and untrusted-data errors
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2


def _act(ns: argparse.Namespace, cfg: ImitationConfig | None, resume: bool) -> int:
    from satenv.training.imitation import ship

    out = Path(getattr(ns, "out_dir", ImitationConfig.out_dir))
    if ns.ship is not None:
        k = ship.choose(ship.recorded(out)) if ns.ship_round is None else ns.ship_round
        print(f"shipped round {k} to {ship.ship(out, k, ns.ship, with_filter=ns.ship_filter)}")
        return 0
    if ns.validate_round is not None:
        from satenv.training.imitation.setup import warm_start_filter

        task = tasks.get(cfg.task) if cfg.task else None
        seeds = task.seeds("validation", ns.validate_seeds) if task else cfg.eval_seeds
        shielded = seeds[:cfg.shield_seeds] if cfg.shield_seeds else seeds
        filt = warm_start_filter(cfg.warm_start) if cfg.warm_start else None
        from satenv.training.envs import make_env

        env = make_env(cfg.env_id, **cfg.resolved_eval_env_kwargs)
        print(f"wrote {ship.validate_round(out, ns.validate_round, env, cfg.warm_start, seeds, shielded, filt)}")
        return 0
    from satenv.training.imitation.rounds import run

    episodes = (cfg.round0_episodes + max(0, cfg.rounds - 1) * cfg.episodes_per_round) if cfg.rounds else 0
    print(f"{'resuming' if resume else 'starting'} {PROG} in {out}: {cfg.rounds} rounds on {cfg.task or cfg.env_id} "
          f"(expert {cfg.expert or cfg.label}, fly {cfg.fly}): {episodes} labelled episodes in all, "
          f"{len(cfg.eval_seeds)} validation episodes a round"
          + (f", then final/ on {len(cfg.test_seeds)} test seeds" if cfg.final_eval else "")
          + "; the expert's solver sets the pace (minutes an episode for the NMPC and tube-RDMPC)", flush=True)
    run(cfg, out, resume=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
