"""A node's worker process ends with the node, even when the node is killed (SIGKILL cannot be
caught, so the node cannot terminate it): otherwise the worker waits for tasks forever and holds the
node's output pipe open, and whoever reads that pipe to the end (a supervisor, a test) blocks."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from shm_ros.ros.supervisor import stop_process

NODE = r"""
import os, time
from shm_ros.ros.worker_pool import WorkerPool
pool = WorkerPool(time.sleep, (0,), os.getpid)
print(pool.submit(os.getpid).result(timeout=120), flush=True)
time.sleep(600)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _node() -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen([sys.executable, "-c", NODE], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    worker = int(proc.stdout.readline())
    assert worker != proc.pid and _alive(worker)
    return proc, worker


def test_worker_ends_with_a_killed_node() -> None:
    proc, worker = _node()
    os.kill(proc.pid, signal.SIGKILL)
    out, _ = proc.communicate(timeout=20)  # returns only once the worker has closed the pipe
    assert proc.returncode == -signal.SIGKILL and out == ""
    end = time.monotonic() + 10
    while _alive(worker) and time.monotonic() < end:
        time.sleep(0.1)
    assert not _alive(worker), "the worker outlived its killed node"


def test_stop_of_a_node_deaf_to_sigint_returns() -> None:
    proc, worker = _node()
    start = time.monotonic()
    proc.send_signal(signal.SIGSTOP)  # a node too busy to act on SIGINT: stop_process must kill it
    code, _ = stop_process(proc, timeout=3.0)
    assert code == -9 and time.monotonic() - start < 20
