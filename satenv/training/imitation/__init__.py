"""Imitation: DAgger of an expert and its safe variants, one resumable rounds loop.

* :mod:`~satenv.training.imitation.config`: :class:`ImitationConfig` (every option, validated);
* :mod:`~satenv.training.imitation.collect`: :func:`collect_episode`, flying and labelling an episode;
* :mod:`~satenv.training.imitation.barrier`: the safety filter's rows as a differentiable barrier;
* :mod:`~satenv.training.imitation.fit`: the DAgger regression and the safe loss;
* :mod:`~satenv.training.imitation.rounds`: :func:`run`, the rounds loop over a crash-safe run folder;
* :mod:`~satenv.training.imitation.folder`: the run folder's files, read as untrusted data;
* :mod:`~satenv.training.imitation.ship`: choosing a round on validation seeds and shipping it;
* :mod:`~satenv.training.imitation.cli`: ``satenv imitate``.
"""

from __future__ import annotations

from satenv.training.imitation.collect import collect_episode
from satenv.training.imitation.config import ImitationConfig, system_config
from satenv.training.imitation.rounds import run

__all__ = ["ImitationConfig", "collect_episode", "run", "system_config"]
