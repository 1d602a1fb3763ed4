"""The paper reproductions, one module per paper (``python -m satenv.bench.reproduce <paper>``).

Each module exposes ``reproduce(plots=None, seed=0, **options) -> dict`` and
``format_table(result) -> str`` (and optionally ``add_arguments(parser)`` and ``RUN_TIME``). A
result carries ``claims`` (:func:`satenv.bench.claims.claim` records: the paper's sentence, its
value, the rule, what we measured) and ``departures`` (:func:`satenv.bench.claims.departure`
records: every setting where the run differs from the paper, with its measured effect); the
reproduction pages render both (``docs/gen_reproductions.py``).
"""
