"""Executors: results in order whoever runs them, workers single-threaded, and none outlives its caller,
even a caller that lingers as a zombie nobody reaps."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from auvnav.errors import ConfigError
from auvnav.executor import DaskExecutor, LocalExecutor, SerialExecutor, chunks, make_executor


def _square_plus_pid(offset: int, chunk: list[int]) -> list[tuple[int, int]]:
    return [(offset + x * x, os.getpid()) for x in chunk]


@pytest.mark.parametrize("make", [SerialExecutor, lambda: LocalExecutor(2), lambda: DaskExecutor("local:2")])
def test_results_come_back_in_order_whoever_runs_them(make) -> None:
    items = chunks(list(range(23)), 4)
    with make() as executor:
        results = [r for out in executor.map(_square_plus_pid, 1, items) for r in out]
    assert [value for value, _ in results] == [1 + x * x for x in range(23)]
    pids = {pid for _, pid in results}
    assert (os.getpid() in pids) == isinstance(executor, SerialExecutor)


def test_make_executor_reads_the_options() -> None:
    assert isinstance(make_executor(workers=1), SerialExecutor)
    with pytest.raises(ConfigError, match="local:N"):
        make_executor("local:zero")
    with pytest.raises(ConfigError, match="not both"):
        make_executor("local:2", workers=2)


# A caller that starts two workers busy for a minute, prints their PIDs, and waits.
CALLER = """
import threading, time
from auvnav.executor import LocalExecutor

def busy(ctx, chunk):
    time.sleep(60)
    return chunk

if __name__ == "__main__":
    executor = LocalExecutor(2)
    threading.Thread(target=lambda: list(executor.map(busy, None, [[1], [2], [3], [4]])), daemon=True).start()
    while len(executor.pids) < 2:
        time.sleep(0.05)
    print(*executor.pids, flush=True)
    time.sleep(60)
"""


def _running(pid: int) -> bool:
    """Alive and not a zombie."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_workers_exit_when_their_caller_dies_even_unreaped(how) -> None:
    """The caller is killed and not reaped (a zombie, as under a supervisor that reads its pipes first):
    its workers exit within a second all the same."""
    caller = subprocess.Popen([sys.executable, "-c", CALLER], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(p) for p in caller.stdout.readline().split()]
        assert len(workers) == 2 and all(_running(p) for p in workers)
        caller.send_signal(how)
        deadline = time.monotonic() + 5.0
        while any(_running(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _running(caller.pid)  # killed, not yet reaped: a zombie or gone
        assert not any(_running(p) for p in workers)
    finally:
        caller.kill()
        caller.wait()


# A caller that asks a worker how many threads its BLAS libraries use (NumPy's is loaded with OpenCV).
BLAS_THREADS = """
from threadpoolctl import threadpool_info
from auvnav.executor import LocalExecutor

def threads(ctx, chunk):
    return [lib["num_threads"] for lib in threadpool_info()]

if __name__ == "__main__":
    with LocalExecutor(1) as executor:
        print(*next(executor.map(threads, None, [[0]])))
"""


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS runs one thread anyway")
def test_workers_run_blas_on_one_thread(tmp_path) -> None:
    """Even when the environment leaves BLAS free to use every core (the tests limit it), as a user's
    shell does: two workers each with a threaded BLAS ran the verification six times slower."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    script = tmp_path / "blas_threads.py"  # a file: workers import its functions
    script.write_text(BLAS_THREADS, encoding="utf-8")
    out = subprocess.run(
        [sys.executable, str(script)], env=env, capture_output=True, text=True, check=True, timeout=60
    ).stdout.split()
    assert out and all(int(n) == 1 for n in out)
