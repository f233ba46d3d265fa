"""Accelerometer errors: gain (+-5 %), misalignment in plan (<= 3 deg) and additive noise.

A sensor meant to read x at a plan point reads ``gain (cos a ax + sin a ay) + noise`` of the point's
absolute acceleration. Noise of 1-5 mm/s^2 RMS is that of a good MEMS accelerometer over 50 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorErrors:
    gain: np.ndarray        # (channels,)
    misalign_rad: np.ndarray
    noise_rms: np.ndarray   # m/s^2

    @classmethod
    def draw(cls, rng: np.random.Generator, channels: int) -> SensorErrors:
        return cls(gain=1.0 + rng.uniform(-0.05, 0.05, channels),
                   misalign_rad=np.deg2rad(rng.uniform(-3.0, 3.0, channels)),
                   noise_rms=rng.uniform(1e-3, 5e-3, channels))

    def read(self, rng: np.random.Generator, ax: np.ndarray, ay: np.ndarray) -> np.ndarray:
        """Measured samples (N, channels) from the true absolute accelerations ax, ay (N, channels)."""
        a = self.gain * (np.cos(self.misalign_rad) * ax + np.sin(self.misalign_rad) * ay)
        return a + self.noise_rms * rng.standard_normal(a.shape)

    def as_dict(self) -> dict:
        return {"gain": self.gain.tolist(), "misalignment_deg": np.rad2deg(self.misalign_rad).tolist(),
                "noise_rms_m_s2": self.noise_rms.tolist()}
