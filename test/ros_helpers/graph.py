"""Start real node processes for tests and stop them the way a user does (SIGINT)."""

from __future__ import annotations

import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from shm_ros.ros.supervisor import node_process, stop_process  # noqa: F401 (re-exported)


def stop(proc: subprocess.Popen, timeout: float = 20.0) -> tuple[int, str]:
    return stop_process(proc, timeout)


@contextmanager
def running(*procs: subprocess.Popen, settle_s: float = 1.5):
    time.sleep(settle_s)
    results: dict[int, tuple[int, str]] = {}
    try:
        yield results
    finally:
        for p in procs:
            results[p.pid] = stop(p)


def replay(bag: Path, *extra: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "shm_ros.cli", "replay", str(bag), *extra],
                          capture_output=True, text=True, timeout=timeout)


def recorded_windows(bag: Path) -> list:
    from shm_ros.io.bags import read_messages

    out = []
    for m in read_messages(bag):
        if m.topic == "/shm/windows":
            w = m.decode()
            n, c = int(w.n_samples), len(w.channel_names)
            out.append((w, np.asarray(w.samples).reshape(n, c)))
    return out
