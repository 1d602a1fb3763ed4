"""MkDocs hooks: the pages render satenv's own sources and results at build time (nothing pasted).

Markers (HTML comments, invisible where a page is read as plain Markdown, e.g. on the repository
host), each alone on a line:

``<!-- docstring: satenv.envs.platoon_v0 -->``
    the module's docstring (reST-flavoured plain text) converted to Markdown;
``<!-- env-figure: platoon_v0 -->``
    the env's picture and caption from ``assets/envs/figures.json`` (``docs/gen_figures.py``);
``<!-- reproduction: pereira2023 -->``
    status, the rendered ``assets/reproductions/<paper>.md`` (departures, claims with the paper's
    sentence, as-published and analysis tables), the command's printed table and every figure of
    ``assets/reproductions/<paper>`` (all written by ``docs/gen_reproductions.py``);
``<!-- include: studies/published/scoreboard.md -->``, ``<!-- include: README.md#quick-start -->``
    a repository file's Markdown (path from the repository root), or the section under one
    heading (its slug), headings shifted one level down; its relative links to ``docs/`` pages
    are re-pointed, other relative links become plain paths;
``<!-- gallery: scoreboard/plots -->``
    every PNG of a site folder, as images.

``MOUNTS`` serves repository folders as site folders (the published scoreboard's plots), so
they are included, not copied. A missing file, module or folder is a build error, and so is a
source reference `` `path.py::Name` `` (or `` `path.py` ``) that no longer exists.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import re
from pathlib import Path
from typing import Any

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
MOUNTS = {"scoreboard/plots": ROOT / "studies" / "published" / "plots"}
"""Site folder -> repository folder served there."""

_MARKER = re.compile(r"^<!-- (docstring|env-figure|reproduction|include|gallery|tasks): (\S+) -->$", re.M)


# --- reST-flavoured docstrings -> Markdown --------------------------------------------------------

_ROLE = re.compile(r":(?:mod|class|func|meth|attr|data|exc):`(~?)([^`]+)`")
_TABLE_BORDER = re.compile(r"^=+( +=+)+$")
_UNDERLINE = re.compile(r"^-{3,}$")
_ARGUMENT = re.compile(r"^(``[^`]+``)\s{2,}(\S.*)$")


def _role(m: re.Match) -> str:
    target = m.group(2)
    return f"``{target.rsplit('.', 1)[-1] if m.group(1) else target}``"


def _table(lines: list[str]) -> list[str]:
    """A reST simple table (border, header, border, rows, border) as a Markdown table."""
    border = lines[0]
    spans = [(m.start(), m.end()) for m in re.finditer(r"=+", border)]
    rows: list[list[str]] = []
    for line in lines[1:]:
        if _TABLE_BORDER.match(line):
            continue
        cells = [line[a:b if i + 1 < len(spans) else None].strip() for i, (a, b) in enumerate(spans)]
        if rows and not cells[0] and len(rows) > 1:  # continuation line of the previous row
            rows[-1] = [f"{old} {new}".strip() for old, new in zip(rows[-1], cells, strict=True)]
        else:
            rows.append(cells)
    out = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(spans)]
    out += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows[1:]]
    return ["", *out, ""]


def rst_to_markdown(text: str) -> str:
    """Convert satenv's docstring conventions to Markdown (headings, tables, argument lists, roles)."""
    lines = _ROLE.sub(_role, text).splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if _TABLE_BORDER.match(line):
            end = i + 1
            borders = 1
            while end < len(lines) and borders < 3:
                borders += bool(_TABLE_BORDER.match(lines[end]))
                end += 1
            out += _table(lines[i:end])
            i = end
        elif line.strip() and _UNDERLINE.match(nxt):
            out += ["", f"## {line.strip()}", ""]
            i += 2
        elif _ARGUMENT.match(line):
            name, rest = _ARGUMENT.match(line).groups()
            i += 1
            while i < len(lines) and lines[i].startswith(" ") and lines[i].strip():
                rest += " " + lines[i].strip()
                i += 1
            out += [f"* {name}: {rest}", ""]
        else:
            out.append(line[:-2] + ":" if line.endswith("::") else line)
            i += 1
    return "\n".join(out)


