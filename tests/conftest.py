"""Shared test fixtures."""

import multiprocessing

import pytest


@pytest.fixture(autouse=True)
def _keep_multiprocessing_start_method():
    """Importing torchrl sets the process-wide start method to 'spawn'; restore it after the test
    so later tests (the scoreboard's worker processes) run as in a fresh process. Modules that
    need torchrl import it inside their tests, not at collection."""
    before = multiprocessing.get_start_method(allow_none=True)
    yield
    if multiprocessing.get_start_method(allow_none=True) != before:
        multiprocessing.set_start_method(before, force=True)
