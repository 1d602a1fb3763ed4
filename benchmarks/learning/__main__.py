"""``python -m benchmarks.learning`` (:mod:`benchmarks.learning.cli`)."""

import sys

from benchmarks.learning.cli import main

sys.exit(main())
