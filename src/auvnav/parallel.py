"""Process pools for the per-image and per-pair work (rendering, features, verification).

Workers start from a clean single-threaded server process (the ``forkserver`` start method), never by
forking the caller: a caller that has used OpenCV or BLAS runs their thread pools, and a child forked
while one of those threads holds a lock waits on it for ever (observed: ``cv2.setNumThreads`` in a
forked worker after ``cv2.stereoRectify`` in the parent). Each worker runs OpenCV and the BLAS behind
NumPy on one thread (``threadpoolctl``), since the pool already uses every core: with the BLAS's own
threads, two workers' small matrix products fought over the cores and the loop stage's verification ran
six times slower (the quick demo's check dive with its features cached: 41 s against 236-276 s).
Workers log their warnings in their caller's format, since they do not inherit the caller's logging
set-up (information from workers, such as libraries announcing their thread counts, is left out). A
worker also exits when its caller has gone: a caller killed by a
signal it cannot catch (SIGTERM, SIGKILL) leaves its workers behind otherwise, each holding its memory
(and its share of the pool's pipes, so that the server process lives on too) for ever.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor

import cv2
from threadpoolctl import threadpool_limits

CALLER_POLL_S = 1.0  # how often a worker checks that its caller is alive


def _exit_with(caller_pid: int) -> None:
    """Exit this process as soon as ``caller_pid`` no longer exists."""
    while True:
        time.sleep(CALLER_POLL_S)
        try:
            os.kill(caller_pid, 0)
        except ProcessLookupError:
            os._exit(1)


def _worker_init(level: int, formatter: logging.Formatter | None, caller_pid: int) -> None:
    threading.Thread(target=_exit_with, args=(caller_pid,), daemon=True).start()
    cv2.setNumThreads(1)
    threadpool_limits(1)
    handler = logging.StreamHandler(sys.stderr)
    if formatter is not None:
        handler.setFormatter(formatter)
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(max(level, logging.WARNING))


def process_pool(workers: int | None = None) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes (None: one per core), safe to start from a threaded caller."""
    root = logging.getLogger()
    formatter = root.handlers[0].formatter if root.handlers else None
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("forkserver"),
        initializer=_worker_init,
        initargs=(root.getEffectiveLevel(), formatter, os.getpid()),
    )
