"""Code, docs and the README speak of the project alone: no references to the tracker's issue
numbers (a reader outside the project cannot know what "issue 27" was); a threshold is named for
what it is."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROCESS_WORDS = re.compile(r"issue ?[0-9]+|ISSUE[0-9]+", re.IGNORECASE)
SCANNED = ("satenv", "baselines", "training", "benchmarks", "docs", "README.md")
TEXT = {".py", ".md", ".yml", ".yaml", ".json", ".txt", ".toml", ".cfg"}


def _files():
    for entry in SCANNED:
        path = ROOT / entry
        yield from ([path] if path.is_file() else
                    (p for p in sorted(path.rglob("*")) if p.is_file() and p.suffix in TEXT))


def test_no_issue_numbers_in_code_docs_or_readme():
    hits = [f"{p.relative_to(ROOT)}:{i}: {line.strip()[:100]}" for p in _files()
            for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1) if PROCESS_WORDS.search(line)]
    assert hits == [], "issue numbers in the project's own text:\n" + "\n".join(hits[:50])


def test_the_pattern_finds_what_it_should():
    assert PROCESS_WORDS.search("met under issue 27's rule") and PROCESS_WORDS.search("ISSUE27_SUCCESS_MARGIN")
    assert not PROCESS_WORDS.search("GitHub issues and pull requests")
