"""Process pools: workers single-threaded, and none outlives its caller."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from auvnav.parallel import CALLER_POLL_S

# A caller that starts two workers busy for a minute, prints their PIDs, and waits.
CALLER = """
import time
from auvnav.parallel import process_pool

if __name__ == "__main__":
    pool = process_pool(2)
    futures = [pool.submit(time.sleep, 60) for _ in range(4)]
    while len(pool._processes) < 2:
        time.sleep(0.05)
    print(*pool._processes, flush=True)
    time.sleep(60)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_workers_exit_when_their_caller_is_killed() -> None:
    """SIGTERM cannot be caught by a caller busy in a pool; its workers must not live on."""
    caller = subprocess.Popen([sys.executable, "-c", CALLER], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(p) for p in caller.stdout.readline().split()]
        assert len(workers) == 2 and all(_alive(p) for p in workers)
        caller.send_signal(signal.SIGTERM)
        caller.wait(timeout=10)
        deadline = time.monotonic() + 5 * CALLER_POLL_S + 5
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(p) for p in workers)
    finally:
        caller.kill()


# A caller that asks a worker how many threads its BLAS libraries use (NumPy's is loaded with OpenCV).
BLAS_THREADS = """
from threadpoolctl import threadpool_info
from auvnav.parallel import process_pool

if __name__ == "__main__":
    with process_pool(1) as pool:
        print(*(lib["num_threads"] for lib in pool.submit(threadpool_info).result()))
"""


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS runs one thread anyway")
def test_workers_run_blas_on_one_thread() -> None:
    """Even when the environment leaves BLAS free to use every core (the tests limit it), as a user's
    shell does: two workers each with a threaded BLAS ran the verification six times slower."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    out = subprocess.run(
        [sys.executable, "-c", BLAS_THREADS], env=env, capture_output=True, text=True, check=True, timeout=60
    ).stdout.split()
    assert out and all(int(n) == 1 for n in out)
