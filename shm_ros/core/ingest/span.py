"""One span of grid rows: the buffered samples placed on the grid, then split into windows.

:func:`place_span` takes every buffered sample that snaps into rows ``[k0, k1)`` out of the
buffers and places it (duplicates, collisions, unsnappable and late stamps reported); channels
mostly absent or at another rate are *dropped* for the span (their samples kept, the rest NaN +
``MISSING``) instead of splitting it everywhere. :func:`split_span` cuts the span at every row
where a kept channel has no sample (a window never spans a gap); pieces shorter than half a
window are dropped and reported. A burst shorter than a window is one span of its own: its pieces
are kept from ``min_window_s`` on (or half a window, if that is shorter), so that a short record
(an earthquake of a minute among ten-minute windows) is one window of its own length.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.diagnostics import Level
from shm_ros.core.ingest.buffers import ChannelBuffer
from shm_ros.core.ingest.config import IngestConfig
from shm_ros.core.ingest.diagnostics import DiagnosticLog
from shm_ros.core.ingest.grid import Grid, estimate_rate, snap
from shm_ros.core.ingest.results import DroppedSpan, IngestStats
from shm_ros.core.ingest.segment import complete_runs
from shm_ros.core.timeutil import ns_to_iso
from shm_ros.core.types import SampleFlag


@dataclass
class Span:
    k0: int
    vals: np.ndarray  # (n, C) values, NaN where no sample
    flags: np.ndarray  # (n, C) SampleFlag bits
    filled: np.ndarray  # (n, C) a sample was placed
    mismatch: np.ndarray  # (C,) channel at another rate than the grid
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.vals.shape[0])


@dataclass
class Piece:
    """A stretch of complete rows of a span that becomes a window."""

    start_ns: int
    rows: slice
    notes: list[str]


def place_span(buffers: Sequence[ChannelBuffer], grid: Grid, k0: int, k1: int, rate: float,
               config: IngestConfig, log: DiagnosticLog, stats: IngestStats, src: Callable[[int], str],
               names: Sequence[str]) -> Span:
    """Take the samples of rows ``[k0, k1)`` out of ``buffers`` and place them on the grid."""
    n, C = k1 - k0, len(buffers)
    span = Span(k0, np.full((n, C), np.nan), np.zeros((n, C), np.uint8), np.zeros((n, C), bool),
                np.zeros(C, bool))
    span_start, span_end = grid.edge(k0), grid.edge(k1)
    tol = config.snap_tolerance * grid.period
    for c, b in enumerate(buffers):
        taken = b.take_before(span_end)
        if taken is None:
            continue
        t, v, f, seq = taken
        before = t < span_start
        if before.any():  # belongs to an earlier, already cut span
            nb = int(before.sum())
            stats.samples_not_windowed["late"] += nb
            log.add(Level.WARN, "late_sample", src(c),
                    f"{nb} sample(s) stamped inside an already cut span (clock jump backwards?): rejected",
                    int(t[before][0]), nb)
            keep = ~before
            t, v, f, seq = t[keep], v[keep], f[keep], seq[keep]
            if t.size == 0:
                continue
        s = snap(t, v, seq, grid, k0, tol)
        if s.run is not None:  # (the usual case: consecutive rows, every sample in order)
            span.vals[s.run, c] = v
            span.flags[s.run, c] = f
            span.filled[s.run, c] = True
        else:
            span.vals[s.rows, c] = v[s.placed]
            span.flags[s.rows, c] = f[s.placed]
            span.filled[s.rows, c] = True
        if s.dup_rows.size:
            ndup = int(s.dup_rows.size)
            span.flags[s.dup_rows, c] |= np.uint8(SampleFlag.DUPLICATE_STAMP)
            log.add(Level.WARN, "duplicate_stamp", src(c),
                    f"{ndup} duplicated stamp(s): first kept and flagged DUPLICATE_STAMP, "
                    f"{ndup} copies not placed ({s.n_dup_differ} with a different value)", s.dup_t0, ndup)
            span.notes.append(f"{names[c]}: {ndup} duplicated stamps")
            stats.samples_not_windowed["duplicate"] += ndup
        if s.n_collide:
            log.add(Level.WARN, "unsnappable", src(c),
                    f"{s.n_collide} stamp(s) compete for a grid point already taken by a closer "
                    "stamp: not placed (gap)", s.collide_t0, s.n_collide)
            stats.samples_not_windowed["unsnappable"] += s.n_collide
        if s.n_far:
            log.add(Level.WARN, "unsnappable", src(c),
                    f"{s.n_far} stamp(s) farther than {config.snap_tolerance:g} period "
                    "from the grid: not placed (gap)", s.far_t0, s.n_far)
            stats.samples_not_windowed["unsnappable"] += s.n_far
        # the rate of this channel, for a clear message when it differs from the grid
        if t.size > 64:
            r = estimate_rate(t[:4096], nominal=False)
            if r is not None and abs(r - rate) > config.rate_tolerance * rate:
                span.mismatch[c] = True
                log.add(Level.ERROR, "rate_mismatch", src(c),
                        f"samples at {r:.4g} Hz, grid at {rate:g} Hz: not resampled; "
                        "the channel is dropped for this window", int(t[0]))
    return span


def min_piece_rows(window_len: int, rate: float, config: IngestConfig, whole_burst: bool) -> float:
    """Grid rows a piece needs to become a window: half a window; for the pieces of a burst shorter
    than a window, ``min_window_s`` (or half a window, if that is shorter)."""
    half = window_len / 2.0
    return min(config.min_window_s * rate, half) if whole_burst else half


def split_span(span: Span, grid: Grid, window_len: int, rate: float, why: str | None, config: IngestConfig,
               log: DiagnosticLog, stats: IngestStats, src: Callable[[int], str],
               dropped_spans: list[DroppedSpan], whole_burst: bool = False) -> tuple[np.ndarray, list[Piece]]:
    """Drop channels mostly absent, then cut the span at its gaps. Returns the dropped channels
    (C,) and the pieces to emit; too short pieces go to ``dropped_spans``. ``whole_burst``: the span
    is a whole burst shorter than a window (:func:`min_piece_rows`)."""
    k0, n = span.k0, span.n
    filled, flags = span.filled, span.flags
    cover = filled.mean(axis=0)
    dropped = (cover < config.min_coverage) | span.mismatch
    for c in np.flatnonzero(dropped).tolist():
        why_dropped = "wrong rate" if span.mismatch[c] else f"only {cover[c]:.0%} of the samples present"
        log.add(Level.WARN, "channel_dropped", src(c),
                f"{why_dropped}: channel dropped for [{ns_to_iso(grid.time(k0))}, {ns_to_iso(grid.time(k0 + n))})",
                grid.time(k0))
        flags[~filled[:, c], c] |= np.uint8(SampleFlag.MISSING)
    active = ~dropped
    row_ok = np.asarray(filled[:, active].all(axis=1), bool) if active.any() else np.zeros(n, bool)
    gap_rows = ~row_ok
    if gap_rows.any():
        if active.any():
            for c in np.flatnonzero(active).tolist():
                miss = ~filled[:, c]
                if miss.any():
                    first_miss = int(np.flatnonzero(miss)[0])
                    log.add(Level.WARN, "gap", src(c),
                            f"{int(miss.sum())} grid point(s) without a sample: window split there",
                            grid.time(k0 + first_miss), int(miss.sum()))
        # (every channel dropped: the whole span is a gap; its samples are counted here as well)
        lost = int(filled[gap_rows].sum())
        if lost:
            stats.samples_not_windowed["gap_rows"] += lost
    min_len = min_piece_rows(window_len, rate, config, whole_burst)
    short_rule = "half a window" if min_len == window_len / 2.0 else "min_window_s"
    pieces = []
    for s, e in complete_runs(row_ok):
        m = e - s
        t_s = grid.time(k0 + s)
        if m < min_len:
            if whole_burst and s == 0 and e == n:
                reason, code, level = "burst", "burst_dropped", Level.WARN
            elif e == n and why is not None:
                reason, code, level = "remainder of burst", "remainder_dropped", Level.OK
            else:
                reason, code, level = "piece between gaps", "remainder_dropped", Level.WARN
            dropped_spans.append(DroppedSpan(t_s, grid.time(k0 + e), m, f"{reason} shorter than {short_rule}"))
            stats.samples_not_windowed["short_piece"] += int(filled[s:e].sum())
            log.add(level, code, "accel",
                    f"{m} samples ({m / rate:.3g} s, {reason}) shorter than "
                    f"{short_rule} ({min_len / rate:.3g} s): dropped", t_s, 1)
            continue
        notes = list(span.notes)
        if s > 0:
            notes.append("starts after a gap (window split there)")
        if e < n:
            notes.append("ends at a gap (window split there)")
        pieces.append(Piece(t_s, slice(s, e), notes))
    return dropped, pieces
