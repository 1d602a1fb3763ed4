"""Where episodes run: in this process, in a pool of worker processes, or on Ray.

Episodes are deterministic given their key, so a backend only changes *where* they run: the
records equal a serial run's except the measured times. Each backend is an iterator of records
in completion order.

Worker processes (``--workers K``, spawn start method) are tied to the board: they run with one
BLAS thread, die with the parent (``prctl(PR_SET_PDEATHSIG, SIGKILL)`` on Linux, plus a thread
that polls the parent's pid on every platform), and a worker that dies takes only its episode
with it: the pool is rebuilt, the episodes that were running are retried one at a time, and an
episode whose worker dies again is recorded as an error.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from satenv.bench._env import single_thread_blas
from satenv.bench.scoreboard.runner import Job, error_record, run_episode
from satenv.bench.scoreboard.specs import ScoreboardError

__all__ = ["iter_pool", "iter_ray", "iter_serial", "stream", "worker_init"]

PARENT_POLL_S = 0.5
Record = dict[str, Any]
Run = Callable[[Any], Record]
"""What a backend runs on each job (default :func:`~satenv.bench.scoreboard.runner.run_episode`;
another grid passes its own picklable top-level function, e.g. ``satenv.bench.learning``'s)."""
Lost = Callable[[Any, str], Record]
"""The record of a job whose worker died (default :func:`~satenv.bench.scoreboard.runner.error_record`)."""


def iter_serial(jobs: list[Job], run: Run = run_episode) -> Iterator[Record]:
    for job in jobs:
        yield run(job)


# ----------------------------------------------------------------------------------------------
# Worker processes that die with the board.
# ----------------------------------------------------------------------------------------------
def _set_parent_death_signal() -> None:
    """Linux: the kernel sends SIGKILL to this process when its parent dies."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)   # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass   # the polling thread still covers it


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def worker_init(parent: int) -> None:
    """Pool worker initialiser: one BLAS thread; exit when the process ``parent`` is gone."""
    single_thread_blas()
    _set_parent_death_signal()
    if os.getppid() != parent:           # the parent died before the signal was armed
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="parent-watch").start()


def _new_pool(workers: int) -> ProcessPoolExecutor:
    import multiprocessing as mp

    return ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                               initializer=worker_init, initargs=(os.getpid(),))


class _Pool:
    """A process pool with at most ``workers`` episodes in flight, rebuilt when a worker dies."""

    def __init__(self, jobs: list[Job], workers: int, run: Run = run_episode, lost: Lost = error_record) -> None:
        self.workers, self.run, self.lost = workers, run, lost
        self.pending: deque[Job] = deque(jobs)
        self.suspects: deque[Job] = deque()      # in flight when a worker died: rerun alone
        self.inflight: dict[Future, tuple[Job, bool]] = {}
        self.pool = _new_pool(workers)

    def _submit(self, queue: deque[Job], alone: bool) -> bool:
        """Start the next job of ``queue``; False (job kept) if the pool broke meanwhile."""
        try:
            fut = self.pool.submit(self.run, queue[0])
        except BrokenProcessPool:   # a worker died after the last collect: rebuild first
            return False
        self.inflight[fut] = (queue.popleft(), alone)
        return True

    def fill(self) -> None:
        if self.suspects:
            if not self.inflight:
                self._submit(self.suspects, alone=True)
            return
        while self.pending and len(self.inflight) < self.workers:
            if not self._submit(self.pending, alone=False):
                return

    def collect(self) -> Iterator[Record]:
        """Wait for at least one episode; yield the finished records, handle a broken pool."""
        if not self.inflight:       # nothing could be submitted: the pool is broken
            yield from self._rebuild()
            return
        done, _ = wait(self.inflight, return_when=FIRST_COMPLETED)
        broken = False
        for fut in done:
            job, alone = self.inflight.pop(fut)
            try:
                yield fut.result()
            except BrokenProcessPool:
                broken = True
                yield from self._lost(job, alone)
        if broken:
            yield from self._rebuild()

    def _lost(self, job: Job, alone: bool) -> Iterator[Record]:
        if alone:   # died again, running alone: this episode kills its worker
            yield self.lost(job, "WorkerDied: the worker process running this episode died "
                                     "(killed, or crashed in native code) twice, the second time alone")
        else:
            self.suspects.append(job)

    def _rebuild(self) -> Iterator[Record]:
        for job, alone in list(self.inflight.values()):
            yield from self._lost(job, alone)
        self.inflight.clear()
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.pool = _new_pool(self.workers)

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


def iter_pool(jobs: list[Job], workers: int, run: Run = run_episode, lost: Lost = error_record
              ) -> Iterator[Record]:
    """Records of ``jobs`` run on ``workers`` spawn processes (see the module docstring)."""
    pool = _Pool(jobs, workers, run, lost)
    try:
        while pool.pending or pool.suspects or pool.inflight:
            pool.fill()
            yield from pool.collect()
    finally:
        pool.close()


# ----------------------------------------------------------------------------------------------
# Ray.
# ----------------------------------------------------------------------------------------------
def _ray_init(workers: int, address: str | None):
    try:
        import ray
    except ModuleNotFoundError as exc:
        if exc.name != "ray":
            raise
        raise ScoreboardError("--backend ray needs Ray: pip install 'satenv[rllib]' (or ray)") from None
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    return ray


def iter_ray(jobs: list[Job], workers: int, address: str | None, run: Run = run_episode) -> Iterator[Record]:
    """Records of ``jobs`` run as Ray tasks (a local Ray, or the cluster at ``address``)."""
    ray = _ray_init(workers, address)
    remote = ray.remote(num_cpus=1)(run)
    pending = [remote.remote(t) for t in jobs]
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        for ref in pending:
            ray.cancel(ref)


def stream(jobs: list[Job], backend: str, workers: int, ray_address: str | None, run: Run = run_episode,
           lost: Lost = error_record) -> Iterator[Record]:
    """The records of ``jobs`` from the chosen backend (``run`` on each job; ``lost`` for a job
    whose worker died twice)."""
    if backend == "ray":
        return iter_ray(jobs, workers, ray_address, run)
    if workers > 1 and len(jobs) > 1:
        return iter_pool(jobs, workers, run, lost)
    return iter_serial(jobs, run)
