"""Synthetic ground motion: Kanai-Tajimi filtered white noise under a Jennings envelope.

The Kanai-Tajimi filter (ground frequency ``fg`` 1.5-5 Hz, ratio ``zg`` 0.3-0.65) shapes the
spectrum like a soil column
a Clough-Penzien second stage (``ff`` = 0.1-0.25 fg) removes the
long-period content so displacements do not drift. The Jennings et al. (1968) envelope rises as
(t/t1)^2, holds until t2 and decays as exp(-c (t - t2)). The record is scaled to its peak (PGA).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GroundMotion:
    fg: float = 2.5          # Hz, Kanai-Tajimi ground frequency
    zg: float = 0.5          # Kanai-Tajimi damping
    ff_ratio: float = 0.15   # Clough-Penzien corner as a fraction of fg
    duration_s: float = 30.0
    t1_frac: float = 0.12    # end of the build-up, fraction of the duration
    t2_frac: float = 0.40    # end of the strong phase
    decay: float = 0.25      # 1/s, exponential decay after t2 (scaled to the duration below)

    @classmethod
    def draw(cls, rng: np.random.Generator, duration_s: float) -> GroundMotion:
        return cls(fg=float(rng.uniform(1.5, 5.0)), zg=float(rng.uniform(0.3, 0.65)),
                   ff_ratio=float(rng.uniform(0.1, 0.25)), duration_s=duration_s,
                   t1_frac=float(rng.uniform(0.08, 0.18)), t2_frac=float(rng.uniform(0.3, 0.5)),
                   decay=float(rng.uniform(4.0, 8.0)) / duration_s)

    def envelope(self, t: np.ndarray) -> np.ndarray:
        t1, t2 = self.t1_frac * self.duration_s, self.t2_frac * self.duration_s
        return np.where(t < t1, (t / t1) ** 2, np.where(t <= t2, 1.0, np.exp(-self.decay * (t - t2))))

    def record(self, rng: np.random.Generator, rate_hz: float, pga: float) -> np.ndarray:
        """One horizontal component (m/s^2) sampled at ``rate_hz`` with peak ``pga``."""
        n = int(round(self.duration_s * rate_hz))
        t = np.arange(n) / rate_hz
        spec = np.fft.rfft(rng.standard_normal(n) * self.envelope(t))
        w = 2 * np.pi * np.fft.rfftfreq(n, 1 / rate_hz)
        wg, wf = 2 * np.pi * self.fg, 2 * np.pi * self.fg * self.ff_ratio
        kt = (wg**2 + 2j * self.zg * wg * w) / (wg**2 - w**2 + 2j * self.zg * wg * w)
        cp = w**2 / (wf**2 - w**2 + 2j * 0.7 * wf * w)
        a = np.fft.irfft(spec * kt * cp, n)
        a *= self.envelope(t)  # keep the quiet start and the decaying tail after filtering
        return a * (pga / np.max(np.abs(a)))
