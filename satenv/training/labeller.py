"""Expert labels in parallel: a process pool across DAgger episodes (:class:`ExpertPool`).

Each worker keeps its env and expert between calls (``satenv.baselines.experts.make``), and each episode
(:class:`LabelJob`) carries its own seed, so its labels do not depend on which worker ran it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from satenv.baselines.experts import make

__all__ = ["ExpertPool", "LabelJob", "label_episode"]


@dataclass(frozen=True)
class LabelJob:
    """One episode to fly and label (the arguments of ``satenv.training.imitation.collect_episode``).

    ``task`` is a :mod:`satenv.tasks` name (its env built with ``env_kwargs`` on top of the task's
    own), ``seed`` the episode's reset seed, ``beta`` the probability of flying the expert's action
    at a step (else the learner's: ``learner`` a policy folder, or ``None``), ``noise`` the std of the
    Gaussian noise on the flown action, ``rng`` the seed of the episode's own generator (the draws of
    ``beta`` and ``noise``): an episode's rows depend on its job alone, not on the worker or the
    order the pool runs it in.
    """

    task: str
    seed: int
    beta: float = 1.0
    noise: float = 0.0
    rng: int | tuple[int, ...] = 0
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    learner: str | None = None


_WORKER: dict[Any, Any] = {}     # per process: (task, env kwargs) -> env; expert and learner alike


def _worker_init(expert: str, options: dict[str, Any], warm: tuple[LabelJob, ...] = ()) -> None:
    """Pool initializer: one BLAS / torch thread per worker process, the expert's name; flies the
    ``warm`` jobs (builds their envs, experts and solvers in every worker)."""
    import os

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    _WORKER.clear()
    _WORKER["expert"] = (expert, dict(options))
    for job in warm:
        label_episode(job)


def label_episode(job: LabelJob) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Fly and label one episode in this process (the pool's worker; usable alone after
    :func:`_worker_init`): the env, the expert and the learner are built once per process and
    reused across its episodes (the expert resets itself at every episode)."""
    import json

    from satenv import tasks
    from satenv.training.imitation import collect_episode

    name, options = _WORKER["expert"]
    key = (job.task, json.dumps(job.env_kwargs, sort_keys=True))
    if key not in _WORKER:
        env = tasks.get(job.task).make_env(**job.env_kwargs)
        _WORKER[key] = (env, make(name, env, **options))
    env, expert = _WORKER[key]
    learner = None
    if job.learner is not None:
        if ("learner", job.learner) not in _WORKER:
            from satenv.training.policy import load

            _WORKER["learner", job.learner] = load(job.learner)
        learner = _WORKER["learner", job.learner]
    return collect_episode(env, expert, learner, job.seed, beta=job.beta, noise=job.noise,
                           rng=np.random.default_rng(job.rng))


def _ready(_: int) -> bool:
    return True


class ExpertPool:
    """A process pool that flies and labels DAgger episodes in parallel, one episode per task.

    Args:
        expert: the expert's registry name (:func:`make`), ``options`` its options.
        workers: processes (one core each: every worker runs single-threaded).
        warm: jobs every worker flies when it starts (their rows are dropped): short episodes of
            the tasks to come build the envs and the expert's solvers before the first call.

    ``pool.label(jobs)`` returns ``(rows, stats)`` per :class:`LabelJob` in the jobs' order; the
    workers keep their envs, experts (with their compiled solvers) and learners between calls, so
    use one pool for a whole run (``with ExpertPool(...) as pool``). An episode's rows are those of
    ``label_episode(job)`` in one process (``tests/test_fast_solvers.py``).
    """

    def __init__(self, expert: str, options: dict[str, Any] | None = None, workers: int = 2,
                 warm: tuple[LabelJob, ...] = ()) -> None:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
            raise ValueError(f"ExpertPool workers must be an int >= 1, got {workers!r}")
        self.workers = workers
        self._pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                         initializer=_worker_init,
                                         initargs=(expert, dict(options or {}), tuple(warm)))
        for _ in self._pool.map(_ready, range(workers)):   # start every worker (and its warm-up) now
            pass

    def label(self, jobs: list[LabelJob]) -> list[tuple[dict[str, np.ndarray], dict[str, Any]]]:
        """Fly and label ``jobs`` on the workers (longest first is the caller's choice of order)."""
        for job in jobs:
            if not isinstance(job, LabelJob):
                raise TypeError(f"ExpertPool.label takes LabelJob items, got {type(job).__name__}")
        return list(self._pool.map(label_episode, jobs))

    def close(self) -> None:
        """Stop the workers."""
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ExpertPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
