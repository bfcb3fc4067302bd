"""Per-clip data work of the hit-event models (simulation, degradation, pose noise, features) on several
CPU cores.

``map_clips(job, n, workers)`` returns ``[job(0), ..., job(n - 1)]``. With ``workers > 1`` the indices are
split into chunks run by forked processes, which inherit ``job`` and everything it reads (no pickling of
the inputs; only the results travel back, so jobs should return small things: features, tracks). A job
draws its randomness from its index alone (one generator per clip, :func:`clip_rngs`), so the result is the
same for any number of workers. Where ``fork`` is unavailable (Windows) the work runs in this process.

Example:
    >>> rngs = clip_rngs(seed, len(clips))
    >>> tracks = map_clips(lambda k: degrade(clips[k], rngs[k], cfg).track, len(clips), workers=8)
"""
from __future__ import annotations

import logging
import multiprocessing as mp
import signal
from collections.abc import Callable
from typing import TypeVar

import numpy as np

log = logging.getLogger(__name__)
T = TypeVar("T")
_JOB: Callable[[int], object] | None = None  # the job of the pool being run (inherited by the forked workers)


def clip_rngs(seed: int, n: int) -> list[np.random.Generator]:
    """One independent generator per clip; the same ``seed`` gives the same generators."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(n)]


def _worker_init() -> None:
    """A worker leaves signals to the parent: the parent's handlers (Lightning's SIGTERM, a training run's
    Ctrl-C) are not inherited, so the pool's own shutdown and the user's interrupt behave as usual."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_chunk(idx: np.ndarray) -> list:
    assert _JOB is not None, "map_clips: a worker started without a job"
    return [_JOB(int(k)) for k in idx]


def can_fork() -> bool:
    """Whether worker processes can be forked here."""
    return "fork" in mp.get_all_start_methods()


def map_clips(job: Callable[[int], T], n: int, workers: int = 0) -> list[T]:
    """``[job(k) for k in range(n)]``, in ``workers`` forked processes when ``workers > 1``.

    ``job`` must not use torch's or CUDA's state (the workers are forks); its results are pickled back."""
    global _JOB
    workers = min(int(workers or 0), n)
    if workers <= 1 or not can_fork():
        return [job(k) for k in range(n)]
    if _JOB is not None:  # a job inside a job (never in this project): no nested pools
        return [job(k) for k in range(n)]
    _JOB = job
    try:
        chunks = np.array_split(np.arange(n), min(n, workers * 4))
        pool = mp.get_context("fork").Pool(workers, initializer=_worker_init)
        try:
            parts = pool.map(_run_chunk, chunks)
            pool.close()  # the workers finish and exit on their own
        except BaseException:
            pool.terminate()
            raise
        finally:
            pool.join()
    finally:
        _JOB = None
    return [r for part in parts for r in part]
