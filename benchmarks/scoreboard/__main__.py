"""``python -m benchmarks.scoreboard``: see :mod:`benchmarks.scoreboard.cli`."""

import sys

from benchmarks.scoreboard.cli import main

sys.exit(main())
