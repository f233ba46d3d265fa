"""Bursts and windows: where the buffered stream is cut.

A burst ends where no channel has a sample for more than ``burst_pause_s``. Every burst has a grid
of its own (:class:`~shm_ros.core.ingest.grid.Grid`, which starts at the burst's first sample with
the burst's nominal period; the caller's ``on_open`` says which, see
:mod:`~shm_ros.core.ingest.rates`). Inside a burst, windows of ``window_s`` are counted from the
burst's first sample. A window is cut once every stamp that could snap into it is final (before
``final_ns``); a burst that ends inside a window is cut at its last sample (a burst shorter than a
window is cut whole). :class:`Bursts` keeps the state of the open burst and decides the cuts;
placing the samples is the caller's ``cut`` callback.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from shm_ros.core.ingest.buffers import ChannelBuffer
from shm_ros.core.ingest.grid import Grid

#: ``cut(k0, k1, why, last_stamp)``: place grid rows ``[k0, k1)`` of the open burst; ``why`` is
#: None for a full window, "pause" or "end" when the burst ends there (at ``last_stamp``).
Cut = Callable[[int, int, str | None, int | None], None]
#: ``on_open(first_stamp, final_ns)``: a burst starts at ``first_stamp``; returns its rate (Hz) and
#: window length (grid rows), or None while its rate cannot be told yet (wait for data).
OnOpen = Callable[[int, int | None], tuple[float, int] | None]


def complete_runs(row_ok: np.ndarray) -> list[tuple[int, int]]:
    """``[start, end)`` of every run of True in ``row_ok``."""
    edges = np.diff(np.concatenate(([0], row_ok.view(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True))


def _first_stamp(buffers: Sequence[ChannelBuffer]) -> int | None:
    firsts = [int(b.t.min()) for b in buffers if b.t.size]
    return min(firsts) if firsts else None


class Bursts:
    """The open burst: its grid, the next window's first grid point, how far it has been scanned."""

    def __init__(self, pause_ns: float, check_interval_ns: int) -> None:
        self.pause_ns = pause_ns
        self.check_interval_ns = check_interval_ns
        self.grid: Grid | None = None  # None: no burst open
        self.window_len = 1  # grid rows of a full window of the open burst
        self.rate = 0.0  # nominal rate of the open burst, Hz
        self.k = 0  # first grid point of the next window
        self.scan_ns: int | None = None  # stamps below this are scanned for pauses
        self.scan_last: int | None = None  # newest stamp of the open burst seen by the scan

    def open(self, origin: int, rate: float, window_len: int) -> None:
        self.grid = Grid(origin, 0, 1e9 / rate)
        self.window_len = window_len
        self.rate = rate
        self.k = 0
        self.scan_ns = None
        self.scan_last = None

    def close(self) -> None:
        self.grid = None
        self.k = 0
        self.scan_ns = None
        self.scan_last = None

    def process(self, buffers: Sequence[ChannelBuffer], final_ns: int | None, cut: Cut,
                on_open: OnOpen) -> int | None:
        """Cut every window whose data is final (``final_ns`` None: end of stream). Returns the stream
        time at which to look again (None: nothing buffered)."""
        pause_ns = self.pause_ns
        end_of_stream = final_ns is None
        fin = np.iinfo(np.int64).max if final_ns is None else int(final_ns)
        waiting = False  # a burst has started whose rate is not known yet
        while True:
            if self.grid is None:
                first = _first_stamp(buffers)
                if first is None or first >= fin:
                    break
                opened = on_open(first, final_ns)
                if opened is None:
                    waiting = True
                    break
                self.open(first, *opened)
            W = self.window_len
            grid = self.grid
            assert grid is not None
            k0 = self.k
            span_start = grid.edge(k0)  # stamps in [span_start, span_end) snap into this window
            span_end = grid.edge(k0 + W)
            lim = min(span_end, fin)
            lo = span_start if self.scan_ns is None else max(span_start, self.scan_ns)
            u = _union([b.between(lo, lim) for b in buffers])
            if u.size:
                prev = self.scan_last
                seq_u = u if prev is None else np.concatenate(([prev], u))
                jumps = np.flatnonzero(np.diff(seq_u) > pause_ns)
                if jumps.size:
                    end_stamp = int(seq_u[jumps[0]])
                    if end_stamp >= span_start:
                        cut(k0, grid.slot(end_stamp) + 1, "pause", end_stamp)
                    self.close()
                    continue
                self.scan_last = int(u[-1])
            self.scan_ns = int(lim)
            last = self.scan_last  # newest stamp of the burst so far
            if fin >= span_end:  # everything that snaps into this window is final
                later = [x.min() for x in (b.between(span_end, fin) for b in buffers) if x.size]
                nxt = int(min(later)) if later else None
                if last is None:  # (cannot happen: a burst opens on a sample) - close defensively
                    self.close()
                    continue
                ended = (nxt - last > pause_ns) if nxt is not None else (end_of_stream or fin - last > pause_ns)
                if nxt is None and not ended:
                    break  # the burst may go on: wait
                if ended:
                    if last >= span_start:
                        cut(k0, grid.slot(last) + 1, "end" if end_of_stream else "pause", last)
                    self.close()
                    continue
                cut(k0, k0 + W, None, None)
                self.k = k0 + W
                continue
            if last is not None and fin - last > pause_ns:
                if last >= span_start:
                    cut(k0, grid.slot(last) + 1, "pause", last)
                self.close()
                continue
            break
        # when to try again: the end of the open window, or a pause after the newest sample; at most
        # every check interval of stream time, so that a long window is not rescanned often
        if self.grid is not None:
            due = self.grid.time(self.k + self.window_len)
            if self.scan_last is not None:
                due = min(due, max(self.scan_last + int(pause_ns) + 1, fin + self.check_interval_ns))
            return due
        first = _first_stamp(buffers)
        if first is None:
            return None
        if waiting:  # more stamps of the new burst tell its rate
            return max(first, fin) + min(self.check_interval_ns, 1_000_000_000)
        return first  # a burst starts there: open it once the stream is final past it


def _union(parts: list[np.ndarray]) -> np.ndarray:
    """The channels' stamps together, sorted (duplicates are harmless). Channels fed by one DAQ
    block share their stamps: an array equal to the one before it is left out (one comparison
    instead of sorting it in), and the merge of the ascending runs is a stable (run-aware) sort."""
    keep: list[np.ndarray] = []
    for p in parts:
        if not (keep and np.array_equal(p, keep[-1])):
            keep.append(p)
    if len(keep) == 1:
        u = keep[0]
        return u if u.size < 2 or bool(np.all(u[1:] >= u[:-1])) else np.sort(u)
    return np.sort(np.concatenate(keep) if keep else np.empty(0, np.int64), kind="stable")
