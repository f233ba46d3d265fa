"""Progress and ETA of long work, on the terminal: one line per update, at most every ``every_s``.

Long-running cores take a ``progress(done, total)`` callback; commands pass a :class:`Progress`.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``label [#####     ] done/total  elapsed, ETA`` lines; the first and last update always print,
    and a count is shown once."""

    def __init__(self, label: str, stream: TextIO | None = None, every_s: float = 1.0, width: int = 30) -> None:
        self.label, self.stream, self.every_s, self.width = label, stream, every_s, width
        self.t0 = time.monotonic()
        self._last = -float("inf")
        self._shown: tuple[int, int] | None = None

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if (done, total) == self._shown or (0 < done < total and now - self._last < self.every_s):
            return
        self._last, self._shown = now, (done, total)
        print(self.line(done, total, now - self.t0), file=self.stream or sys.stderr, flush=True)

    def line(self, done: int, total: int, elapsed: float) -> str:
        frac = done / total if total else 1.0
        bar = "#" * int(round(self.width * frac))
        eta = elapsed / done * (total - done) if done else float("nan")
        eta_text = f"ETA {eta:.0f} s" if done < total and done else ("done" if done >= total else "ETA -")
        return f"{self.label} [{bar:<{self.width}}] {done}/{total}  {elapsed:.0f} s, {eta_text}"
