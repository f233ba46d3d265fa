"""Novelty: an EWMA control chart on the standardised residuals of the environmental model.

Each mode's residual ``z_k = (f_k - prediction_k) / heldout_rmse_k`` (and, optionally, the damping's
log residual) is smoothed by an EWMA ``e_k <- (1 - lambda) e_k + lambda z_k`` (a missing mode keeps
its value). Under normal conditions each ``e_k`` has variance ``lambda / (2 - lambda)``, so the
chart statistic ``T = mean_k e_k^2 / (lambda / (2 - lambda))`` is about ``chi2_m / m``; its threshold
is the ``alarm_quantile`` of that distribution (each variance inflated by the residuals' lag-1
autocorrelation in training), or of the training period's statistic when that is
larger (a model that fits the training period worse than its own held-out error claims). A small
persistent shift (a stiffness loss) accumulates in the EWMA; a freezing spell that the temperature
model explains leaves the residuals at zero. The modes of an alarm are those whose own ``e_k^2``
exceeds the one-mode quantile (or the largest contributor).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtri  # chi-square quantiles without scipy.stats' import (~1 s)


@dataclass
class NoveltyChart:
    lam: float
    n_modes: int
    threshold: float = float("inf")
    ewma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seen: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    inflation: np.ndarray = field(default_factory=lambda: np.zeros(0))  # AR(1) factor per input

    def __post_init__(self) -> None:
        self.resize(self.n_modes)

    def resize(self, n: int) -> None:
        self.ewma = np.concatenate([self.ewma, np.zeros(n - self.ewma.size)])
        self.seen = np.concatenate([self.seen, np.zeros(n - self.seen.size, bool)])
        self.inflation = np.concatenate([self.inflation, np.ones(n - self.inflation.size)])
        self.n_modes = n

    def set_autocorrelation(self, k: int, phi: float) -> None:
        """Residuals correlated window to window (lag-1 ``phi``) give the EWMA a larger variance:
        ``lambda/(2-lambda) (1 + (1-lambda) phi) / (1 - (1-lambda) phi)``."""
        r = (1 - self.lam) * phi
        self.inflation[k] = (1 + r) / (1 - r)

    @property
    def variance(self) -> np.ndarray:
        return self.lam / (2.0 - self.lam) * self.inflation

    def update(self, z: np.ndarray) -> float:
        """Add one window's residuals (NaN = not found); the chart statistic after it."""
        if z.size > self.ewma.size:
            self.resize(z.size)
        ok = np.isfinite(z)
        self.ewma[ok] = (1 - self.lam) * self.ewma[ok] + self.lam * z[ok]
        self.seen |= ok
        if not self.seen.any():
            return float("nan")
        return float(np.mean(self.ewma[self.seen] ** 2 / self.variance[self.seen]))

    def calibrate(self, training_stats: np.ndarray, quantile: float) -> float:
        m = max(1, int(self.seen.sum()) or self.n_modes)
        nominal = float(chdtri(m, 1.0 - quantile) / m)
        tr = training_stats[np.isfinite(training_stats)]
        self.threshold = max(nominal, float(np.quantile(tr, quantile)) if tr.size >= 10 else nominal)
        return self.threshold

    def alarm_modes(self, numbers: list[int], quantile: float) -> list[int]:
        per = np.where(self.seen, self.ewma ** 2 / self.variance, 0.0)
        lim = chdtri(1, 1.0 - quantile)
        out = [numbers[k] for k in np.flatnonzero(per > lim) if k < len(numbers)]
        return out or ([numbers[int(np.argmax(per))]] if per.size else [])


def alarm_episodes(alarm: np.ndarray, gap: int = 6) -> list[tuple[int, int]]:
    """(first, last) window indices of alarm episodes; alarms fewer than ``gap`` windows apart are
    one episode (a chart hovering at its threshold is one event, not many)."""
    idx = np.flatnonzero(alarm)
    if idx.size == 0:
        return []
    out = []
    start = prev = int(idx[0])
    for i in idx[1:]:
        if i - prev > gap:
            out.append((start, prev))
            start = int(i)
        prev = int(i)
    out.append((start, prev))
    return out
