"""Claim and departure records of the reproductions: what the paper says, what we ran, what we measured.

Every ``satenv/bench/reproductions/<paper>.py`` returns ``result["claims"]`` (records of
:func:`band`, :func:`bound`, :func:`statement` or :func:`no_value`) and ``result["departures"]``
(:func:`departure` records), and sets ``result["pass"] = passed(result)``. A claim record::

    {"claim": "RMSE PLF follower 1", "source": "TABLE II: ... PLF | 19.781 | ...",
     "paper": 19.781, "measured": 19.2, "rule": "within +-10 % of 19.781: [17.8, 21.76]",
     "status": "met", "met": True, "variant": "ours", "gating": True, ...context}

The rule comes from the paper's text, never from the measured number:

* the paper gives a value (``"is 1000 s"``, a table cell): :func:`band`, ``measured`` within
  +-``tol`` (default :data:`BAND`, 10 %) of it;
* the paper states a limit (``"does not exceed ... 1 N"``, ``"-50 <= u <= 50"``): :func:`bound`;
* the paper states a checkable fact (``"collision avoidance completely"``: 0 collisions):
  :func:`statement`;
* the paper gives no value (figures only, or a claim that is ours): :func:`no_value`; its status
  is ``"no paper value"``, it is never counted as met and never gates.

A claim that compares with a design of ours the paper does not give (li2022's APF) is marked by
:func:`against_our_design`: reported in its own section, never gating.

``variant`` says which run the claim judges (``"ours"``, ``"as published"``, an ablation); only
paper-valued claims of ``"ours"`` gate: ``python -m satenv.bench.reproduce`` exits 0 only when every
one of them is met (:func:`passed`); as-published and ablation rows are reported, not gating.

A departure record (:func:`departure`) names a setting where the run differs from the paper, the
paper's value (or ``"not stated"``), ours, why, the measured effect on the claims, and the config
fields it covers (``fields``; the departures test compares them with the paper-valued config).
:func:`format_claims` prints claims; :func:`markdown_claims` / :func:`markdown_departures` render
them for the reproduction pages, :func:`markdown_rows` the README's claim table
(``python -m satenv.bench.claims RESULT.json ...``).
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["BAND", "NO_VALUE", "NOT_STATED", "band", "bound", "statement", "no_value", "departure",
           "against_our_design", "paper_claims", "design_comparisons", "gating", "passed", "count", "format_claims",
           "markdown_claims", "markdown_departures", "markdown_rows", "summary_rows", "changed_claims"]

BAND = 0.10
"""Default half-width of the band around a paper value (relative)."""
NO_VALUE = "paper gives no value"
NOT_STATED = "not stated"
OURS = "ours"
STATUSES = ("met", "not met", NO_VALUE)


def _record(name: str, source: str, paper: Any, measured: Any, rule: str, status: str,
            variant: str, note: str | None, context: dict[str, Any]) -> dict[str, Any]:
    if not isinstance(name, str) or not name:
        raise TypeError(f"claim name must be a non-empty str, got {name!r}")
    if not isinstance(source, str) or not source:
        raise TypeError(f"claim {name!r}: source must quote the paper (non-empty str), got {source!r}")
    if status not in STATUSES:
        raise ValueError(f"claim {name!r}: status must be one of {STATUSES}, got {status!r}")
    rec = {"claim": name, "source": source, "paper": _plain(paper), "measured": _plain(measured),
           "rule": rule, "status": status, "met": status == "met", "variant": variant,
           "gating": variant == OURS and status != NO_VALUE}
    if note is not None:
        rec["note"] = note
    rec.update({k: _plain(v) for k, v in context.items()})
    return rec


def _numbers(v: Any) -> list[float] | None:
    v = _plain(v)
    vals = v if isinstance(v, list) else [v]
    if not vals or any(x is None or isinstance(x, bool) or not isinstance(x, (int, float)) for x in vals):
        return None
    return [float(x) for x in vals]


def band(name: str, source: str, paper: float | Sequence[float], measured: Any, *, tol: float = BAND,
         unit: str = "", variant: str = OURS, note: str | None = None, **context: Any) -> dict[str, Any]:
    """The paper gives a value: met when ``measured`` is within ``+-tol`` (relative) of it; for a
    vector (a position), when ``||measured - paper|| <= tol ||paper||``."""
    if not 0 < tol < 1:
        raise ValueError(f"band {name!r}: tol must be in (0, 1), got {tol}")
    ref, got = _numbers(paper), _numbers(measured)
    if ref is None:
        raise TypeError(f"band {name!r}: paper must be a number or a list of numbers, got {paper!r}")
    unit = f" {unit}" if unit else ""
    ok = got is not None and len(got) == len(ref) and all(math.isfinite(g) for g in got)
    if isinstance(_plain(paper), list):
        radius = tol * math.dist(ref, [0.0] * len(ref))
        ok = ok and math.dist(got, ref) <= radius
        rule = f"within +-{100 * tol:.0f} % of the paper's vector: distance <= {_fmt(radius)}{unit}"
    else:
        lo, hi = ref[0] - tol * abs(ref[0]), ref[0] + tol * abs(ref[0])
        ok = ok and lo <= got[0] <= hi
        rule = f"within +-{100 * tol:.0f} % of the paper's value: [{_fmt(lo)}, {_fmt(hi)}]{unit}"
    return _record(name, source, paper, measured, rule, "met" if ok else "not met", variant, note, context)


def bound(name: str, source: str, limit: float, measured: Any, *, op: str = "<=", unit: str = "",
          variant: str = OURS, note: str | None = None, basis: str = "the paper's limit",
          **context: Any) -> dict[str, Any]:
    """The paper states a limit: met when ``measured op limit`` (``op`` ``"<="`` or ``">="``);
    ``basis`` says where the number comes from when the paper states the limit as a formula whose
    value rests on our reading (e.g. ``"(15) with eta = 1, ours"``)."""
    if op not in ("<=", ">="):
        raise ValueError(f"bound {name!r}: op must be '<=' or '>=', got {op!r}")
    got = _numbers(measured)
    ok = got is not None and all(math.isfinite(g) and (g <= limit if op == "<=" else g >= limit) for g in got)
    rule = f"{op} {_fmt(float(limit))}{(' ' + unit) if unit else ''} ({basis})"
    return _record(name, source, limit, measured, rule, "met" if ok else "not met", variant, note, context)


def statement(name: str, source: str, paper: Any, measured: Any, holds: bool, *, rule: str,
              variant: str = OURS, note: str | None = None, **context: Any) -> dict[str, Any]:
    """The paper states a checkable fact (``paper``, e.g. 0 collisions); ``holds``: it does here."""
    return _record(name, source, paper, measured, rule, "met" if holds else "not met", variant, note,
                   context)


def no_value(name: str, source: str, measured: Any, *, ours: str | None = None, variant: str = OURS,
             note: str | None = None, **context: Any) -> dict[str, Any]:
    """The paper gives no value: reported (with ``ours``, our own test and its outcome, if any),
    never met, never gating."""
    rule = NO_VALUE + (f"; our test: {ours}" if ours else "")
    return _record(name, source, None, measured, rule, NO_VALUE, variant, note, context)


def departure(name: str, paper: Any, ours: Any, why: str, effect: str, *,
              fields: Iterable[str] = (), source: str | None = None) -> dict[str, Any]:
    """A setting where the run differs from the paper (``paper``: its value or :data:`NOT_STATED`)."""
    for key, val in (("name", name), ("why", why), ("effect", effect)):
        if not isinstance(val, str) or not val:
            raise TypeError(f"departure {name!r}: {key} must be a non-empty str, got {val!r}")
    rec = {"name": name, "paper": _plain(paper), "ours": _plain(ours), "why": why, "effect": effect,
           "fields": list(fields)}
    if source is not None:
        rec["source"] = source
    return rec


def against_our_design(record: dict[str, Any], design: str) -> dict[str, Any]:
    """A claim that compares with a design of ours the paper does not give (``design``, e.g. our
    APF): it says how the two designs compare here, not whether the paper reproduces, so it is
    reported in its own section (``against_our_design``) and never gates."""
    if not isinstance(design, str) or not design:
        raise TypeError(f"claim {record.get('claim')!r}: design must name our design, got {design!r}")
    return {**record, "against_our_design": design, "gating": False}


def paper_claims(claims: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims judged against the paper alone (those of :func:`against_our_design` left out)."""
    return [c for c in claims if not c.get("against_our_design")]


