"""``python -m satenv.bench.learning`` (:mod:`satenv.bench.learning.cli`)."""

import sys

from satenv.bench.learning.cli import main

sys.exit(main())
