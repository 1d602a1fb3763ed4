"""One check for the bit-for-bit kernel tests (not a pytest module): two cores' step results equal."""

from __future__ import annotations

from typing import Any

import numpy as np


def assert_same_step(got: Any, want: Any) -> None:
    """``got`` and ``want`` (``StepResult``s) hold the same infos (key order, dtypes, values),
    rewards and terminations, bit for bit."""
    assert list(got.info) == list(want.info)
    for key, val in want.info.items():
        assert got.info[key].dtype == val.dtype, key
        np.testing.assert_array_equal(got.info[key], val, err_msg=key)
    np.testing.assert_array_equal(got.rewards, want.rewards)
    np.testing.assert_array_equal(got.terminated, want.terminated)