def design_comparisons(claims: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims that compare with a design of ours (:func:`against_our_design`)."""
    return [c for c in claims if c.get("against_our_design")]


def gating(claims: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The claims that decide the exit code: paper-valued claims of our default run."""
    return [c for c in claims if c.get("gating")]


def passed(result: dict[str, Any]) -> bool:
    """True when the result has at least one gating claim and every one is met."""
    gate = gating(result.get("claims", []))
    return bool(gate) and all(c["met"] for c in gate)


def count(claims: Iterable[dict[str, Any]]) -> dict[str, int]:
    """Claims per status, and the gating ones met / total."""
    claims = list(claims)
    out = {s: sum(c["status"] == s for c in claims) for s in STATUSES}
    gate = gating(claims)
    out.update(gating=len(gate), gating_met=sum(c["met"] for c in gate))
    return out


def changed_claims(base: Iterable[dict[str, Any]], other: Iterable[dict[str, Any]],
                   key: str = "claim") -> list[str]:
    """Names (``key``) of the claims whose status differs between two lists of records."""
    before = {c[key]: c["status"] for c in base}
    return [c[key] for c in other if c[key] in before and before[c[key]] != c["status"]]


def _plain(v: Any) -> Any:
    if hasattr(v, "tolist"):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, float) and not math.isfinite(v):
        return None
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


def _verdict(claims: list[dict[str, Any]]) -> str:
    n = count(claims)
    return (f"paper-valued claims of our run: {n['gating_met']} of {n['gating']} met -> "
            f"{'PASS' if n['gating'] and n['gating_met'] == n['gating'] else 'FAIL'}; "
            f"all rows: {n['met']} met, {n['not met']} not met, {n[NO_VALUE]} without a paper value")


