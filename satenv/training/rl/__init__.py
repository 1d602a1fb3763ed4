"""The lean batched learners over ``satenv.make_vec`` arrays (no per-agent Python, torch on one thread).

* :mod:`satenv.training.rl.ppo` — PPO with the IPPO / MAPPO variants (``satenv ppo``,
  ``python -m satenv.training.rl.ppo``); writes the same policy folder as every other trainer.
* :mod:`satenv.training.rl.nets` — its networks (shared or per-agent weights in one matmul per layer).
* ``tuned/<task>.json`` — configurations tuned on validation seeds (``--tuned``).
"""

from __future__ import annotations

__all__ = ["LeanConfig", "main", "train"]


def __getattr__(name: str):
    if name in __all__:   # torch is imported on demand
        from satenv.training.rl import ppo

        return getattr(ppo, name)
    raise AttributeError(f"module 'satenv.training.rl' has no attribute {name!r}")
