"""What the building is like during one event: the effect-dependent part of the model.

An effect (``event_effects.py``) hands the assembler one :class:`StoryState` per event
the clean
building is ``StoryState.clean(n)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


class Spring(str, Enum):
    ELASTIC = "elastic"      # linear story springs
    STEEL02 = "steel02"      # elastic part in parallel with a Giuffre-Menegotto-Pinto hysteretic part
    CRACK = "crack"          # bilinear elastic, softer once the crack opens (positive drift only)


@dataclass
class Soil:
    """Footings on soil springs in x and y (one per column line, each a share of the totals)."""

    mass: float
    k_sway: float            # N/m, all footings together, each horizontal direction
    yield_sway: float        # m, first knee of the softening soil backbone


@dataclass
class StoryState:
    k_factor: np.ndarray                      # (n,) multiplies the story stiffness (x and y)
    spring: Spring = Spring.ELASTIC
    yield_drift: np.ndarray | None = None     # (n,) m: STEEL02 yield / CRACK opening drift per story
    nonlinear_share: float = 0.5              # STEEL02: share of the hysteretic part; CRACK: loss when open
    nonlinear_stories: list[int] = field(default_factory=list)
    damper_factor: np.ndarray | None = None   # (n,) multiplies the building's linear dampers
    brace_k: np.ndarray | None = None         # (n,) damper braces: stiffness, N/m (x and y)
    brace_c: np.ndarray | None = None         # (n,) and dashpot, N s/m
    quad_c: np.ndarray | None = None          # (n,) quadratic (orifice) dampers, N/(m/s)^2
    soil: Soil | None = None

    def is_linear(self) -> bool:
        nonlinear_springs = self.spring is not Spring.ELASTIC and bool(self.nonlinear_stories)
        quadratic = self.quad_c is not None and bool(np.any(self.quad_c > 0))
        return not (nonlinear_springs or quadratic or self.soil is not None)

    @classmethod
    def clean(cls, n: int) -> StoryState:
        return cls(k_factor=np.ones(n))
