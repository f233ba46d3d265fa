"""The ingest core's record of diagnostics: every occurrence counted, a bounded number recorded.

A fault that goes on (a channel full of NaNs) would otherwise flood a long-running node with one
record per window per sample; instead, records of one ``(code, source)`` are limited to
``max_repeats`` between two emitted windows (so a live node keeps reporting a fault that goes on,
window after window) and to one for "once" notices, while :attr:`DiagnosticLog.counts` keeps the
total of every occurrence.
"""

from __future__ import annotations

from collections import Counter

from shm_ros.core.diagnostics import Diagnostic, Level

MAX_KEPT_DIAGNOSTICS = 10_000  # the newest are kept; counts are kept for all


class DiagnosticLog:
    def __init__(self, max_repeats: int) -> None:
        self.max_repeats = max_repeats
        self.kept: list[Diagnostic] = []
        self.counts: Counter[tuple[str, str]] = Counter()  # (code, source) -> occurrences
        self._since: Counter[tuple[str, str]] = Counter()  # records per (code, source) since the last window
        self._new = 0  # records not yet popped

    def add(self, level: Level, code: str, source: str, message: str, stamp_ns: int | None = None,
            count: int = 1, once: bool = False) -> None:
        key = (code, source)
        first = key not in self.counts
        self.counts[key] += count
        if first if once else self._since[key] < self.max_repeats:
            self._since[key] += 1
            self.kept.append(Diagnostic(level, code, source, message, stamp_ns, count))
            self._new += 1
            if len(self.kept) > 2 * MAX_KEPT_DIAGNOSTICS:  # bounded memory in a long-running node
                del self.kept[:MAX_KEPT_DIAGNOSTICS]
                self._new = min(self._new, len(self.kept))

    def window_emitted(self) -> None:
        """A window went out: repeats of every code are recorded again."""
        self._since.clear()

    def pop_new(self) -> list[Diagnostic]:
        """Records added since the last call."""
        out = self.kept[len(self.kept) - self._new:] if self._new else []
        self._new = 0
        return out
