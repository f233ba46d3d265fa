"""Settings of one explain run (every field has a default; plain data)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class ExplainConfig:
    held_out_every: int = 4  # every 4th block of windows is held out of the fit
    block_windows: int = 0  # windows per block (0: one day of windows, or W / 8 if shorter)
    threshold: float | None = None  # log Bayes factor a candidate must clear (None: the shipped calibration)
    tie_nats: float = 2.0  # accepted candidates within this of the best are reported together
    effect_form_error: float = 0.1  # tau: per-mode model-form error of an effect's size
    noise_guess: float = 0.003  # prior mode of the relative frequency scatter per window
    damping_noise_guess: float = 0.2  # prior mode of the relative damping scatter per window
    n_importance: int = 3000  # importance draws of the evidence
    nested_check: bool = True  # second evidence estimator (nested sampling) for candidates that clear the threshold
    n_live: int = 150
    prior_sensitivity: bool = True
    catch_all: bool = True
    second_round: bool = True  # after accepting one effect, fit the others on top of it
    surrogate_check: bool = True  # check the surrogate against the exact model at the MAP's factors
    surrogate_tolerance: float = 1e-4
    frequency_gate: float = 0.2  # pairing of tracked modes with model modes
    mac_gate: float = 0.8
    min_unpaired_fraction: float = 0.5  # an unpaired mode seen in at least this share of windows is reported
    seed: int = 0
