"""Claim records of the reproductions: one home for "what the paper says, what we measured, met?".

Every ``benchmarks/repro_<paper>.py`` returns ``result["claims"]``, a list of :func:`claim`
records, and sets ``result["pass"] = all_met(result["claims"])``; ``python -m benchmarks.reproduce``
exits 0 only when every claim it checks is met (:func:`passed`). A record::

    {"claim": "FOE PLF follower 1", "paper": 3.262e-06, "measured": 6.9e-06, "met": False,
     "target": "<= 1.5x paper", ...context (e.g. "topology", "follower", "case")}

``paper`` is the paper's number or statement (``None`` when the claim is ours, e.g. a pass
test the paper does not state: say so in ``note``), ``measured`` what the run gave, ``target``
the rule that decides ``met``. :func:`format_claims` prints them; :func:`markdown_rows` makes the
README's claim table rows (``python -m benchmarks.claims RESULT.json ...``).
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

__all__ = ["claim", "all_met", "passed", "format_claims", "markdown_rows", "within"]

def claim(name: str, paper: Any, measured: Any, met: bool, *, target: str | None = None,
          note: str | None = None, **context: Any) -> dict[str, Any]:
    """One claim record (JSON-ready: numpy scalars become Python numbers)."""
    if not isinstance(name, str) or not name:
        raise TypeError(f"claim name must be a non-empty str, got {name!r}")
    rec = {"claim": name, "paper": _plain(paper), "measured": _plain(measured), "met": bool(met)}
    if target is not None:
        rec["target"] = target
    if note is not None:
        rec["note"] = note
    rec.update({k: _plain(v) for k, v in context.items()})
    return rec


def within(measured: float, paper: float, factor: float) -> bool:
    """``measured`` within a factor ``factor`` (>= 1) of ``paper`` (both positive)."""
    if factor < 1:
        raise ValueError(f"factor must be >= 1, got {factor}")
    return paper > 0 and measured > 0 and max(measured / paper, paper / measured) <= factor


def all_met(claims: Iterable[dict[str, Any]]) -> bool:
    """True when there is at least one claim and every one is met."""
    claims = list(claims)
    return bool(claims) and all(c["met"] for c in claims)


def passed(result: dict[str, Any]) -> bool:
    """The verdict of a reproduction result: its ``pass`` flag and, if it lists claims, all met."""
    ok = bool(result.get("pass", True))
    if "claims" in result:
        ok = ok and all_met(result["claims"])
    return ok


def _plain(v: Any) -> Any:
    if hasattr(v, "tolist"):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        if v != 0 and math.isfinite(v) and (abs(v) < 1e-3 or abs(v) >= 1e5):
            return f"{v:.3e}"
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def format_claims(claims: Iterable[dict[str, Any]]) -> str:
    """The claims as plain-text lines ``claim | paper | measured | target | met``."""
    claims = list(claims)
    width = max((len(c["claim"]) for c in claims), default=5)
    lines = [f"{'claim':<{width}} | {'paper':>12} | {'measured':>12} | target | status"]
    for c in claims:
        lines.append(f"{c['claim']:<{width}} | {_fmt(c['paper']):>12} | {_fmt(c['measured']):>12} "
                     f"| {c.get('target', '-')} | {'met' if c['met'] else 'NOT MET'}")
    n_met = sum(c["met"] for c in claims)
    verdict = "PASS" if all_met(claims) else "FAIL"
    lines.append(f"claims met: {n_met}/{len(claims)} -> {verdict}")
    return "\n".join(lines)


def markdown_rows(result: dict[str, Any]) -> list[str]:
    """README claim-table rows ``| paper | claim | paper value | measured | target | status |``."""
    rows = []
    for c in result.get("claims", []):
        status = "met" if c["met"] else "**not met**"
        rows.append(f"| {result.get('paper', '?')} | {c['claim']} | {_fmt(c['paper'])} | "
                    f"{_fmt(c['measured'])} | {c.get('target', '-')} | {status} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the README table rows of reproduction JSON files."""
    paths = sys.argv[1:] if argv is None else argv
    if not paths:
        print("usage: python -m benchmarks.claims RESULT.json [...]", file=sys.stderr)
        return 2
    print("| paper | claim | paper value | measured | target | status |")
    print("|---|---|---|---|---|---|")
    for p in paths:
        for row in markdown_rows(json.loads(Path(p).read_text())):
            print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
