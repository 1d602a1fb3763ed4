"""The one command-line grammar: argparse parsers, and config dataclasses as flags and back.

Every satenv command builds its parser with :func:`new_parser` (``allow_abbrev=False``: a
mistyped ``--scenario`` is an error, never taken for ``--scenarios``; descriptions shown as
written, reST markup stripped by :func:`plain`). A frozen config dataclass becomes flags with
:func:`add_config_flags` and comes back with :func:`config_from_args`; :func:`config_to_argv`
turns a config into the flags that rebuild it.

A field ``name: T = default`` is the flag ``--name`` (underscores as dashes); its help is the
docstring under the field, with its default. Values by type:

- ``int``, ``float``, ``str``, ``pathlib.Path``; ``T | None`` also takes ``none`` (unless ``T``
  is ``str``);
- ``Literal[...]``: one of the choices;
- ``bool``: ``--flag`` or ``--flag true|false`` (also ``1/0``, ``yes/no``); ``--no-flag``;
- ``tuple[T, ...]``: comma or space separated (``--net-arch 64,64`` or ``64 64``);
- ``dict``: a JSON object;
- ``Annotated[T, Arg(...)]``: the field's own reader, metavar or flag name.

A bad value exits with status 2 and one ``error:`` line naming the flag, the value and what is
expected; so does a value the dataclass rejects (its message, with the field named as its flag).
"""

from __future__ import annotations

import argparse
import ast
import functools
import inspect
import json
import os
import re
import textwrap
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import MISSING, Field, dataclass, fields
from pathlib import Path
from typing import Annotated, Any, Literal

__all__ = ["Arg", "add_config_flags", "config_from_args", "config_parser", "config_to_argv", "flag_message",
           "flag_name", "int_at_least", "new_parser", "out_file", "out_folder", "parse_bool", "parse_config",
           "parse_json_object", "plain"]


@dataclass(frozen=True)
class Arg:
    """How one config field reads from the command line: ``Annotated[T, Arg(...)]``."""

    parse: Callable[[Any], Any] | None = None
    """Token (or, with ``many``, the list of tokens) -> value; raises ``ValueError`` on bad input."""
    show: Callable[[Any], str] | None = None
    """Value -> its token (the help's default, :func:`config_to_argv`)."""
    metavar: str | None = None
    """The value's name in ``--help``."""
    name: str | None = None
    """The flag without ``--`` (default: the field name with dashes)."""
    many: bool = False
    """The flag takes several tokens (``nargs='*'``)."""


def parse_bool(text: str) -> bool:
    """A boolean flag's value: ``true``/``false`` (also ``1``/``0``, ``yes``/``no``)."""
    low = str(text).lower()
    if low not in ("true", "false", "1", "0", "yes", "no"):
        raise ValueError(f"expected true or false, got {text!r}")
    return low in ("true", "1", "yes")


