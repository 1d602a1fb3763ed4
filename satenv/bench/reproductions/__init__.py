"""The paper reproductions, one module per paper (``python -m satenv.bench.reproduce <paper>``).

Each module exposes ``reproduce(plots=None, seed=0, **options) -> dict`` and
``format_table(result) -> str`` (and optionally ``add_arguments(parser)`` and ``RUN_TIME``). A
result carries ``claims`` (:func:`satenv.bench.claims.claim` records: the paper's sentence, its
value, the rule, what we measured) and ``departures`` (:func:`satenv.bench.claims.departure`
records: every setting where the run differs from the paper, with its measured effect); the
reproduction pages render both (``docs/gen_reproductions.py``).
"""

from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[3]
"""The folder holding the ``satenv`` package (the repository in a source checkout)."""


def figure_paths(paths, plots: str | Path) -> list[str]:
    """The figure paths a result records: relative to the repository when they lie in it, else
    relative to the ``plots`` folder, so no result names the machine that wrote it."""
    out = []
    for p in map(Path, paths):
        full = p.resolve()
        base = REPOSITORY if full.is_relative_to(REPOSITORY) else Path(plots).resolve()
        out.append(full.relative_to(base).as_posix() if full.is_relative_to(base) else p.name)
    return out