def module_docstring(module: str) -> str:
    """A module's docstring read from its source file (without importing it)."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise PluginError(f"docstring marker: module {module!r} not found")
    doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text(encoding="utf-8")))
    if not doc:
        raise PluginError(f"docstring marker: module {module!r} has no docstring")
    return rst_to_markdown(doc)


# --- generated results --------------------------------------------------------------------------

def _site_dir(folder: str) -> Path:
    path = MOUNTS.get(folder, DOCS / folder)
    if not path.is_dir():
        raise PluginError(f"folder {folder!r} ({path}) does not exist")
    return path


def _relative(page_src: str, target: str) -> str:
    """Link from the page's source file to a site path (both relative to docs/)."""
    depth = page_src.count("/")
    return "../" * depth + target


def gallery(folder: str, page_src: str) -> str:
    images = sorted(_site_dir(folder).glob("*.png"))
    return "\n\n".join(f"![{p.stem}]({_relative(page_src, f'{folder}/{p.name}')})" for p in images)


def env_figure(env_id: str, page_src: str) -> str:
    index_path = DOCS / "assets" / "envs" / "figures.json"
    figures = json.loads(index_path.read_text(encoding="utf-8"))
    if env_id not in figures:
        raise PluginError(f"env-figure: no figure for {env_id!r} in {index_path}: run docs/gen_figures.py")
    fig = figures[env_id]
    src = _relative(page_src, f"assets/envs/{fig['image']}")
    return f"![{env_id} episode]({src})\n\n*{fig['caption']}*"


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "**no**"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (dict, list)):
        return "`" + json.dumps(value, separators=(", ", ": "), default=str).replace("|", "\\|") + "`"
    return str(value).replace("|", "\\|").replace("\n", " ")


def claims_table(claims: Any) -> str:
    """A table of a reproduction's claims: a list of dicts, or a dict name -> dict or bool."""
    if isinstance(claims, dict):
        claims = [{"claim": k, **(v if isinstance(v, dict) else {"met": v})} for k, v in claims.items()]
    first = ["case", "claim", "name", "paper", "target", "measured", "met"]
    keys = [k for k in first if any(k in c for c in claims)]
    keys += [k for c in claims for k in c if k not in keys]
    keys = list(dict.fromkeys(keys))
    rows = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    rows += ["| " + " | ".join(_cell(c.get(k, "")) for k in keys) + " |" for c in claims]
    return "\n".join(rows)


def reproduction(paper: str, page_src: str) -> str:
    base = DOCS / "assets" / "reproductions"
    json_path = base / f"{paper}.json"
    command = f"satenv reproduce {paper} --out {paper}.json --plots figs/"
    if not json_path.exists():
        return (f"!!! note \"Not generated yet\"\n    `{json_path.relative_to(ROOT)}` is not in this "
                f"checkout: run `python docs/gen_reproductions.py --only {paper}` (or `{command}`).")
    result = json.loads(json_path.read_text(encoding="utf-8"))
    status = ("every paper-valued claim of our run met" if result.get("pass")
              else "**not every paper-valued claim of our run met**")
    parts = [f"Result of `{command}` (`{json_path.relative_to(ROOT)}`): {status}"
             + (f", wall time {result['wall_time_s']:.0f} s." if "wall_time_s" in result else ".")]
    page = base / f"{paper}.md"             # departures, claims, analyses (docs/gen_reproductions.py)
    if page.exists():
        parts.append(page.read_text(encoding="utf-8"))
    elif result.get("claims"):
        parts += ["### Claims", claims_table(result["claims"])]
    text = base / f"{paper}.txt"
    if text.exists():
        parts += ["### The command's table", "```text\n" + text.read_text(encoding="utf-8").rstrip() + "\n```"]
    if (base / paper).is_dir():
        parts += ["### Figures", gallery(f"assets/reproductions/{paper}", page_src)]
    return "\n\n".join(parts)


