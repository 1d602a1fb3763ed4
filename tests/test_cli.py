"""The ``satenv`` command and its one grammar (``satenv.cliargs``): sub-commands, help that reads
well, config dataclasses as flags and back, and a bad input as one ``error:`` line (exit status 2)
naming the flag, the value and what is expected, with nothing written."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import pytest

from satenv import cli, cliargs

ROOT = Path(__file__).resolve().parents[1]
RAW_REST = re.compile(r"``|:(func|mod|class|data|meth|attr):`")


def _satenv(*args: str, pre: str = "") -> subprocess.CompletedProcess:
    """``python -m satenv ARGS`` in a fresh process (``pre``: Python run first, e.g. to hide a module)."""
    code = f"{pre}\nimport sys\nfrom satenv.cli import main\nsys.exit(main({list(args)!r}))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)


def _error(capsys, main, argv) -> str:
    """The one ``error:`` line of a rejected command line (exit status 2)."""
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "Traceback" not in err, err
    (line,) = [x for x in err.splitlines() if "error:" in x]
    return line


# --- the dispatcher -------------------------------------------------------------------------------

def test_help_lists_every_command_in_one_line_and_imports_no_extra():
    run = _satenv("--help", pre="")
    assert run.returncode == 0
    listed = re.findall(r"^  ([a-z-]+)  ", run.stdout, flags=re.M)
    assert listed == list(cli.COMMANDS)
    probe = subprocess.run([sys.executable, "-c", "import sys; from satenv.cli import main; main(['--help']); "
                            "print(sorted(m for m in ('torch', 'casadi', 'ray', 'benchmarl', 'stable_baselines3', "
                            "'satenv.baselines.registry') "
                            "if m in sys.modules))"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert probe.stdout.strip().endswith("[]"), probe.stdout      # the commands are imported when they run


def test_every_command_resolves_to_a_main():
    for name in cli.COMMANDS:
        assert callable(cli.resolve(name)), name


def test_an_unknown_or_missing_command_is_one_error_line(monkeypatch, capsys):
    assert cli.main(["bord"]) == 2
    assert "unknown command 'bord' (did you mean 'board'?)" in capsys.readouterr().err
    assert cli.main([]) == 2
    monkeypatch.setitem(cli.COMMANDS, "ghost", cli.Command("satenv.no_such.module:main", "x"))
    assert cli.main(["ghost", "--help"]) == 2
    assert "'satenv ghost' is not available" in capsys.readouterr().err


def test_a_command_resolves_through_the_registry_resolver(monkeypatch):
    """One resolver of ``"module:attribute"`` strings: an installed module without the function is
    the registry's ``ResolveError``, not a raw ``AttributeError``."""
    from satenv.baselines.registry import ResolveError

    monkeypatch.setitem(cli.COMMANDS, "hollow", cli.Command("satenv.training.train:no_such_main", "x"))
    with pytest.raises(ResolveError, match="no attribute 'no_such_main'"):
        cli.resolve("hollow")


