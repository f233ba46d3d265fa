"""What pairing observed modes with model modes yields: the gate, the pairs and the modes left out.

The pairing itself (:mod:`shm_ros.core.bayes.pairing`) belongs to updating; its results travel with
the data (``ModalObservations.unmodelled_modes``) to every stage above, so they live here, below them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

# Automatic frequency gate: a model-form allowance plus the frequency shift a 3-sigma prior excursion
# of one factor can cause (frequencies go as the square root of a stiffness or inverse mass factor, so
# 3 sigma of a factor with coefficient of variation c moves them by about 1.5 c), kept within
# 15-25 %: tighter would leave out in-class modes of a rough nominal model, wider would admit modes
# of another class (a lateral mode 30 % from a vertical one).
GATE_MODEL_FORM = 0.10
GATE_PRIOR_SIGMAS = 1.5
GATE_RANGE = (0.15, 0.25)
DEFAULT_MAC_GATE = 0.8


def automatic_frequency_gate(prior_cv: float) -> float:
    """Relative frequency gate for priors whose largest coefficient of variation is ``prior_cv``."""
    if not math.isfinite(prior_cv):
        return GATE_RANGE[1]
    return float(np.clip(GATE_MODEL_FORM + GATE_PRIOR_SIGMAS * abs(prior_cv), *GATE_RANGE))


@dataclass(frozen=True)
class PairingGate:
    """How far an observed mode may be from its model mode: relative frequency and MAC."""

    frequency: float = 0.2
    mac: float = DEFAULT_MAC_GATE

    def __post_init__(self) -> None:
        if not self.frequency > 0:
            raise ValueError(f"frequency gate must be > 0, got {self.frequency}")
        if not 0 <= self.mac < 1:
            raise ValueError(f"MAC gate must be in [0, 1), got {self.mac}")

    @staticmethod
    def resolve(frequency: float, mac_gate: float, prior_cv: float) -> PairingGate:
        """The configured gate; ``frequency <= 0`` means automatic from the prior width."""
        f = frequency if frequency > 0 else automatic_frequency_gate(prior_cv)
        return PairingGate(float(f), float(mac_gate))

    def to_dict(self) -> dict[str, float]:
        return {"frequency": self.frequency, "mac": self.mac}


@dataclass
class UnmodelledMode:
    """An observed mode that pairs with no model mode, and why."""

    mode: int | None  # tracked mode number (None: a cluster of per-window estimates)
    frequency_hz: float
    nearest_model_mode: int  # 1-based, ascending model frequency
    nearest_model_frequency_hz: float
    frequency_ratio: float  # f_model / f_obs of the nearest model mode
    mac: float | None  # MAC with the nearest model mode (None: no shape)
    reason: str  # "frequency" | "mac" | "one-to-one"
    fraction_of_windows: float | None = None  # recordings: share of windows where it was found

    def to_dict(self) -> dict[str, Any]:
        return {"mode": self.mode, "frequency_hz": self.frequency_hz,
                "nearest_model_mode": self.nearest_model_mode,
                "nearest_model_frequency_hz": self.nearest_model_frequency_hz,
                "frequency_ratio": self.frequency_ratio, "mac": self.mac, "reason": self.reason,
                "fraction_of_windows": self.fraction_of_windows}

    def message(self, gate: PairingGate) -> str:
        who = f"observed mode {self.mode}" if self.mode is not None else "an identified mode"
        near = (f"nearest model mode {self.nearest_model_mode} ({self.nearest_model_frequency_hz:.3f} Hz, "
                f"ratio {self.frequency_ratio:.2f}" + ("" if self.mac is None else f", MAC {self.mac:.2f}")
                + ")")
        why = {"frequency": f"no model mode within a factor {1 + gate.frequency:.2f} of its frequency "
                            f"(the {100 * gate.frequency:.0f} % gate)",
               "mac": f"no model mode within the frequency gate reaches MAC {gate.mac:.2f}",
               "one-to-one": "every model mode within the gates is paired with an observed mode that "
                             "fits it better"}[self.reason]
        seen = "" if self.fraction_of_windows is None else f" in {self.fraction_of_windows:.0%} of windows"
        return (f"{who} at {self.frequency_hz:.3f} Hz{seen} left out of the updating: {why}; {near}. "
                "The model class may lack it (e.g. a lateral or torsional mode of a plane model).")


@dataclass
class ModePairing:
    """Observed modes ``observed`` (indices) paired with model modes ``model_index`` (0-based)."""

    observed: np.ndarray  # (k,) indices into the observed modes, ascending
    model_index: np.ndarray  # (k,) model mode of each kept observed mode
    unmodelled: list[UnmodelledMode] = field(default_factory=list)
    gate: PairingGate = field(default_factory=PairingGate)

    def same_as(self, other: ModePairing) -> bool:
        return (np.array_equal(self.observed, other.observed)
                and np.array_equal(self.model_index, other.model_index))

    def describe(self, mode_numbers: Sequence[int], at: str) -> dict[str, Any]:
        return {"at": at, "gate": self.gate.to_dict(),
                "observed_modes": [int(mode_numbers[i]) for i in self.observed],
                "model_modes": [int(j) + 1 for j in self.model_index]}
