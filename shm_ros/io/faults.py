"""Deterministic faults for the reliability tests: a node kills itself at a named point.

``SHM_FAULT=<node>:<point>[:<count>]`` makes the node named ``<node>`` (its ROS name, e.g.
``identify``; ``bag`` and ``store`` for the bag writer and the track store of any process) die by
``SIGKILL`` the ``<count>``-th time (default 1) it passes ``<point>``; several faults are separated
by commas. With ``SHM_FAULT_MARK=<folder>`` each fault fires once only: firing creates
``<folder>/<node>.<point>``, and a node restarted after it runs on normally. ``<point>`` ``enospc`` is not a
kill: the write there fails with ``ENOSPC`` (a full disk) instead.

Points: ``bag:write`` (a bag writer flushing a message: a large record is partly on disk when the
process dies; the recorder flushes every message), ``identify:published``
(after publishing the estimate of a window), ``ingest:published`` (after publishing a window),
``update:published``, ``predict:published`` and ``explain:published`` (after publishing a
posterior, a prediction, a verdict, once its subscribers acknowledged it),
``store:commit`` (inside the track store's transaction of a window, before its commit),
``<any node>:close`` (on a stop, before the node closes its files), ``recorder:enospc`` and
``store:enospc`` (the next write fails as on a full disk). Without ``SHM_FAULT`` every call reads
one environment variable and finds nothing.
"""

from __future__ import annotations

import errno
import os
import signal
from collections.abc import Callable
from pathlib import Path

_passes: dict[tuple[str, str], int] = {}


def _armed(node: str, point: str) -> int:
    """The count at which the fault at (node, point) fires; 0 when it is not set."""
    for spec in os.environ.get("SHM_FAULT", "").split(","):
        parts = spec.strip().split(":")
        if len(parts) >= 2 and parts[0] == node and parts[1] == point:
            return int(parts[2]) if len(parts) > 2 and parts[2] else 1
    return 0


def _fires(node: str, point: str) -> bool:
    count = _armed(node, point)
    if not count:
        return False
    key = (node, point)
    _passes[key] = _passes.get(key, 0) + 1
    if _passes[key] != count:
        return False
    marks = os.environ.get("SHM_FAULT_MARK")
    if marks:
        try:  # exclusive create: the first process to fire it wins, a restarted one runs normally
            (Path(marks) / f"{node}.{point}").touch(exist_ok=False)
        except FileExistsError:
            return False
    return True


def fault_point(node: str, point: str, before: Callable[[], object] | None = None) -> None:
    """Die here (SIGKILL, nothing flushed or closed) when ``SHM_FAULT`` says so; ``before`` first
    (a publisher waiting until its subscribers have the message: killed after its delivery)."""
    if _fires(node, point):
        if before is not None:
            before()
        os.kill(os.getpid(), signal.SIGKILL)



def disk_full_point(node: str, path: str | Path) -> None:
    """Fail as a full disk would when ``SHM_FAULT`` names ``<node>:enospc``."""
    if _fires(node, "enospc"):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