@pytest.mark.parametrize("name", cli.COMMANDS)
def test_every_command_has_a_help_without_raw_rest(name, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.resolve(name)(["--help"])
    out = capsys.readouterr().out
    assert exit_.value.code == 0 and "usage:" in out and "--help" in out
    assert not RAW_REST.search(out), RAW_REST.search(out).group(0)


def test_python_dash_m_satenv_is_the_command():
    run = subprocess.run([sys.executable, "-m", "satenv", "card", "--help"], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert run.returncode == 0 and run.stdout.startswith("usage: satenv card")


# --- bad input: one error line, exit 2, nothing written ------------------------------------------------

def test_train_budget_zero_names_the_flag(capsys, tmp_path):
    from satenv.training.train import main

    line = _error(capsys, main, ["--budget", "0", "--out-dir", str(tmp_path / "run")])
    assert "error: --budget must be an int >= 1, got 0" in line and "total_timesteps" not in line
    assert "unrecognized arguments: --bud 5" in _error(capsys, main, ["--bud", "5"])    # no abbreviations
    assert not (tmp_path / "run").exists()


def test_board_rejects_an_empty_out_dir_and_an_abbreviated_flag(capsys, tmp_path, monkeypatch):
    from satenv.bench.scoreboard.cli import main

    monkeypatch.chdir(tmp_path)
    assert "argument --out-dir/--out: expected a folder path, got ''" in _error(capsys, main, ["--out-dir", ""])
    (tmp_path / "f").write_text("x")
    assert "'f' exists and is not a folder" in _error(capsys, main, ["--out-dir", "f"])
    assert "unrecognized arguments: --scenario" in _error(capsys, main, ["--scenario", "platoon-PLF-cw"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_board_list_without_the_mpc_extra():
    hide = "import sys; sys.modules.update(casadi=None, daqp=None, osqp=None)"
    run = _satenv("board", "--list", pre=hide)
    assert run.returncode == 0 and "Traceback" not in run.stderr, run.stderr
    assert "not available (optional dependency" in run.stdout and "dmpc" in run.stdout


def test_the_board_plan_line_states_size_time_and_swarms():
    from satenv.bench.scoreboard.cli import plan_line

    keys = [("platoon-PLF-cw", "zero", s) for s in (1, 2)] + [("cluster-swarm40", "dmpc", 1)]
    rate = {("platoon-PLF-cw", "zero"): 30.0, ("cluster-swarm40", "apf"): 600.0}
    line = plan_line(keys, {keys[0]: {}}, 2, rate)
    assert line.startswith("planning 3 episodes on 2 tasks x 2 policies (1 already in the log)")
    assert "about 5 min on 2 worker(s)" in line           # (30 + 600) s / 2 workers, the swarm's pair by its task
    assert "cluster-swarm40 take minutes per episode" in line
    assert "planning 1 episodes" in plan_line(keys[:1], {}, 1, {}) and "about" not in plan_line(keys[:1], {}, 1, {})


def test_a_default_policy_run_leaves_the_swarms_out_as_a_default_selection():
    from satenv.bench.scoreboard.cli import SWARM_MARK, without_swarms
    from satenv.bench.scoreboard.plan import select
    from satenv.bench.scoreboard.registry import TASKS

    sel = select(without_swarms().split(","), TASKS, "task", [], strict=True)
    assert sel.names == [n for n in TASKS if SWARM_MARK not in n] and len(sel.names) < len(TASKS)
    assert not sel.explicit                 # unavailable or unfitting tasks are skipped, not errors


@pytest.mark.parametrize("systems", [",", "nope", "platoon-pereira2023,nope"])
def test_datasets_systems_must_name_systems(systems, capsys, tmp_path):
    from satenv.bench.learning.datasets import main

    line = _error(capsys, main, ["write", "--systems", systems, "--root", str(tmp_path / "m"),
                                 "--manifest", str(tmp_path / "manifest.json")])
    assert "argument --systems: expected 'all' or comma-separated systems among" in line and repr(systems) in line
    assert list(tmp_path.iterdir()) == []


def test_results_run_log_must_be_a_file(capsys, tmp_path):
    from satenv.bench.learning.cli import main

    line = _error(capsys, main, ["run", "--log", str(tmp_path), "--dry-run"])
    assert "argument --log:" in line and "is a folder; expected a file path" in line


def test_reproduce_lists_each_papers_own_flags(capsys):
    from satenv.bench import reproduce

    with pytest.raises(SystemExit):
        reproduce.main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    for flag in ("--case", "--variant", "--with", "--no-ablation", "--steps", "--no-diagnostics", "--no-analysis"):
        assert flag in out
    line = _error(capsys, reproduce.main, ["pereira2023", "--case", "1"])      # li2022's flag, not this paper's
    assert "unrecognized arguments: --case 1" in line
    assert "invalid choice: 'smith1999'" in _error(capsys, reproduce.main, ["smith1999"])


def test_card_help_and_claims_errors(capsys, tmp_path):
    from satenv.bench import claims
    from satenv.training import card

    with pytest.raises(SystemExit) as exit_:
        card.main(["--help"])
    assert exit_.value.code == 0
    (tmp_path / "x.json").write_text("[1]")
    assert "expected a JSON object with 'claims'" in _error(capsys, claims.main, [str(tmp_path / "x.json")])
    assert "expected a readable reproduction result" in _error(capsys, claims.main, [str(tmp_path / "no.json")])


# --- the grammar: a config dataclass as flags and back -----------------------------------------------

@dataclass(frozen=True)
class Demo:
    """A demo config (``Demo``) for :func:`satenv.cliargs.config_parser`."""

    count: int = 3
    """How many (``count``); at least 1."""
    rate: float = 0.5
    """A rate, 50 % by default."""
    name: str = ""
    """A name."""
    mode: Literal["a", "b"] = "a"
    """The mode."""
    flag: bool = True
    """A switch."""
    sizes: tuple[int, ...] = (64, 64)
    """Layer sizes."""
    extra: dict = field(default_factory=dict)
    """A JSON object."""
    limit: int | None = None
    """An optional limit."""
    renamed: Annotated[int, cliargs.Arg(name="short")] = 1
    """A field with another flag name."""

    def __post_init__(self) -> None:
        if self.count < 1:
            raise ValueError(f"count must be >= 1, got {self.count}")


def test_a_config_round_trips_through_its_flags():
    cfg = Demo(count=7, rate=0.25, name="x y", mode="b", flag=False, sizes=(8,), extra={"k": [1]}, limit=4, renamed=9)
    argv = cliargs.config_to_argv(cfg)
    assert cliargs.parse_config(Demo, argv) == cfg
    assert cliargs.config_to_argv(Demo()) == [] and cliargs.parse_config(Demo, []) == Demo()
    parse = lambda *a: cliargs.parse_config(Demo, list(a))  # noqa: E731
    assert parse("--flag").flag and not parse("--no-flag").flag and not parse("--flag", "false").flag
    assert parse("--sizes", "1,2", "3").sizes == (1, 2, 3) and parse("--sizes").sizes == ()
    assert parse("--limit", "none").limit is None and parse("--short", "5").renamed == 5


@pytest.mark.parametrize(("argv", "expected"), [
    (["--count", "x"], "error: --count 'x': expected an int, got 'x'"),
    (["--count", "0"], "error: --count must be >= 1, got 0"),
    (["--mode", "c"], "argument --mode: invalid choice: 'c'"),
    (["--extra", "[1]"], "error: --extra '[1]': expected a JSON object"),
    (["--flag", "maybe"], "error: --flag 'maybe': expected true or false"),
    (["--cou", "2"], "unrecognized arguments: --cou 2")])
def test_a_bad_flag_is_one_line_naming_it(argv, expected, capsys):
    with pytest.raises(SystemExit) as exit_:
        cliargs.parse_config(Demo, argv, prog="demo")
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and expected in err, err


def test_the_help_is_the_field_docstrings_without_rest(capsys):
    with pytest.raises(SystemExit):
        cliargs.parse_config(Demo, ["--help"], prog="demo")
    out = " ".join(capsys.readouterr().out.split())
    assert "A demo config (Demo) for satenv.cliargs.config_parser." in out
    assert "How many (count); at least 1. (default: 3)" in out and "A rate, 50 % by default. (default: 0.5)" in out
    assert "{a,b}" in out and "(default: 64,64)" in out and "--short" in out and "(default: '')" in out
    assert not RAW_REST.search(out)


def test_plain_strips_rest():
    assert cliargs.plain("see :func:`~a.b`, ``x`` and `tyro <https://x.y>`_") == "see a.b, x and tyro"


def test_trainers_say_what_they_will_do(capsys):
    from satenv.training.config import TrainConfig, announce

    cfg = TrainConfig(task="platoon-tplf30-random-cw", out_dir="runs/x", test_seeds=(900_000, 900_001))
    text = announce(cfg, "PPO, 4096 agent-steps")
    assert capsys.readouterr().err.strip() == text.strip()
    for part in ("training on platoon-tplf30-random-cw: PPO, 4096 agent-steps", "2 held-out episodes",
                 "--test-seeds", "--eval-baselines zero", "Writes to runs/x/", "tensorboard --logdir runs/x/tb"):
        assert part in text


# --- the docs: every satenv command line names a command and flags it has --------------------------

def _doc_commands() -> list[tuple[str, list[str]]]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    found = []
    for page in pages:
        for block in re.findall(r"```(?:bash|sh)\n(.*?)```", page.read_text(), re.S):
            for line in block.replace("\\\n", " ").splitlines():
                m = re.search(r"(?:^|&& |\s)satenv ([a-z-]+)((?: [^#|&;]*)?)", line)
                if m and not line.lstrip().startswith("#"):
                    found.append((f"{page.relative_to(ROOT)}: {line.strip()}", [m.group(1), *shlex.split(m.group(2))]))
    return found


def _help(argv: list[str]) -> str:
    """The ``--help`` text of ``satenv ARGV`` (a paper of ``reproduce``, a sub-command of ``results``)."""
    import contextlib
    import io

    two_words = argv[0] in ("reproduce", "results") and len(argv) > 1 and not argv[1].startswith("-")
    head = argv[:2] if two_words else argv[:1]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), pytest.raises(SystemExit):
        cli.resolve(head[0])([*head[1:], "--help"])
    return buf.getvalue()


PARSED_IN_TEST_TRAINING = {"train", "train-marl", "train-rllib", "imitate", "ppo"}
"""Commands whose doc lines ``tests/test_training.py`` parses with the command's own parser
(aliases and replayed configs included)."""


def test_every_satenv_command_in_the_docs_names_a_command_and_its_flags():
    """README.md and docs/: each ``satenv <command> ...`` line of a shell block uses a command of
    ``satenv --help`` and only flags its ``--help`` lists (whole names: no abbreviation)."""
    found = _doc_commands()
    assert len(found) >= 30 and any(w.startswith("docs/cli.md") for w, _ in found)
    helps: dict[str, set[str]] = {}
    for where, argv in found:
        assert argv[0] in cli.COMMANDS, f"{where}: no command {argv[0]!r}"
        if argv[0] in PARSED_IN_TEST_TRAINING:
            continue
        key = " ".join(argv[:2]) if argv[0] in ("reproduce", "results") else argv[0]
        if key not in helps:
            helps[key] = set(re.findall(r"(--[a-z0-9][a-z0-9-]*)", _help(argv)))
        for flag in (a.split("=")[0] for a in argv[1:] if a.startswith("--")):
            listed = flag in helps[key] or (flag.startswith("--no-") and "--" + flag[5:] in helps[key])
            assert listed, f"{where}: {flag} is not an option of satenv {key}"


def test_cli_page_has_an_example_of_every_command():
    text = (ROOT / "docs" / "cli.md").read_text()
    for name in cli.COMMANDS:
        assert re.search(rf"^satenv {name}\b", text, flags=re.M), name
    nav = (ROOT / "mkdocs.yml").read_text()
    assert "cli.md" in nav and "layout.md" in nav
