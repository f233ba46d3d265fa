"""The sample rate of a burst: every burst is cut on a grid of its own rate.

Records made years apart by different instruments (earthquake records at 100 and 200 Hz in one
bag) are each one burst; nothing is resampled, so each burst keeps the rate it was recorded at. The
rate of a burst is, in this order: ``sample_rate_hz`` when it is configured; the declared rate of
the AccelBlocks that carry its first sample (:class:`BlockRates`); or fitted to its Imu stamps
(:func:`stamps_rate`). Inside a burst the rate is fixed: a block or channel at another rate there is
a fault (rejected or dropped, as in ``docs/ingest.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.ingest.buffers import ChannelBuffer
from shm_ros.core.ingest.grid import estimate_rate

_ENOUGH = 64  # stamps of a channel that make its rate estimate final
_FEWEST = 17  # fewest stamps estimate_rate works with (a burst that ended that early)
_MOST = 1024  # stamps of a channel looked at


@dataclass
class BlockRates:
    """Stretches of AccelBlocks at one declared rate, ``[t_first, t_last, rate]``, in time order."""

    runs: list[list] = field(default_factory=list)

    @property
    def last_rate(self) -> float | None:
        return self.runs[-1][2] if self.runs else None

    def accepts(self, t0: int, rate: float, latest_ns: int | None, pause_ns: float) -> bool:
        """A block at ``rate`` starting at ``t0`` is accepted when it has the rate of the blocks
        before it or starts a new burst (more than a pause after the newest stamp of any channel)."""
        last = self.last_rate
        if last is None or abs(rate - last) <= 1e-6 * last:
            return True
        return latest_ns is None or t0 - latest_ns > pause_ns

    def add(self, t0: int, t1: int, rate: float) -> bool:
        """Record an accepted block with samples ``[t0, t1]``; True when its rate differs from the
        previous block's."""
        last = self.last_rate
        if last is not None and abs(rate - last) <= 1e-6 * last:
            run = self.runs[-1]
            run[0], run[1] = min(run[0], t0), max(run[1], t1)
            return False
        self.runs.append([t0, t1, rate])
        return last is not None

    def rate_at(self, t: int) -> float | None:
        """The declared rate of the blocks around stamp ``t`` (None: no block there)."""
        for t0, t1, rate in reversed(self.runs):
            if t0 <= t <= t1:
                return float(rate)
        return None

    def prune(self, before_ns: int) -> None:
        """Forget stretches that ended before ``before_ns`` (the newest is always kept)."""
        if len(self.runs) > 1:
            self.runs = [r for r in self.runs[:-1] if r[1] >= before_ns] + self.runs[-1:]


def stamps_rate(buffers: Sequence[ChannelBuffer], first: int, final_ns: int | None, pause_ns: float,
                tolerance: float) -> tuple[float | None, bool]:
    """The rate of the burst starting at ``first`` fitted to its stamps: ``(rate, decided)``.

    Each channel's rate is fitted to its first stamps of the burst (before the burst's first pause);
    the rate most channels agree on (within ``tolerance``) wins, so one channel at another rate cannot
    move the grid. Undecided (``(None, False)``) while no channel has 64 stamps and the burst may
    still go on; once it has ended, 17 stamps of a channel are enough; ``(None, True)`` when even
    those are missing (the caller falls back to the previous rate).
    """
    fin = np.iinfo(np.int64).max if final_ns is None else int(final_ns)
    # each channel's first stamps (a cap cannot fake a pause: where a channel's cap ends, the
    # others' stamps or that channel's own pause still show whether the burst goes on)
    chans = [np.unique(b.between(first, fin))[: 4 * _MOST] for b in buffers]
    chans = [t for t in chans if t.size]
    if not chans:
        return None, final_ns is None
    merged = np.unique(np.concatenate(chans))
    jumps = np.flatnonzero(np.diff(merged) > pause_ns)
    end = int(merged[jumps[0]]) if jumps.size else None  # the burst's last stamp, when seen
    ended = final_ns is None or end is not None or fin - int(merged[-1]) > pause_ns
    per_channel = [(t if end is None else t[t <= end])[:_MOST] for t in chans]
    enough = any(t.size >= _ENOUGH for t in per_channel)
    if not enough and not ended:
        return None, False
    need = _ENOUGH if enough else _FEWEST
    fits = [(r, t.size) for t in per_channel if t.size >= need
            for r in (estimate_rate(t),) if r is not None]
    if not fits:
        return None, True

    def support(fit: tuple[float, int]) -> tuple[int, int]:
        r = fit[0]
        return sum(1 for q, _ in fits if abs(q - r) <= tolerance * r), fit[1]

    return float(max(fits, key=support)[0]), True
