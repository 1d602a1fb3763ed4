"""``satenv imitate``: run, resume, validate and ship imitation (DAgger and its safe variants).

    satenv imitate --task platoon-pereira2022-random --rounds 8 --out-dir runs/platoon_dagger
    satenv imitate --env-id formation_v0 --expert cgmres --rounds 4 --out-dir runs/formation_dagger
    satenv imitate --system platoon-pereira2022 --warm-start satenv/training/policies/platoon_pereira2022_dagger_shield \\
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
import dataclasses
import json
import sys
import typing
from pathlib import Path
from typing import Any

from satenv import tasks
from satenv.training.config import config_from_json
from satenv.training.imitation.config import ImitationConfig, from_json, system_defaults

__all__ = ["build_parser", "main", "parse"]

PROG = "satenv imitate"
ALIASES = {"--run-dir": "--out-dir", "--val-seeds": "--eval-seeds", "--learning-rate": "--lr",
           "--val-shield-seeds": "--shield-seeds"}
"""Flags of earlier commands -> the flag they mean."""
SEED_FIELDS = ("eval_seeds", "test_seeds")


def _value(name: str, hint: Any) -> Any:
    """The argparse ``type`` of a config field: a parser raising ``ArgumentTypeError`` with the
    field, the value and what is expected."""
    bare = typing.get_args(hint)[0] if typing.get_origin(hint) is typing.Annotated else hint
    origin, args = typing.get_origin(bare), typing.get_args(bare)

    def parse(text: str) -> Any:
        try:
            return convert(text)
        except (ValueError, TypeError) as err:
            raise argparse.ArgumentTypeError(f"{err}") from None

    def convert(text: str) -> Any:
        if name in SEED_FIELDS:
            return tasks.parse_seeds(text)
        if bare is bool:
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError(f"expected true or false, got {text!r:.40}")
            return text.lower() in ("true", "1", "yes")
        if bare is int:
            return _int(text)
        if bare is float:
            try:
                return float(text)
            except ValueError:
                raise ValueError(f"expected a number, got {text!r:.40}") from None
        if origin is tuple:
            items = [t for t in text.replace(",", " ").split() if t]
            if args and args[0] is int:
                return tuple(_int(t) for t in items)
            return tuple(items)
        if origin is dict or bare is dict:
            try:
                value = json.loads(text)
            except json.JSONDecodeError as err:
                raise ValueError(f"expected a JSON object, got {text!r:.60} ({err.msg})") from None
            if not isinstance(value, dict):
                raise ValueError(f"expected a JSON object, got {text!r:.60}")
            return value
        return None if text.lower() in ("none", "null") and type(None) in args else text

    parse.__name__ = "a " + (getattr(bare, "__name__", None) or "value")
    return parse


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"expected an integer, got {text!r:.40}") from None


class _Parser(argparse.ArgumentParser):
    """A parser whose errors are one ``ValueError`` line (``main`` prints it, no usage dump)."""

    def error(self, message: str) -> typing.NoReturn:
        raise ValueError(f"{message} (see {PROG} --help)")


def build_parser() -> argparse.ArgumentParser:
    """Every :class:`ImitationConfig` field as ``--field-name`` (given flags only), and the run options."""
    p = _Parser(prog=PROG, description=__doc__.split("\n\n")[0], allow_abbrev=False,
                                epilog="\n\n".join(__doc__.split("\n\n")[1:]),
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
    run.add_argument("--validate-seeds", type=int, default=100, help="validation seeds of --validate-round")
    hints = typing.get_type_hints(ImitationConfig, include_extras=True)
    fields = p.add_argument_group("config fields (ImitationConfig)")
    for f in dataclasses.fields(ImitationConfig):
        choices = typing.get_args(hints[f.name]) if typing.get_origin(hints[f.name]) is typing.Literal else None
        fields.add_argument("--" + f.name.replace("_", "-"), dest=f.name, default=argparse.SUPPRESS,
                            type=_value(f.name, hints[f.name]) if choices is None else str, choices=choices,
                            metavar=f.name.upper(), help=_help(f))
    return p


def _help(f: dataclasses.Field) -> str:
    default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
    return f"(default: {default!r})".replace("%", "%%")


def parse(argv: list[str] | None = None) -> tuple[argparse.Namespace, ImitationConfig | None, bool]:
    """``(options, config, resume)`` of a command line: the config is ``--config``'s, else the run
    folder's ``config.json`` (then ``resume``), else the task's system defaults, with the given
    flags on top; ``None`` for ``--ship``."""
    args = [ALIASES.get(a.partition("=")[0], a.partition("=")[0]) + a.partition("=")[1] + a.partition("=")[2]
            for a in (sys.argv[1:] if argv is None else argv)]
    ns = build_parser().parse_args(args)
    given = {f.name: getattr(ns, f.name) for f in dataclasses.fields(ImitationConfig) if hasattr(ns, f.name)}
    out = Path(given.get("out_dir", ImitationConfig.out_dir))
    if ns.ship is not None:
        return ns, None, True
    saved = out / "config.json"
    resume = ns.config is None and saved.is_file()
    if ns.resume and not resume:
        raise ValueError(f"--resume: {saved} is missing (a run folder's config.json)")
    if ns.system is not None:
        from satenv.training.recipes import system_name

        given.setdefault("task", tasks.training_task(system_name(ns.system)).name)
    if ns.config is not None or resume:
        base = _saved(ns.config if ns.config is not None else saved, ns.allow_code_env_id).to_json()
    else:
        base = _fresh_base(given)
    return ns, config_from_json({**base, **given}, ImitationConfig), resume


def _saved(path: Path, allow_code: bool) -> ImitationConfig:
    """The config of a saved ``config.json`` (its names vetted before anything is built)."""
    from satenv.training.imitation.config import upgrade
    from satenv.training.trust import check_replayed_config, read_json

    data = read_json(path.parent, path.name)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object of config fields, got {type(data).__name__}")
    check_replayed_config(upgrade(data), allow_code_env_id=allow_code, source=str(path))
    return from_json(data)


def _fresh_base(given: dict[str, Any]) -> dict[str, Any]:
    """A new run's base: the system's hyper-parameters of the task (none for an env id without
    a task, or a task of no system)."""
    from satenv.training.config import DEFAULT_TASK

    if given.get("task") is None and "env_id" in given:
        return {}
    task = tasks.get(given.get("task") or DEFAULT_TASK)
    return {"task": task.name, **system_defaults(task.system)} if task.system else {}


def main(argv: list[str] | None = None) -> int:
    """The command (module docstring); 0 on success, 2 with one line naming a bad input."""
    try:
        ns, cfg, resume = parse(argv)
        return _act(ns, cfg, resume)
    except ValueError as err:               # satenv's input errors, run-folder and untrusted-data errors
        print(f"{PROG}: error: {err}", file=sys.stderr)
        return 2


def _act(ns: argparse.Namespace, cfg: ImitationConfig | None, resume: bool) -> int:
    from satenv.training.imitation import ship

    out = Path(vars(ns).get("out_dir", ImitationConfig.out_dir))
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

    print(f"{'resuming' if resume else 'starting'} {PROG} in {out}: {cfg.rounds} rounds on "
          f"{cfg.task or cfg.env_id} (expert {cfg.expert or cfg.label}, fly {cfg.fly})", flush=True)
    run(cfg, out, resume=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
