"""The one extension point of explain: a candidate physics is a small class in this package.

A candidate changes the analysis model per window: it returns, for a batch of its own parameter
vectors, multiplicative factors on parameter groups (:mod:`shm_ros.core.explain.groups`) for every
window, computed from the window's covariates and time (:class:`Context`); a damping candidate
returns factors on the modal damping instead. Everything else (the surrogate's frequencies, the
likelihood, the fit, the evidence, the report) is shared. A new effect is a new file here with a
class registered by ``@CANDIDATES.register("<label>")``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from shm_ros.core.plugins import KindRegistry


@dataclass(frozen=True)
class ParamSpec:
    """A candidate parameter with a physical, bounded prior (uniform on [lo, hi], or log-uniform)."""

    name: str
    lo: float
    hi: float
    null: float | None = None  # value at which the candidate reduces to the nominal model
    log: bool = False  # log-uniform prior
    unit: str = ""
    # a parameter the likelihood is not smooth in (a knee, a change time): the fit scans it on a grid
    # and the evidence integrates it with a piecewise-constant proposal instead of a Gaussian one
    grid: bool = False
    # a moment in the campaign (seconds since the first window, e.g. a change time): the held-out check
    # leaves out the held-out windows the training windows cannot place it among (Candidate.time_span)
    moment: bool = False


@dataclass
class Context:
    """What a candidate may depend on, per window (analysis windows in time order)."""

    times_s: np.ndarray  # (W,) seconds since the first window
    covariates: dict[str, np.ndarray]  # temperature_c, rms_accel_m_s2, pga_m_s2, ... (W,) NaN = missing
    start_epoch_s: float = 0.0  # POSIX time of times_s == 0 (for ISO times in the verdict)
    hints: dict[str, Any] = field(default_factory=dict)  # from locate: knee guess, change window, ...


@dataclass
class Modification:
    """A candidate's effect for a batch: factors (B, W) per group name; ``damping`` (B, W) or None;
    ``added_damping`` (B, W) or None: stiffness-proportional damping added to the inherent one, as
    the first mode's added ratio in units of its inherent one (time domain only,
    :class:`shm_ros.core.explain.td_model.FactorModel`)."""

    groups: dict[str, np.ndarray]
    damping: np.ndarray | None = None
    added_damping: np.ndarray | None = None


class Candidate(ABC):
    """Base class of every candidate physics (see module docstring)."""

    name: ClassVar[str]  # registry label, set by the registry
    vocabulary: ClassVar[str]  # docs/interfaces.md §5 name
    explanation: ClassVar[str] = ""  # plain words for an engineer
    # groups tried when nothing (locate) says where to look; "EI:*" = every numbered EI group
    default_groups: ClassVar[tuple[str, ...]] = ("EI",)

    def __init__(self, group: str, context: Context):
        self.group = group  # the parameter group it acts on (see groups.py), e.g. "EI", "EI:2", "bearings"
        self.context = context

    @property
    def label(self) -> str:
        return f"{self.vocabulary}/{self.name}/{self.group}"

    @abstractmethod
    def params(self) -> list[ParamSpec]:
        ...

    @abstractmethod
    def modify(self, theta: np.ndarray) -> Modification:
        """theta (B, p) -> factors per window."""

    @abstractmethod
    def form(self, theta: np.ndarray) -> str:
        """Plain-words form with the fitted values, theta (p,)."""

    def time(self, theta: np.ndarray) -> float | None:
        """Seconds since the first window at which the effect starts, if it starts at a moment."""
        return None

    def time_span(self, theta: np.ndarray, intervals: dict[str, tuple[float, float]]) -> tuple[float, float] | None:
        """Seconds since the first window within which the effect starts, as the data place it: its
        ``time`` at ``theta`` widened by the 95 % intervals of its ``moment`` parameters; None when it
        does not start at a moment. The held-out check leaves out the held-out windows between the
        training windows that bracket this span (:func:`shm_ros.core.explain.scoring.judged_windows`):
        the training windows cannot fix their prediction."""
        t = self.time(theta)
        if t is None:
            return None
        ends = [t, *(x for p in self.params() if p.moment and p.name in intervals for x in intervals[p.name])]
        return float(min(ends)), float(max(ends))

    def look_elsewhere(self) -> float:
        """Nats taken off the evidence gain for a prior narrowed around a hint from locate (which read
        the same data): ln of the full prior range over the narrowed one. 0 for a full prior."""
        return 0.0

    def key_parameter(self) -> str:
        """The parameter whose interval must exclude its null value for the candidate to be accepted."""
        return self.params()[0].name

    def describe(self, theta: np.ndarray) -> dict[str, float]:
        return {p.name: float(v) for p, v in zip(self.params(), np.asarray(theta, float), strict=True)}


CANDIDATES: KindRegistry[Candidate] = KindRegistry("explain candidate", "shm_ros.core.explain.candidates")
