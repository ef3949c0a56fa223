"""Process pools for the per-image and per-pair work (rendering, features, verification).

Workers start from a clean single-threaded server process (the ``forkserver`` start method), never by
forking the caller: a caller that has used OpenCV or BLAS runs their thread pools, and a child forked
while one of those threads holds a lock waits on it for ever (observed: ``cv2.setNumThreads`` in a
forked worker after ``cv2.stereoRectify`` in the parent). Each worker runs OpenCV on one thread, since
the pool already uses every core.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import cv2


def _single_threaded() -> None:
    cv2.setNumThreads(1)


def process_pool(workers: int | None = None) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes (None: one per core), safe to start from a threaded caller."""
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("forkserver"),
        initializer=_single_threaded,
    )
