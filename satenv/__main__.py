"""``python -m satenv``: the ``satenv`` command (:mod:`satenv.cli`)."""

import sys

from satenv.cli import main

sys.exit(main())