def format_claims(claims: Iterable[dict[str, Any]]) -> str:
    """The claims as plain-text lines ``claim | variant | paper | measured | rule | status``."""
    claims = list(claims)
    width = max((len(c["claim"]) for c in claims), default=5)
    lines = [f"{'claim':<{width}} | {'variant':<12} | {'paper':>12} | {'measured':>12} | rule | status"]
    for c in claims:
        lines.append(f"{c['claim']:<{width}} | {c['variant']:<12} | {_fmt(c['paper']):>12} | "
                     f"{_fmt(c['measured']):>12} | {c['rule']} | "
                     f"{c['status'].upper() if c['status'] == 'not met' else c['status']}")
    lines.append(_verdict(claims))
    return "\n".join(lines)


def _cell(v: Any) -> str:
    text = _fmt(v) if not isinstance(v, str) else v
    return text.replace("|", "\\|").replace("\n", " ")


def _status(c: dict[str, Any]) -> str:
    return {"met": "met", "not met": "**not met**"}.get(c["status"], "*" + NO_VALUE + "*")


def markdown_claims(claims: Iterable[dict[str, Any]], verdict: bool = True) -> str:
    """A Markdown table of claims: claim, run, the paper's sentence, its value, rule, measured, status
    (``verdict``: followed by the verdict line of these claims)."""
    rows = ["| claim | run | the paper says | paper | rule | measured | status |", "|---|---|---|---|---|---|---|"]
    for c in claims:
        rows.append(f"| {_cell(c['claim'])} | {_cell(c['variant'])} | \u201c{_cell(c['source'])}\u201d | "
                    f"{_cell(c['paper'])} | {_cell(c['rule'])} | {_cell(c['measured'])} | {_status(c)} |")
    return "\n".join(rows) + ("\n\n" + _verdict(list(claims)) + "." if verdict else "")


def markdown_departures(departures: Iterable[dict[str, Any]]) -> str:
    """A Markdown table of departures: setting, the paper's value, ours, why, measured effect."""
    rows = ["| setting | paper | ours | why | measured effect on the claims |", "|---|---|---|---|---|"]
    for d in departures:
        rows.append(f"| {_cell(d['name'])} | {_cell(d['paper'])} | {_cell(d['ours'])} | {_cell(d['why'])} "
                    f"| {_cell(d['effect'])} |")
    return "\n".join(rows)


def markdown_rows(result: dict[str, Any]) -> list[str]:
    """README claim-table rows ``| paper | claim | run | paper value | measured | rule | status |``."""
    return [f"| {result.get('paper', '?')} | {_cell(c['claim'])} | {_cell(c['variant'])} | {_cell(c['paper'])} | "
            f"{_cell(c['measured'])} | {_cell(c['rule'])} | {_status(c)} |" for c in result.get("claims", [])]


def summary_rows(result: dict[str, Any]) -> list[str]:
    """README summary rows, one per run: ``| paper | run | paper-valued met | not met | no paper value |``;
    the not-met claims with measured and paper values."""
    rows = []
    for run in dict.fromkeys(c["variant"] for c in result.get("claims", [])):
        mine = [c for c in result["claims"] if c["variant"] == run]
        valued = [c for c in mine if c["status"] != NO_VALUE]
        bad = "; ".join(f"{c['claim']}: {_fmt(c['measured'])} (paper {_fmt(c['paper'])})"
                        for c in valued if not c["met"]) or "-"
        rows.append(f"| {result.get('paper', '?')} | {run}{' (gating)' if run == OURS else ''} | "
                    f"{sum(c['met'] for c in valued)}/{len(valued)} | {_cell(bad)} | "
                    f"{sum(c['status'] == NO_VALUE for c in mine)} |")
    return rows


def main(argv: list[str] | None = None) -> int:
    """Print the README table rows of reproduction JSON files (``--summary``: one row per run)."""
    from satenv.cliargs import new_parser

    parser = new_parser("python -m satenv.bench.claims", "Print the README claim-table rows of reproduction "
                        "result files (satenv reproduce writes them).")
    parser.add_argument("results", nargs="+", metavar="RESULT.json", help="reproduction result files")
    parser.add_argument("--summary", action="store_true", help="one row per run instead of one per claim")
    args = parser.parse_args(argv)
    tables = []
    for p in args.results:
        try:
            result = json.loads(Path(p).read_text())
        except (OSError, ValueError) as err:
            parser.error(f"RESULT.json {p!r}: expected a readable reproduction result file ({err})")
        if not isinstance(result, dict):
            parser.error(f"RESULT.json {p!r}: expected a JSON object with 'claims', got {type(result).__name__}")
        tables.append(result)
    if args.summary:
        print("| paper | run | paper-valued claims met | not met: measured (paper) | no paper value |")
        print("|---|---|---|---|---|")
    else:
        print("| paper | claim | run | paper value | measured | rule | status |")
        print("|---|---|---|---|---|---|---|")
    for result in tables:
        for row in (summary_rows(result) if args.summary else markdown_rows(result)):
            print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
