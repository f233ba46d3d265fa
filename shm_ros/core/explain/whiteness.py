"""Is what remains noise? Per mode, the misfit's autocorrelation over consecutive windows.

An effect that is fully modelled leaves a misfit that is white from window to window (identification
scatter); an effect that is missing, or only partly modelled, leaves a course in time (lag-1
autocorrelation near 1 for a slow one). Locate asks this of the nominal model's misfit; the verdict
asks it again after the accepted effects (:func:`residual_whiteness`), so that a user sees whether
they took up all of the structure or only part of it. The Ljung-Box statistic is a few lines on the
autocorrelations; statsmodels' version would add a dependency for them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from shm_ros.core.bayes.model_error import autocorrelation as series_autocorrelation

LAGS = 12  # windows: two hours of 10-minute windows
STRUCTURED_P = 1e-3  # Ljung-Box p-value below which a mode's misfit is structured
# lag-1 autocorrelation from which structure left after the accepted effects is worth a note: about a
# third of the misfit's variance then follows a course in time (on hundreds of windows the Ljung-Box
# test alone flags courses far too small to matter: lag-1 0.1-0.2 after a fully named effect)
LEFT_LAG1 = 0.3


def _filled(r: np.ndarray) -> np.ndarray:
    """Missing windows filled with the mean (conservative: it shrinks the autocorrelation)."""
    r = np.asarray(r, float)
    return np.where(np.isfinite(r), r, np.nanmean(r) if np.isfinite(r).any() else 0.0)


def autocorrelation(r: np.ndarray, lags: int) -> np.ndarray:
    """Autocorrelation at lags 1..``lags`` of a misfit series with missing windows (:func:`_filled`)."""
    return series_autocorrelation(_filled(r), lags)


def ljung_box(r: np.ndarray, lags: int = LAGS) -> float:
    """p-value of the Ljung-Box test that the series is white up to ``lags`` (over its finite values:
    windows where the mode was not found, or held out, are skipped, not read as NaN)."""
    r = _finite(r)
    n = r.size
    if n <= lags + 2:
        return 1.0
    rho = autocorrelation(r, lags)
    q = n * (n + 2) * float(np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
    return float(stats.chi2.sf(q, lags))


@dataclass
class Whiteness:
    """Per mode, the misfit before and after the accepted effects (windows in time order)."""

    mode_numbers: list[int]
    lag1_before: list[float]
    lag1_after: list[float]
    p_before: list[float]  # Ljung-Box p-values
    p_after: list[float]

    def unexplained_course(self) -> list[int]:
        """Modes with structure left whose lag-1 autocorrelation the accepted effects did not even
        halve: the course in time there is not what they explain (the whiteness downgrade)."""
        return [m for m in self.still_structured
                if self.lag1_after[self.mode_numbers.index(m)] > 0.5 * self.lag1_before[self.mode_numbers.index(m)]]

    @property
    def still_structured(self) -> list[int]:
        """Modes whose misfit was structured and still is after the accepted effects, to a degree
        that matters (:data:`LEFT_LAG1`)."""
        return [m for m, pb, pa, r in zip(self.mode_numbers, self.p_before, self.p_after, self.lag1_after, strict=True)
                if pb < STRUCTURED_P and pa < STRUCTURED_P and r >= LEFT_LAG1]

    def to_dict(self) -> dict[str, list[float] | list[int]]:
        return {"mode_numbers": list(self.mode_numbers), "lag1_before": self.lag1_before,
                "lag1_after": self.lag1_after, "ljung_box_p_before": self.p_before,
                "ljung_box_p_after": self.p_after, "still_structured": self.still_structured}

    def note(self) -> str | None:
        """Plain words when structure remains after the accepted effects (else None)."""
        left = self.still_structured
        if not left:
            return None
        rho = [self.lag1_after[self.mode_numbers.index(m)] for m in left]
        modes, values = listing(left, rho)
        return (f"after the accepted effects the misfit of {modes} still follows a course in time (lag-1 "
                f"autocorrelation {values}; white misfit: about 0): part of what moves "
                f"{'them' if len(left) > 1 else 'it'} is not modelled")


def listing(modes: list[int], lag1: list[float]) -> tuple[str, str]:
    """(``"modes 2, 9"``, ``"0.37, 0.80"``): the modes with structure left and their lag-1 values."""
    return f"mode{'s' if len(modes) > 1 else ''} {', '.join(map(str, modes))}", ", ".join(f"{r:.2f}" for r in lag1)


def residual_whiteness(before: np.ndarray, after: np.ndarray, mode_numbers: list[int],
                       lags: int = LAGS) -> Whiteness:
    """:class:`Whiteness` of the misfit (W, K) before and after, windows in time order."""
    b, a = np.asarray(before, float), np.asarray(after, float)
    cols = range(b.shape[1])
    return Whiteness([int(m) for m in mode_numbers],
                     [float(autocorrelation(_finite(b[:, k]), 1)[0]) for k in cols],
                     [float(autocorrelation(_finite(a[:, k]), 1)[0]) for k in cols],
                     [ljung_box(b[:, k], lags) for k in cols], [ljung_box(a[:, k], lags) for k in cols])


def _finite(r: np.ndarray) -> np.ndarray:
    """The finite values of a series, in order (missing windows skipped)."""
    r = np.asarray(r, dtype=float)
    return r[np.isfinite(r)]
