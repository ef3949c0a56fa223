"""What a benchmark's process tree uses, on Linux: every descendant of a process (the forkserver's pool
workers are not children that ``getrusage`` would see), the peak of their summed resident sets, and
their CPU time. Shared by the benchmark scripts (run as ``python benchmarks/bench_x.py``, so this
module is importable beside them)."""

from __future__ import annotations

import os
import threading
from pathlib import Path


def descendants(pid: int) -> list[int]:
    """``pid`` and all its descendants now (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo += children.get(p, [])
    return out


class TreeUsage:
    """This process and every descendant: the peak of their summed resident sets (sampled every
    ``period_s``) and their user + system CPU seconds so far (:meth:`cpu_s`: the live processes read
    now, those that have exited as last sampled)."""

    def __init__(self, period_s: float = 0.2) -> None:
        self.peak_mib = 0.0
        self._period_s = period_s
        self._ticks: dict[int, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)

    def __enter__(self) -> TreeUsage:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    def _read(self) -> float:
        """Update each process's CPU ticks; the tree's summed resident set now, MiB."""
        page_mib = os.sysconf("SC_PAGE_SIZE") / 2**20
        total = 0.0
        for pid in descendants(os.getpid()):
            try:
                rss = int(Path(f"/proc/{pid}/statm").read_text().split()[1]) * page_mib
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            total += rss
            self._ticks[pid] = max(self._ticks.get(pid, 0), int(fields[11]) + int(fields[12]))
        return total

    def cpu_s(self) -> float:
        """User and system CPU seconds of the tree so far."""
        self._read()
        return sum(self._ticks.values()) / os.sysconf("SC_CLK_TCK")

    def _sample(self) -> None:
        while not self._stop.wait(self._period_s):
            self.peak_mib = max(self.peak_mib, self._read())
