"""Process settings shared by the benchmark command lines (called from their ``main``, never at
import)."""

from __future__ import annotations

import os

BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_thread_blas() -> None:
    """One BLAS thread per process (fair, stable timings): sets :data:`BLAS_THREAD_VARS` to 1
    unless the user set them. It holds for processes started afterwards, and for this one only if
    numpy's BLAS is not loaded yet, so command lines call it first thing."""
    for var in BLAS_THREAD_VARS:
        os.environ.setdefault(var, "1")
