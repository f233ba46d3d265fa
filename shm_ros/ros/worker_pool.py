"""One worker process for a node's long work (sampling, prediction, explanation).

Long, Python-bound work in the node's own process would hold the GIL and stall its executor; in a
process of its own it does not, and the node can stop it at once (terminate). The process is
spawned, not forked: the node's process runs DDS threads, which a forked child would inherit dead.
A worker ends with its node: if the node is killed (SIGKILL, out of memory) it cannot terminate the
worker, which would otherwise wait for tasks forever and keep the node's stdout pipe open.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

PARENT_CHECK_S = 0.5


def _exit_with_parent(parent: int) -> None:
    # polling, not prctl(PR_SET_PDEATHSIG): that signal follows the thread that spawned the worker,
    # which for a process pool can be any thread of the node
    while os.getppid() == parent:
        time.sleep(PARENT_CHECK_S)
    os._exit(1)


def _guarded_init(parent: int, init: Callable[..., None], initargs: tuple) -> None:
    threading.Thread(target=_exit_with_parent, args=(parent,), name="parent-watch", daemon=True).start()
    init(*initargs)


class WorkerPool:
    """A single-process pool started at once (``ready`` is submitted first), restartable."""

    def __init__(self, initializer: Callable[..., None], initargs: tuple, ready: Callable[[], Any]) -> None:
        self._init, self._initargs, self._ready = initializer, initargs, ready
        self._workers: set[multiprocessing.process.BaseProcess] = set()
        self.pool = self._new()

    def _new(self) -> ProcessPoolExecutor:
        pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_guarded_init,
                                   initargs=(os.getpid(), self._init, self._initargs))
        self._submit(pool, self._ready)  # start the process now, not at the first task
        return pool

    def _submit(self, pool: ProcessPoolExecutor, fn: Callable[..., Any], *args: Any) -> Future:
        before = set(multiprocessing.active_children())
        future = pool.submit(fn, *args)
        self._workers |= set(multiprocessing.active_children()) - before
        return future

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        """Run ``fn(*args)`` in the worker; a worker that died while idle is replaced once."""
        try:
            return self._submit(self.pool, fn, *args)
        except BrokenProcessPool:
            self.restart()
            return self._submit(self.pool, fn, *args)

    def restart(self) -> None:
        """A new worker process (after one was lost, e.g. out of memory)."""
        self.pool.shutdown(wait=False, cancel_futures=True)
        self.pool = self._new()

    def shutdown(self) -> None:
        """Stop at once: a task in progress is terminated, not waited for."""
        self.pool.shutdown(wait=False, cancel_futures=True)
        for proc in self._workers:
            if proc.is_alive():
                proc.terminate()
                proc.join(5.0)
