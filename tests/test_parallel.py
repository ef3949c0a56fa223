"""Process pools: no worker outlives its caller."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

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
