"""The exceptions satenv raises for bad input (a leaf module: it imports nothing from satenv).

Catch :class:`SatenvError` to catch every rejected input: a wrong value is a ``SatenvError``
(a ``ValueError``); a value of the wrong kind (a string, a bool or a complex number where a real
number is meant, a masked array) is a :class:`SatenvTypeError`, which is a ``TypeError`` and,
so that one ``except`` serves both, also a ``SatenvError``.
"""

from __future__ import annotations

__all__ = ["SatenvError", "SatenvTypeError"]


class SatenvError(ValueError):
    """Bad input to satenv (a ``ValueError``): the message names the field, the value received
    and what is expected."""


class SatenvTypeError(SatenvError, TypeError):
    """Input of the wrong type (a ``TypeError``, and a :class:`SatenvError`)."""
