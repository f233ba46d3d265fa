"""What identification does to the true modes of each window of a dense campaign.

* Frequency: relative error with standard deviation 0.1-0.5 % per mode, half of its variance an
  AR(1) over windows (rho 0.6-0.9: neighbouring windows share excitation and noise conditions).
* Damping: multiplicative log-normal scatter of 25-50 % (damping estimates are poor), also
  correlated from window to window.
* Shapes: additive noise of 1-4 % of the largest component
each shape is scaled to largest |1|
  with a positive sign at its largest true component.
* Missing: 1-4 % of a mode's windows have no estimate.
* Swaps: where two tracked modes are within 5 % of each other, 2-5 % of the windows carry them
  swapped (the tracker paired the wrong estimates).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .drivers import ar1


@dataclass(frozen=True)
class IdErrors:
    freq_sd: np.ndarray      # (modes,) relative
    damp_sd_ln: np.ndarray   # (modes,)
    shape_sd: float
    rho: float
    missing: float
    swap: float

    @classmethod
    def draw(cls, rng: np.random.Generator, modes: int) -> IdErrors:
        return cls(freq_sd=rng.uniform(0.001, 0.005, modes), damp_sd_ln=rng.uniform(0.25, 0.5, modes),
                   shape_sd=float(rng.uniform(0.01, 0.04)), rho=float(rng.uniform(0.6, 0.9)),
                   missing=float(rng.uniform(0.01, 0.04)), swap=float(rng.uniform(0.02, 0.05)))

    def _correlated(self, rng: np.random.Generator, w: int, sd: float) -> np.ndarray:
        return np.sqrt(0.5) * ar1(rng, w, self.rho, sd) + np.sqrt(0.5) * sd * rng.standard_normal(w)

    def apply(self, rng: np.random.Generator, f: np.ndarray, zeta: np.ndarray, phi: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """f, zeta (W, K), phi (W, S, K) true -> identified (same shapes) and the swap flags (W, K)."""
        w, k = f.shape
        f_id = f * (1 + np.column_stack([self._correlated(rng, w, s) for s in self.freq_sd]))
        z_id = zeta * np.exp(np.column_stack([self._correlated(rng, w, s) for s in self.damp_sd_ln]))
        ref = np.argmax(np.abs(phi), axis=1)                                  # (W, K)
        sign = np.sign(np.take_along_axis(phi, ref[:, None, :], axis=1))
        p = phi * sign
        p = p / np.max(np.abs(p), axis=1, keepdims=True)
        p = p + self.shape_sd * rng.standard_normal(p.shape)
        p = p / np.max(np.abs(p), axis=1, keepdims=True)
        swapped = np.zeros((w, k), dtype=bool)
        for j in range(k - 1):
            close = np.abs(f[:, j + 1] / f[:, j] - 1.0) < 0.05
            flip = close & (rng.uniform(size=w) < self.swap)
            for arr in (f_id, z_id):
                arr[flip, j], arr[flip, j + 1] = arr[flip, j + 1].copy(), arr[flip, j].copy()
            p[flip, :, j], p[flip, :, j + 1] = p[flip, :, j + 1].copy(), p[flip, :, j].copy()
            swapped[flip, j] = swapped[flip, j + 1] = True
        gone = rng.uniform(size=(w, k)) < self.missing
        f_id[gone], z_id[gone] = np.nan, np.nan
        p[np.repeat(gone[:, None, :], p.shape[1], axis=1)] = np.nan
        return f_id, z_id, p, swapped

    def as_dict(self) -> dict:
        return {"frequency_sd_relative": self.freq_sd.tolist(), "damping_sd_log": self.damp_sd_ln.tolist(),
                "shape_sd": self.shape_sd, "ar1_rho": self.rho, "missing_fraction": self.missing,
                "swap_fraction_when_close": self.swap}