def parse_json_object(text: str) -> dict[str, Any]:
    """A JSON object flag's value (``'{"randomize": true}'``)."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = None
    if not isinstance(value, dict):
        raise ValueError(f"expected a JSON object, e.g. '{{\"randomize\": true}}', got {text!r}")
    return value


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type``: an int >= ``minimum`` (else the flag's error names the value)."""
    def read(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected an int >= {minimum}, got {text!r}")
        return value

    read.__name__ = f"int >= {minimum}"
    return read


def _under_a_file(path: Path) -> Path | None:
    """The nearest existing ancestor of ``path`` when it is not a folder (``path`` cannot be made)."""
    for parent in path.parents:
        if os.path.lexists(parent):
            return None if parent.is_dir() else parent
    return None


def out_folder(text: str) -> Path:
    """An argparse ``type``: an output folder (a new path or an existing folder; not '', not a file)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a folder path, got {text!r}")
    path = Path(text)
    if path.exists() and not path.is_dir() or path.is_symlink() and not path.exists():
        raise argparse.ArgumentTypeError(f"{text!r} exists and is not a folder; give a new or an existing folder")
    if (blocker := _under_a_file(path)) is not None:
        raise argparse.ArgumentTypeError(f"{text!r} lies under {str(blocker)!r}, which is not a folder")
    return path


def published_or_user(parser: argparse.ArgumentParser, flag: str, given: Any, update_published: bool,
                      published: Any, user: Any) -> Any:
    """Where a command writes: ``given`` (the flag's value) when set, else ``published`` (the committed
    record) with ``--update-published``, else ``user`` (a user folder). A value given together with
    ``--update-published`` is one error naming both flags."""
    if given is not None and update_published:
        parser.error(f"argument {flag}: {str(given)!r} given with --update-published (which writes {published}); "
                     "give one of them")
    if given is not None:
        return given
    return published if update_published else user


def out_file(text: str) -> Path:
    """An argparse ``type``: an output file path (not '', not an existing folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a file path, got {text!r}")
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; expected a file path")
    if (blocker := _under_a_file(path)) is not None:
        raise argparse.ArgumentTypeError(f"{text!r} lies under {str(blocker)!r}, which is not a folder")
    return path


_ROLE = re.compile(r":[a-z:]+:`~?([^`]+)`")
_LINK = re.compile(r"`([^`<]+?)\s*<[^>]+>`_")


def plain(text: str | None) -> str:
    """Docstring text as a terminal shows it: dedented, reST roles, links and double backticks
    stripped (``:func:`x``` -> ``x``, ````x```` -> ``x``, ```a <url>`_`` -> ``a``)."""
    text = inspect.cleandoc(text or "")
    text = _LINK.sub(r"\1", _ROLE.sub(r"\1", text))
    return text.replace("``", "")


def new_parser(prog: str | None = None, description: str | None = None, epilog: str | None = None,
               **kwargs: Any) -> argparse.ArgumentParser:
    """An argparse parser in the project's style: no abbreviated flags, descriptions as written
    (reST stripped)."""
    kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
    return argparse.ArgumentParser(prog=prog, description=plain(description) or None,
                                   epilog=plain(epilog) or None, allow_abbrev=False, **kwargs)


def flag_name(cls: type, f: Field) -> str:
    """The flag of a field of the dataclass ``cls``: ``--`` and its :class:`Arg` name or its name
    with dashes."""
    arg = _arg(_hints(cls)[f.name])
    return "--" + (arg.name if arg and arg.name else f.name.replace("_", "-"))


@functools.cache
def _docstrings(cls: type) -> dict[str, str]:
    """The docstring under each field of ``cls`` and its dataclass bases (the subclass's wins)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for node, nxt in zip(body, body[1:], strict=False):
            if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str)):
                out[node.target.id] = " ".join(plain(nxt.value.value).split())
    return out


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls, include_extras=True)


def _arg(tp: Any) -> Arg | None:
    if typing.get_origin(tp) is Annotated:
        return next((m for m in tp.__metadata__ if isinstance(m, Arg)), None)
    return None


def _bare(tp: Any) -> tuple[Any, bool]:
    """``tp`` without ``Annotated`` and ``| None``; whether it was optional."""
    if typing.get_origin(tp) is Annotated:
        tp = typing.get_args(tp)[0]
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return (args[0] if len(args) == 1 else tp), len(args) < len(typing.get_args(tp))
    return tp, False


def _many(tp: Any) -> bool:
    arg = _arg(tp)
    if arg and arg.parse:
        return arg.many
    return typing.get_origin(_bare(tp)[0]) is tuple


def _show(tp: Any, value: Any) -> str:
    arg = _arg(tp)
    if arg and arg.show:
        return arg.show(value)
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (tuple, list)):
        return ",".join(map(str, value))
    if isinstance(value, dict):
        return json.dumps(value)
    return str(value)


_SCALARS: dict[Any, tuple[Callable[[str], Any], str]] = {
    int: (int, "an int"), float: (float, "a number"), str: (str, "a string"), Path: (Path, "a path"),
    bool: (parse_bool, "true or false")}


def _convert(tp: Any, value: Any) -> Any:
    """The value of a field of type ``tp`` from its token(s) (``ValueError`` naming the value)."""
    arg = _arg(tp)
    if arg and arg.parse:
        return arg.parse(value)
    bare, optional = _bare(tp)
    if optional and bare is not str and isinstance(value, str) and value.lower() == "none":
        return None
    if typing.get_origin(bare) is Literal:
        return {str(c): c for c in typing.get_args(bare)}[value]
    if typing.get_origin(bare) is tuple:
        item = typing.get_args(bare)[0]
        return tuple(_convert(item, p.strip()) for tok in value for p in tok.split(",") if p.strip())
    if bare is dict or typing.get_origin(bare) is dict:
        return parse_json_object(value)
    read, what = _SCALARS.get(bare, (None, ""))
    if read is None:
        raise TypeError(f"no command-line reader for a field of type {tp!r}: annotate it with Arg(parse=...)")
    try:
        return read(value)
    except ValueError:
        raise ValueError(f"expected {what}, got {value!r}") from None


def add_config_flags(parser: argparse.ArgumentParser, cls: type, *, title: str | None = None) -> None:
    """One flag per field of the dataclass ``cls`` (see the module docstring). Only the flags
    given land in the namespace (read them back with :func:`config_from_args`)."""
    group = parser.add_argument_group(title) if title else parser
    docs = _docstrings(cls)
    for f in fields(cls):
        if not f.init:
            continue
        tp = _hints(cls)[f.name]
        arg, (bare, _) = _arg(tp), _bare(tp)
        default = f.default if f.default is not MISSING else (
            f.default_factory() if f.default_factory is not MISSING else MISSING)
        shown = "" if default in (MISSING, None) else f" (default: {_show(tp, default) if default != '' else repr('')})"
        text = (docs.get(f.name, "") + shown).replace("%", "%%")
        flag = flag_name(cls, f)
        kw: dict[str, Any] = {"dest": f.name, "default": argparse.SUPPRESS, "help": text,
                              "metavar": arg.metavar if arg and arg.metavar else None}
        if typing.get_origin(bare) is Literal and not (arg and arg.parse):
            kw["choices"] = [str(c) for c in typing.get_args(bare)]
            kw["metavar"] = kw["metavar"] or "{" + ",".join(kw["choices"]) + "}"
        if bare is bool and not (arg and arg.many):
            kw.update(nargs="?", const="true", metavar=kw["metavar"] or "{true,false}")
            group.add_argument(flag, **kw)
            group.add_argument("--no-" + flag[2:], dest=f.name, action="store_const", const="false",
                               default=argparse.SUPPRESS, help=argparse.SUPPRESS)
            continue
        if _many(tp):
            kw["nargs"] = "*"
        if kw["metavar"] is None and not kw.get("choices"):
            kw["metavar"] = "JSON" if bare is dict or typing.get_origin(bare) is dict else f.name.upper()
        group.add_argument(flag, **kw)


def flag_message(cls: type, message: str) -> str:
    """A dataclass's message with a leading field name written as its flag."""
    flags = {f.name: flag_name(cls, f) for f in fields(cls)}
    m = re.match(r"(\w+)\b", message)
    return flags[m.group(1)] + message[m.end():] if m and m.group(1) in flags else message


def config_from_args(parser: argparse.ArgumentParser, cls: type, ns: argparse.Namespace,
                     base: Any = None) -> Any:
    """The ``cls`` config of the flags in ``ns`` (those :func:`add_config_flags` added), over
    ``base`` (a ``cls`` instance) or the field defaults. A bad value is ``parser.error`` (exit
    status 2, the flag named)."""
    values = {} if base is None else {f.name: getattr(base, f.name) for f in fields(cls) if f.init}
    for f in fields(cls):
        if f.init and hasattr(ns, f.name):
            raw = getattr(ns, f.name)
            try:
                values[f.name] = _convert(_hints(cls)[f.name], raw)
            except ValueError as err:
                shown = " ".join(raw) if isinstance(raw, list) else raw
                parser.error(f"{flag_name(cls, f)} {shown!r}: {err}")
    try:
        return cls(**values)
    except (ValueError, TypeError) as err:
        parser.error(flag_message(cls, str(err)))


def config_parser(cls: type, *, prog: str | None = None, description: str | None = None,
                  epilog: str | None = None) -> argparse.ArgumentParser:
    """:func:`new_parser` with one flag per field of ``cls`` (its docstring as the description)."""
    parser = new_parser(prog, description if description is not None else cls.__doc__, epilog,
                        usage="%(prog)s [OPTIONS]")
    add_config_flags(parser, cls)
    return parser


def parse_config(cls: type, argv: Sequence[str] | None = None, **kwargs: Any) -> Any:
    """``argv`` (default: ``sys.argv[1:]``) as a ``cls`` config (:func:`config_parser`'s flags)."""
    parser = config_parser(cls, **kwargs)
    return config_from_args(parser, cls, parser.parse_args(argv))


def config_to_argv(cfg: Any, *, changed_only: bool = True) -> list[str]:
    """The flags that rebuild ``cfg`` with :func:`config_from_args` (only the fields that differ
    from their defaults, unless ``changed_only`` is false)."""
    out: list[str] = []
    cls = type(cfg)
    for f in fields(cls):
        if not f.init:
            continue
        value = getattr(cfg, f.name)
        default = f.default if f.default is not MISSING else (
            f.default_factory() if f.default_factory is not MISSING else MISSING)
        if changed_only and default is not MISSING and value == default:
            continue
        tp = _hints(cls)[f.name]
        if _many(tp) and isinstance(value, (tuple, list)) and not (_arg(tp) and _arg(tp).show):
            out += [flag_name(cls, f), *map(str, value)] if value else [flag_name(cls, f)]
        else:
            out += [flag_name(cls, f), _show(tp, value)]
    return out

