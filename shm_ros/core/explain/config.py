"""Settings of one explain run: the ``shm-ros explain`` options and the explain node's parameters."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from shm_ros.core.config import option


class MisfitCorrelation(enum.StrEnum):
    """How the misfit of one window relates to the window before (:mod:`.drift`)."""

    DRIFT = "drift"  # a random-walk drift under the scatter, integrated (records of 40 windows or more)
    INDEPENDENT = "independent"


@dataclass
class ExplainConfig:
    held_out_every: int = option(4, "every n-th block of windows is held out of the fit and scores it")
    block_windows: int = option(0, "windows per block (0: a third of a day of windows, or W / 8 if shorter)")
    threshold: float | None = option(None, "log Bayes factor a candidate must clear (unset: the shipped "
                                     "calibration, threshold.json)")
    tie_nats: float = option(2.0, "accepted candidates within this many nats of the best are reported together")
    tie_fraction: float = option(0.01, "accepted candidates whose fitted changes move with the best's in every "
                                 "mode (correlation >= 0.95) and whose evidence is within this fraction of "
                                 "the best's gain are reported together too")
    effect_form_error: float = option(0.1, "per-mode model-form error of an effect's size (relative)")
    noise_guess: float = option(0.003, "prior mode of the relative frequency scatter per window")
    damping_noise_guess: float = option(0.2, "prior mode of the relative damping scatter per window")
    n_importance: int = option(3000, "importance draws of the evidence")
    nested_check: bool = option(True, "second evidence estimator (nested sampling) for accepted candidates")
    n_live: int = option(150, "live points of the nested-sampling check")
    prior_sensitivity: bool = option(True, "report the evidence with prior widths halved and doubled")
    catch_all: bool = option(True, "fit the catch-all discrepancy (reports unexplained structure)")
    second_round: bool = option(True, "after accepting one effect, fit the others on top of it")
    backfit_passes: int = option(3, "with several accepted effects, passes of refitting each on top of the "
                                 "others on every window (fewer when they settle)")
    surrogate_check: bool = option(True, "check the surrogate against the exact model at each fit")
    surrogate_tolerance: float = option(1e-4, "largest relative frequency error of the surrogate")
    frequency_gate: float = option(0.2, "pairing of tracked modes with model modes: relative frequency gate")
    mac_gate: float = option(0.8, "pairing of tracked modes with model modes: MAC gate")
    min_unpaired_fraction: float = option(0.5, "an unpaired mode seen in at least this share of windows is "
                                          "reported as unmodelled")
    misfit_correlation: str = option(MisfitCorrelation.DRIFT, "misfit from window to window: drift (a slow "
                                     "unmeasured driver is not read as an effect) or independent",
                                     choices=MisfitCorrelation)
    seed: int = option(0, "random seed (the same seed gives the same verdict)")
