"""Executors for per-item work (rendering, features, verification): one protocol, three runners.

Per-item work is a function ``fn(context, chunk) -> list`` applied to chunks of items; an executor
maps it and gives the results back chunk by chunk, in order, whoever ran them (DESIGN section 9):

- :class:`SerialExecutor`: in this process (one worker, tests);
- :class:`LocalExecutor`: a pool of local processes, one per core by default;
- :class:`DaskExecutor`: a Dask ``distributed`` cluster, at an address (``tcp://host:8786``) or
  started here (``local:N``, a ``LocalCluster`` of N single-threaded worker processes). The files
  the work reads and writes (images, caches) must be on a file system every worker sees.

:func:`make_executor` turns a ``--scheduler`` option into one.

Local workers start from a clean single-threaded server process (the ``forkserver`` start method),
never by forking the caller: a caller that has used OpenCV or BLAS runs their thread pools, and a
child forked while one of those threads holds a lock waits on it for ever (observed:
``cv2.setNumThreads`` in a forked worker after ``cv2.stereoRectify`` in the parent). Each worker
(local or Dask) runs OpenCV and the BLAS behind NumPy on one thread (``threadpoolctl``), since the
executor already uses every core: with the BLAS's own threads, two workers' small matrix products
fought over the cores and the loop stage's verification ran six times slower (41 s against
236-276 s on the quick demo's check dive with its features cached). Local workers log their warnings
in their caller's format, since they do not inherit the caller's logging set-up.

A local worker exits as soon as its caller has gone, whatever killed it: it holds the reading end of
a pipe whose only writing end is the caller's, and the kernel closes that end when the caller exits,
even while it lingers as a zombie that no parent has reaped (asking whether the caller's PID exists,
as this module once did, takes a zombie for alive: a supervisor that reads the workers' pipes before
reaping then waits for ever). Dask's own worker processes watch their nanny the same way.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing.connection import Connection
from typing import Any, TypeVar

from auvnav.errors import ConfigError

log = logging.getLogger(__name__)

C = TypeVar("C")
T = TypeVar("T")
R = TypeVar("R")
Task = Callable[[Any, list[Any]], list[Any]]


def single_threaded() -> None:
    """Run OpenCV and the BLAS libraries of this process on one thread each."""
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    threadpool_limits(1)


def chunks(items: Sequence[T], size: int) -> list[list[T]]:
    """``items`` cut into lists of ``size`` (the last shorter)."""
    return [list(items[k : k + size]) for k in range(0, len(items), size)]


class Executor(ABC):
    """Maps ``fn(context, chunk)`` over chunks; results come back in chunk order."""

    #: Processes the work is spread over.
    workers: int = 1
    #: What runs the work, for messages: ``serial``, ``local``, ``dask local:2``, ``dask tcp://...``.
    name: str = ""

    @abstractmethod
    def map(self, fn: Task, context: Any, items: Sequence[list[Any]]) -> Iterator[list[Any]]:
        """Yield ``fn(context, chunk)`` for each chunk, in order."""

    @abstractmethod
    def close(self) -> None:
        """Release the workers (idempotent)."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialExecutor(Executor):
    """Everything in this process."""

    name = "serial"

    def map(self, fn: Task, context: Any, items: Sequence[list[Any]]) -> Iterator[list[Any]]:
        for chunk in items:
            yield fn(context, chunk)

    def close(self) -> None:
        pass


def _watch_caller(alive: Connection) -> None:
    """Block until the caller's end of the pipe closes, then exit at once."""
    try:
        alive.recv_bytes()
    except (EOFError, OSError):
        pass
    os._exit(1)


def _worker_init(level: int, log_format: str | None, alive: Connection) -> None:
    threading.Thread(target=_watch_caller, args=(alive,), daemon=True).start()
    single_threaded()
    handler = logging.StreamHandler(sys.stderr)
    if log_format is not None:
        handler.setFormatter(logging.Formatter(log_format))
    root = logging.getLogger()
    root.handlers = [handler]
    root.setLevel(max(level, logging.WARNING))


class LocalExecutor(Executor):
    """A pool of local worker processes (see the module docstring)."""

    name = "local"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        root = logging.getLogger()
        formatter = root.handlers[0].formatter if root.handlers else None
        log_format = getattr(formatter, "_fmt", None)  # the format, not the formatter (it may hold a stream)
        # The workers hold the reading end; the writing end never leaves this process.
        self._alive_r, self._alive_w = multiprocessing.Pipe(duplex=False)
        self._pool = ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=multiprocessing.get_context("forkserver"),
            initializer=_worker_init,
            initargs=(root.getEffectiveLevel(), log_format, self._alive_r),
        )

    def map(self, fn: Task, context: Any, items: Sequence[list[Any]]) -> Iterator[list[Any]]:
        futures = [self._pool.submit(fn, context, chunk) for chunk in items]
        try:
            for future in futures:
                yield future.result()
        finally:
            for future in futures:
                future.cancel()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._alive_w.close()
        self._alive_r.close()

    @property
    def pids(self) -> list[int]:
        """The worker processes started so far."""
        return list(self._pool._processes)


class DaskExecutor(Executor):
    """A Dask ``distributed`` cluster: ``local:N`` starts one here, anything else is its address."""

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError as err:  # pragma: no cover - a dependency of the package
            raise ConfigError(
                "--scheduler needs Dask's distributed package (pip install distributed)"
            ) from err
        self._cluster = None
        if address.startswith("local:"):
            text = address.removeprefix("local:")
            if not (text.isascii() and text.isdigit()) or int(text) < 1:
                raise ConfigError(f"--scheduler {address}: expected local:N with N a positive integer")
            self._cluster = LocalCluster(
                n_workers=int(text),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
            self._client = Client(self._cluster)
        else:
            try:
                self._client = Client(address, timeout="20s")
            except (OSError, TimeoutError, ValueError) as err:
                raise ConfigError(f"--scheduler {address}: cannot reach the Dask scheduler ({err})") from err
        self._client.run(single_threaded)
        self.workers = max(1, len(self._client.scheduler_info()["workers"]))
        self.name = f"dask {address}"

    def map(self, fn: Task, context: Any, items: Sequence[list[Any]]) -> Iterator[list[Any]]:
        shared = self._client.scatter(context, broadcast=True)
        futures = [self._client.submit(fn, shared, chunk, pure=False) for chunk in items]
        try:
            for future in futures:
                yield future.result()
        finally:
            self._client.cancel(futures)

    def close(self) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(scheduler: str | None = None, workers: int | None = None) -> Executor:
    """The executor a command's ``--scheduler`` and ``--workers`` options ask for.

    Parameters
    ----------
    scheduler : str, optional
        None: local processes; ``local:N``: a Dask ``LocalCluster`` of N workers; else the address
        of a running Dask scheduler.
    workers : int, optional
        Local processes (None: one per core; 1: in this process). Not with ``scheduler``.
    """
    if scheduler:
        if workers is not None:
            raise ConfigError("give --workers or --scheduler, not both")
        return DaskExecutor(scheduler)
    if workers is not None and workers < 1:
        raise ConfigError(f"--workers must be at least 1; found {workers}")
    return SerialExecutor() if workers == 1 else LocalExecutor(workers)
