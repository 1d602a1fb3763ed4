"""satenv: multi-agent spacecraft formation-flying environments and baselines."""

__version__ = "0.1.0"
