"""The documentation site builds (``mkdocs build --strict``) and every code example on it runs.

Examples: every ```` ```python ```` block of ``docs/**/*.md`` and ``README.md``, run in order in
one namespace per page (a page reads as one script). A block preceded by the line
``<!-- no-test: reason -->`` is skipped.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
OWN_PACKAGES = {"satenv", "baselines", "training", "benchmarks"}
_BLOCK = re.compile(r"(<!-- no-test: [^>]+ -->\n)?```python\n(.*?)```", re.S)


def python_blocks(page: Path) -> list[str]:
    """The page's runnable ```python blocks, in order."""
    return [m.group(2) for m in _BLOCK.finditer(page.read_text(encoding="utf-8")) if not m.group(1)]


def test_examples_are_found(tmp_path):
    counts = {p.relative_to(ROOT).as_posix(): len(python_blocks(p)) for p in PAGES}
    assert counts["README.md"] >= 2 and counts["docs/envs/platoon_v0.md"] == 1, counts
    page = tmp_path / "page.md"
    page.write_text("<!-- no-test: needs a cluster -->\n```python\nraise SystemExit\n```\n"
                    "```bash\nls\n```\n```python\nx = 1\n```\n")
    assert python_blocks(page) == ["x = 1\n"]


@pytest.mark.parametrize("page", [p for p in PAGES if python_blocks(p)],
                         ids=lambda p: p.relative_to(ROOT).as_posix())
def test_page_examples_run(page):
    namespace: dict = {"__name__": "__docs__"}
    for k, code in enumerate(python_blocks(page)):
        try:
            exec(compile(code, f"{page.name}[block {k}]", "exec"), namespace)
        except ModuleNotFoundError as exc:  # an optional extra (e.g. torch) not installed here
            if (exc.name or "").split(".")[0] in OWN_PACKAGES:
                raise
            pytest.skip(f"{page.name} block {k} needs {exc.name} (an optional extra)")


def test_mkdocs_build_strict(docs_site):
    """``mkdocs build --strict`` as the README writes it (no ``-q``: every WARNING counts)."""
    site, out = docs_site
    log = out.stdout + out.stderr
    assert out.returncode == 0, log
    assert "WARNING" not in log, log
    pages = sorted(site.glob("**/index.html"))
    assert len(pages) >= 25, [p.relative_to(site) for p in pages]
    html = (site / "envs" / "servicing_v0" / "index.html").read_text(encoding="utf-8")
    assert "(M, 13)" in html and "servicing_v0.png" in html  # the docstring and the figure rendered


def _hooks():
    pytest.importorskip("mkdocs", reason="mkdocs is not installed (the 'docs' extra)")
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_claims_table_reads_any_claim_shape():
    hooks = _hooks()
    listed = hooks.claims_table([
        {"case": 1, "claim": "converges", "paper": "about 1000 s", "measured": 1101.5, "met": True},
        {"case": 1, "claim": "accurate", "paper": 0.071, "measured": {"rdmpc": 0.02}, "met": False, "note": "x|y"},
    ])
    lines = listed.splitlines()
    assert lines[0] == "| case | claim | paper | measured | met | note |"
    assert lines[2] == "| 1 | converges | about 1000 s | 1102 | yes |  |"
    assert lines[3] == '| 1 | accurate | 0.071 | `{"rdmpc": 0.02}` | **no** | x\\|y |'
    as_dict = hooks.claims_table({"waypoints_reached": True, "pointing_achieved": False})
    assert as_dict.splitlines()[3] == "| pointing_achieved | **no** |"


def test_docstring_conversion():
    hooks = _hooks()
    doc = ("title\n\nSpaces\n------\n``preset``   ``\"a\"`` or\n             ``\"b\"``.\nnext :class:`~x.Y`\n\n"
           "=======  =======\nentries  meaning\n=======  =======\n0–2      first\n         more\n"
           "3        second\n=======  =======\n")
    md = hooks.rst_to_markdown(doc)
    assert "## Spaces" in md and '* ``preset``: ``"a"`` or ``"b"``.' in md and "next ``Y``" in md
    assert "| entries | meaning |" in md and "| 0–2 | first more |" in md and "| 3 | second |" in md
    with pytest.raises(Exception, match="not defined in satenv/baselines/dmpc.py"):
        hooks.check_source_refs("`satenv/baselines/dmpc.py::OneHopDMPC.gone`", "page.md")
    hooks.check_source_refs("`satenv/baselines/dmpc.py::OneHopDMPC.solve` `satenv/allocation.py`", "page.md")
