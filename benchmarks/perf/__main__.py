"""``python -m benchmarks.perf``."""

from benchmarks.perf import main

main()
