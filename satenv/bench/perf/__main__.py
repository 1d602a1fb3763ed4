"""``python -m satenv.bench.perf``."""

from satenv.bench.perf import main

if __name__ == "__main__":   # the expert pools spawn workers that import this module again
    main()
