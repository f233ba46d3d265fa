"""Options of the tracking stage (one definition for core, node and command line)."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from shm_ros.core.config import option


class ReferenceSource(enum.StrEnum):
    WINDOWS = "windows"  # clusters of the first windows' modes
    MODEL = "model"  # the structure file's FE modes at the sensors
    BOTH = "both"  # clusters of the first windows, numbered and completed by the FE modes


class EnvModel(enum.StrEnum):
    AUTO = "auto"  # the candidate with the smallest held-out error
    CONSTANT = "constant"
    LINEAR = "linear"  # the main covariate
    BILINEAR = "bilinear"  # the main covariate with a knee (freezing)
    MULTI = "multi"  # every covariate, lagged temperatures, time
    MULTI_KNEE = "multi_knee"  # ``multi`` plus the knee
    PCA = "pca"  # no covariate: the leading principal components of the frequencies


@dataclass
class TrackingConfig:
    reference_windows: int = option(24, "windows that establish the tracked mode set (fewer when the "
                                    "record has fewer)")
    min_presence: float = option(0.5, "a tracked mode is found in at least this fraction of the "
                                 "reference windows")
    cluster_cutoff: float = option(0.05, "cut-off of |df|/f + (1 - MAC) when clustering the "
                                   "reference windows' modes")
    reference_source: str = option("windows", "where the tracked mode set comes from "
                                   "(model/both need a structure file)", choices=ReferenceSource)
    freq_tol: float = option(0.05, "frequency gate |f - f_pred| / f_pred around the predicted frequency; "
                             "widened by the environmental model's predicted shift")
    max_freq_gate: float = option(0.25, "widest frequency gate (after misses and predicted shifts)")
    mac_min: float = option(0.8, "assignment gate: MAC with the reference shape")
    freq_weight: float = option(0.3, "weight of the frequency term in the assignment cost (MAC term: 1)")
    adapt: float = option(0.1, "exponential average of the reference after each assignment (0 = fixed)")
    birth_windows: int = option(24, "recent windows whose unassigned modes may form a new tracked mode "
                                "(0 = no new modes)")
    covariate: str = option("temperature_c", "main environmental variable (the knee is on it)")
    lag_hours: float = option(3.0, "time constant of the first-order lag applied to temperatures "
                              "(thermal inertia; 0 = none)")
    env_model: str = option("auto", "environmental model of the frequencies", choices=EnvModel)
    # the node trains on its first ``training_windows`` rows instead (it cannot know the total)
    training_fraction: float = option(0.25, "first fraction of the windows that trains the "
                                      "environmental model and the novelty threshold", ros=False)
    ewma_lambda: float = option(0.2, "weight of the newest window in the novelty chart's EWMA")
    alarm_quantile: float = option(0.9999, "novelty threshold: this quantile of the chart statistic "
                                   "under normal conditions (or of the training statistic if larger)")
    alarm_windows: int = option(3, "consecutive windows above the threshold before an alarm (one "
                                "odd window is not a change)")
    novelty_damping: bool = option(False, "damping ratios enter the novelty chart too")

    def __post_init__(self) -> None:
        if self.reference_windows < 1:
            raise ValueError(f"reference_windows must be >= 1, got {self.reference_windows}")
        for name in ("min_presence", "training_fraction", "alarm_quantile", "ewma_lambda"):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {v}")
        if not 0 < self.freq_tol < 1 or not 0 <= self.mac_min < 1:
            raise ValueError("freq_tol must be in (0, 1) and mac_min in [0, 1)")
        if not self.freq_tol <= self.max_freq_gate < 1:
            raise ValueError(f"max_freq_gate must be in [freq_tol, 1), got {self.max_freq_gate}")
        if not 0 <= self.adapt < 1:
            raise ValueError(f"adapt must be in [0, 1), got {self.adapt}")
        if self.alarm_windows < 1:
            raise ValueError(f"alarm_windows must be >= 1, got {self.alarm_windows}")
        if self.birth_windows < 0 or self.lag_hours < 0 or self.freq_weight < 0:
            raise ValueError("birth_windows, lag_hours and freq_weight must be >= 0")
        self.reference_source = ReferenceSource(self.reference_source).value
        self.env_model = EnvModel(self.env_model).value
