"""Settings of a response prediction (``shm-ros predict``, the predict node's parameters)."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from shm_ros.core.config import check_choice, option


class Baseline(enum.StrEnum):
    """What is removed from the records before the model is driven from rest."""

    MEAN = "mean"  # the mean of the pre-event part (sensor offsets, gravity on a tilted axis)
    LINEAR = "linear"  # a straight line fitted to the pre-event part (offset and slow drift)


class Unmeasured(enum.StrEnum):
    """How accelerations at unmeasured floors are predicted (see :mod:`.expansion`)."""

    MODEL = "model"  # the model's output alone
    EXPANDED = "expanded"  # the model's output plus the measured residual expanded on its mode shapes


@dataclass
class PredictConfig:
    """Every field has a default; all are plain data."""

    n_draws: int = option(200, "posterior draws pushed through the model (0: the MAP only)")
    seed: int = option(0, "random seed of the draws (the same seed gives the same numbers)")
    level: float = option(0.95, "probability of the predictive band and of the peak intervals")
    baseline: str = option(Baseline.MEAN.value, "baseline correction from the pre-event part: its mean "
                           "or a straight line fitted to it", choices=Baseline)
    onset_arias: float = option(0.001, "the event starts where the input's Arias intensity reaches "
                                "this fraction; the record before it is the pre-event part")
    min_pre_event_s: float = option(1.0, "shortest pre-event part used for the baseline and the noise "
                                    "floor (shorter: the first this many seconds are used)")
    envelope_s: float = option(2.0, "window of the local mean square that scales the model error in time")
    relative_error: float = option(0.1, "model error relative to the response RMS when the posterior "
                                   "carries no time-domain calibration (modal posterior, nominal model)")
    unmeasured: str = option(Unmeasured.EXPANDED.value, "unmeasured floors' accelerations: the model's output "
                             "alone, or plus the measured floors' residual expanded on the model's mode shapes",
                             choices=Unmeasured)
    chunk: int = option(32, "draws simulated at once (memory: chunk x states x samples complex values)")
    threads: int = option(1, "threads simulating chunks of draws concurrently (the numbers do not depend on it)")

    def validate(self) -> PredictConfig:
        check_choice("predict", "baseline", self.baseline, Baseline)
        check_choice("predict", "unmeasured", self.unmeasured, Unmeasured)
        if self.n_draws < 0:
            raise ValueError(f"predict: n_draws must be >= 0, got {self.n_draws}")
        if not 0.0 < self.level < 1.0:
            raise ValueError(f"predict: level must be in (0, 1), got {self.level}")
        if not 0.0 < self.onset_arias < 0.5:
            raise ValueError(f"predict: onset_arias must be in (0, 0.5), got {self.onset_arias}")
        if self.chunk < 1 or self.threads < 1 or self.envelope_s <= 0 or self.relative_error < 0 \
                or self.min_pre_event_s < 0:
            raise ValueError("predict: chunk >= 1, threads >= 1, envelope_s > 0, relative_error >= 0, "
                             "min_pre_event_s >= 0")
        return self