def _slug(heading: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", heading.lower()).strip("-")


def _outside_fences(text: str) -> list[bool]:
    """Per line: True where the line is Markdown text, False inside a fenced code block."""
    flags, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            flags.append(False)
        else:
            flags.append(not fenced)
    return flags


def _section(text: str, slug: str, where: str) -> str:
    """The section under the heading whose slug is ``slug`` (to the next heading of its level)."""
    lines = text.splitlines(keepends=True)
    heads = [(k, len(m.group(1)), _slug(m.group(2))) for k, (line, ok) in
             enumerate(zip(lines, _outside_fences(text), strict=True))
             if ok and (m := re.match(r"^(#+) (.*)$", line))]
    for n, (k, level, s) in enumerate(heads):
        if s == slug:
            end = next((h[0] for h in heads[n + 1:] if h[1] <= level), len(lines))
            return "".join(lines[k + 1:end])
    raise PluginError(f"include: no heading {slug!r} in {where}; headings: {[h[2] for h in heads]}")


def _link(m: re.Match, page_src: str) -> str:
    """A relative link of a repository file, re-pointed for the page (docs/...) or shown as a path."""
    text, target = m.groups()
    if re.match(r"^[a-z]+:|^#", target):
        return m.group(0)
    if target.startswith("docs/"):
        return f"[{text}]({_relative(page_src, target[len('docs/'):])})"
    return text if text.strip("`") == target else f"{text} (`{target}`)"


def include(spec: str, page_src: str) -> str:
    """A repository file (``path``) or one section of it (``path#heading-slug``), headings one level down."""
    path, _, slug = spec.partition("#")
    file = ROOT / path
    if not file.is_file():
        raise PluginError(f"include: {file} does not exist")
    text = file.read_text(encoding="utf-8")
    if slug:
        text = _section(text, slug, path)
    out = []
    for line, ok in zip(text.splitlines(), _outside_fences(text), strict=True):
        if ok:
            line = re.sub(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)", lambda m: _link(m, page_src), line)
            line = re.sub(r"^(#+) ", r"#\1 ", line)
        out.append(line)
    return "\n".join(out)


_SOURCE_REF = re.compile(r"`(\w+/[\w/]*\.py)(?:::([\w.]+))?`")


def _defined(tree: ast.AST, qualname: str) -> bool:
    scope = getattr(tree, "body", [])
    for part in qualname.split("."):
        node = next((n for n in scope if isinstance(n, (ast.FunctionDef, ast.ClassDef))
                     and n.name == part), None)
        if node is None:
            return False
        scope = node.body
    return True


def check_source_refs(markdown: str, page_src: str) -> None:
    """Every `` `path.py` `` and `` `path.py::Name.attr` `` on a page names a file and a definition."""
    for m in _SOURCE_REF.finditer(markdown):
        path, qualname = m.groups()
        file = ROOT / path
        if not file.is_file():
            raise PluginError(f"{page_src}: {path} does not exist")
        if qualname and not _defined(ast.parse(file.read_text(encoding="utf-8")), qualname):
            raise PluginError(f"{page_src}: {qualname} is not defined in {path}")


def task_table(what: str) -> str:
    """``<!-- tasks: systems -->``: the paper systems; ``<!-- tasks: all -->``: every task of
    ``satenv.tasks``, with its env, system, role, seeds, perturbations and cost budget."""
    from satenv import tasks

    if what == "systems":
        rows = ["| system | controller | expert | training task | paper task |", "|---|---|---|---|---|"]
        rows += [f"| {s.label} (`{s.name}`) | `{s.controller}` | `{s.expert}` | `{s.training_task}` | "
                 f"`{s.paper_task}` |" for s in tasks.SYSTEMS.values()]
        return "\n".join(rows)
    if what != "all":
        raise PluginError(f"<!-- tasks: {what} -->: expected 'all' or 'systems'")
    rows = ["| task | env | system, role | test seeds | perturbations | cost budget | description |",
            "|---|---|---|---|---|--:|---|"]
    for t in tasks.TASKS.values():
        test = tasks.show_seeds(t.seeds("test"))
        budget = "none (no safety constraint)" if t.cost_budget is None else f"{t.cost_budget:g}"
        rows.append(f"| `{t.name}` | `{t.env_id}` | {t.system or '–'}, {t.role} | {test} | "
                    f"{', '.join(f'`{p}`' for p in t.perturbations) or '–'} | {budget} | {t.description} |")
    return "\n".join(rows)


# --- MkDocs events ------------------------------------------------------------------------------

def on_files(files, config):
    for folder, path in MOUNTS.items():
        for file in sorted(path.glob("*.png")):
            files.append(File.generated(config, f"{folder}/{file.name}", abs_src_path=str(file)))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:
    src = page.file.src_uri

    def expand(m: re.Match) -> str:
        kind, arg = m.groups()
        if kind == "docstring":
            return module_docstring(arg)
        if kind == "env-figure":
            return env_figure(arg, src)
        if kind == "reproduction":
            return reproduction(arg, src)
        if kind == "include":
            return include(arg, src)
        if kind == "tasks":
            return task_table(arg)
        return gallery(arg, src)

    check_source_refs(markdown, src)
    return _MARKER.sub(expand, markdown)


def on_page_content(html: str, page, config, files) -> str:
    """Tidy reST left in API docstrings: roles (``:class:<code>X</code>``) and ``::`` before code."""
    html = re.sub(r":(?:mod|class|func|meth|attr|data|exc):(<code>)~?", r"\1", html)
    return html.replace("::</p>", ":</p>")
