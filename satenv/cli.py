"""The ``satenv`` command: one entry point, one sub-command per job.

    satenv --help                 # the sub-commands, one line each
    satenv <command> --help       # a sub-command's options
    satenv board --quick          # e.g. the small scoreboard

Each sub-command is a ``main(argv)`` of the module that owns it (:data:`COMMANDS`), imported only
when it runs: ``satenv --help`` is fast and works without the optional extras.
"""

from __future__ import annotations

import importlib.util
import sys
from typing import NamedTuple

__all__ = ["COMMANDS", "Command", "main", "resolve"]


class Command(NamedTuple):
    """A sub-command: its ``"module:function"`` entry point, one line for ``satenv --help``, and the
    extra it needs, if any."""

    target: str
    summary: str
    extra: str = ""


COMMANDS: dict[str, Command] = {
    "train": Command("satenv.training.train:main", "train a shared policy with stable-baselines3 (PPO, SAC)",
                     "train"),
    "train-marl": Command("satenv.training.benchmarl_train:main",
                          "train with BenchMARL (MAPPO, IPPO, MASAC, ISAC, MADDPG, IDDPG)", "marl"),
    "train-rllib": Command("satenv.training.rllib_train:main", "train with Ray RLlib (multi-agent PPO)", "rllib"),
    "ppo": Command("satenv.training.rl.ppo:main", "train with the lean batched PPO (ppo, ippo, mappo)", "train"),
    "ppo-tune": Command("satenv.training.rl.tune:main",
                        "tune the lean PPO on a task: candidates chosen on validation seeds", "train"),
    "imitate": Command("satenv.training.imitation.cli:main",
                       "imitate an expert controller (DAgger and its safe variants), resume, validate, ship",
                       "train"),
    "heldout": Command("satenv.training.recipes.heldout:main",
                       "score a policy folder on a system's held-out test seeds", "train"),
    "team-sizes": Command("satenv.training.team_sizes:main",
                          "one set-encoder policy on teams of other sizes than it was trained on", "train"),
    "card": Command("satenv.training.card:main", "the shipped policies' cards: numbers both ways, targets"),
    "board": Command("satenv.bench.scoreboard.cli:main", "the scoreboard: rank every policy on every task"),
    "reproduce": Command("satenv.bench.reproduce:main", "reproduce a paper's table and claims", "mpc"),
    "results": Command("satenv.bench.learning.cli:main",
                       "the reference-results grid: run it, write results.json, render the page", "train"),
    "datasets": Command("satenv.bench.learning.datasets:main",
                        "write or read the Minari demonstration datasets", "datasets"),
    "safety-alone": Command("satenv.bench.safety_alone:main",
                            "learned policies alone and behind the safety filter, on test seeds", "train"),
    "perf": Command("satenv.bench.perf:main", "time the batched core, the envs, the solvers, the learners"),
}
"""Sub-command -> where it lives (``satenv --help`` lists them in this order)."""


class Unavailable(Exception):
    """A sub-command whose module is not installed here."""


def resolve(name: str):
    """The ``main`` of sub-command ``name`` (:func:`satenv.baselines.registry.resolve`, imported here
    so that ``satenv --help`` stays light); a module not installed is :class:`Unavailable`, an
    import error inside an installed one is raised as it is."""
    from satenv.baselines.registry import resolve as resolve_target

    target = COMMANDS[name].target
    module = target.partition(":")[0]
    if not _exists(module):
        raise Unavailable(f"'satenv {name}' is not available in this installation ({module} is not installed)")
    return resolve_target(target)


def _exists(module: str) -> bool:
    parent = module.rpartition(".")[0]
    if parent and not _exists(parent):
        return False
    return importlib.util.find_spec(module) is not None


def _usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: satenv <command> [options]", "", "commands:"]
    lines += [f"  {name:<{width}}  {c.summary}" + (f" [extra: {c.extra}]" if c.extra else "")
              for name, c in COMMANDS.items()]
    lines += ["", "satenv <command> --help shows a command's options; an extra is installed with",
              "pip install -c constraints.txt -e \".[EXTRA]\". Documentation: docs/cli.md."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run ``satenv <command> [options]``; the sub-command's exit status."""
    args = sys.argv[1:] if argv is None else list(argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(_usage())
        return 0 if args else 2
    if args[0] in ("-V", "--version"):
        from satenv import __version__

        print(f"satenv {__version__}")
        return 0
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        import difflib

        near = difflib.get_close_matches(name, COMMANDS, n=1)
        print(f"satenv: error: unknown command {name!r}" + (f" (did you mean {near[0]!r}?)" if near else "")
              + f"; expected one of {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    try:
        func = resolve(name)
    except Unavailable as why:
        print(f"satenv: error: {why}", file=sys.stderr)
        return 2
    program, sys.argv[0] = sys.argv[0], f"satenv {name}"   # the prog of a parser that does not name one
    try:
        status = func(rest)
    finally:
        sys.argv[0] = program
    return status if isinstance(status, int) else 0


if __name__ == "__main__":
    sys.exit(main())
