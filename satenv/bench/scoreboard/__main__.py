"""``python -m satenv.bench.scoreboard``: see :mod:`satenv.bench.scoreboard.cli`."""

import sys

from satenv.bench.scoreboard.cli import main

sys.exit(main())
