"""Samples of one output channel waiting to be cut, in numpy chunks (arrival order).

Appending is cheap (a chunk is only referenced); :meth:`ChannelBuffer.consolidate` joins the chunks
when the cutter needs to look at the samples.
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.types import SampleFlag


class ChannelBuffer:
    __slots__ = ("t", "v", "f", "seq", "chunks", "last_max", "name")

    def __init__(self, name: str) -> None:
        self.name = name
        self.t = np.empty(0, np.int64)  # stamps, ns
        self.v = np.empty(0, np.float64)  # values, m/s^2
        self.f = np.empty(0, np.uint8)  # SampleFlag bits set at arrival (OUT_OF_ORDER)
        self.seq = np.empty(0, np.int64)  # arrival order over all channels (ties of snapping)
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.last_max: int | None = None  # latest stamp seen (for OUT_OF_ORDER at arrival)

    def append(self, t: np.ndarray, v: np.ndarray, seq: np.ndarray, ascending: bool = False) -> int:
        """Add samples; returns how many are out of order (stamp < an earlier stamp).
        ``ascending``: the caller knows ``t`` does not decrease (then only its first stamp is
        compared with the earlier ones)."""
        if t.size == 0:
            return 0
        if ascending and (self.last_max is None or t[0] >= self.last_max):
            self.last_max = int(t[-1])
            self.chunks.append((t, v, np.zeros(t.size, np.uint8), seq))
            return 0
        run = np.maximum.accumulate(t)
        prev = np.empty_like(run)
        prev[0] = np.iinfo(np.int64).min if self.last_max is None else self.last_max
        if t.size > 1:
            prev[1:] = run[:-1]
        if self.last_max is not None:
            np.maximum(prev, self.last_max, out=prev)
        ooo = t < prev
        f = np.where(ooo, np.uint8(SampleFlag.OUT_OF_ORDER), np.uint8(0)).astype(np.uint8)
        self.last_max = int(max(run[-1], prev[-1]))
        self.chunks.append((t, v, f, seq))
        return int(ooo.sum())

    def consolidate(self) -> None:
        if self.chunks:
            ts, vs, fs, ss = zip(*self.chunks, strict=True)
            self.t = np.concatenate((self.t, *ts))
            self.v = np.concatenate((self.v, *vs))
            self.f = np.concatenate((self.f, *fs))
            self.seq = np.concatenate((self.seq, *ss))
            self.chunks.clear()

    def keep(self, mask: np.ndarray) -> None:
        self.t, self.v, self.f, self.seq = self.t[mask], self.v[mask], self.f[mask], self.seq[mask]

    def take_before(self, end_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Remove and return ``(t, v, f, seq)`` of the samples stamped before ``end_ns`` (None if none)."""
        sel = self.t < end_ns
        if not sel.any():
            return None
        out = self.t[sel], self.v[sel], self.f[sel], self.seq[sel]
        self.keep(~sel)
        return out

    def between(self, lo: int, hi: int) -> np.ndarray:
        """Stamps in ``[lo, hi)`` (consolidated samples only)."""
        return self.t[(self.t >= lo) & (self.t < hi)]

    @property
    def size(self) -> int:
        return int(self.t.size) + sum(c[0].size for c in self.chunks)
