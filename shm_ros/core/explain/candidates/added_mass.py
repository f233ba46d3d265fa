"""Added mass: a mass on the deck / a floor, always there or only some of the time.

When the mass is there comes from locate's hints: ``when = "hours"`` (one or two windows of the
day, e.g. jammed traffic at the morning and evening rush hours, ``hours_utc``: ``[[start, end], ...]``
in hours UTC), ``"below"`` (below a temperature, e.g. snow or ice, ``below_c``), ``"after"`` (from a
window on, e.g. new equipment or ballast, ``change_index``); without a hint it is always there.
The one parameter is the added fraction of the group's mass.
"""

from __future__ import annotations

import numpy as np

from ._common import (
    after_change,
    change_time,
    daily_windows,
    hinted_time_span,
    hinted_window_look_elsewhere,
    hour_utc,
    hours_text,
    temperatures,
)
from .base import CANDIDATES, Candidate, Modification, ParamSpec


@CANDIDATES.register("added_mass")
class AddedMass(Candidate):
    vocabulary = "added_mass"
    explanation = ("Mass that the model does not include (traffic standing on the deck, snow, ice, new "
                   "equipment) lowers every frequency a little, most in the modes that move that part.")
    default_groups = ("mass", "mass:*")

    def params(self) -> list[ParamSpec]:
        return [ParamSpec("mass_fraction", 0.0, 0.5, null=0.0, unit="fraction of the group's mass")]

    def active(self) -> np.ndarray:
        """(W,) 1 where the mass is there."""
        h, W = self.context.hints, len(self.context.times_s)
        when = str(h.get("when", "always"))
        if when == "hours" and "hours_utc" in h:
            return daily_windows(hour_utc(self.context), h["hours_utc"]).astype(float)
        if when == "below" and "below_c" in h:
            return (temperatures(self.context)[0] < float(h["below_c"])).astype(float)
        if when == "after" and "change_index" in h:
            return after_change(self.context)
        return np.ones(W)

    def modify(self, theta: np.ndarray) -> Modification:
        frac = np.atleast_2d(np.asarray(theta, float))[:, 0]
        return Modification(groups={self.group: 1.0 + frac[:, None] * self.active()[None, :]})

    def form(self, theta: np.ndarray) -> str:
        h = self.context.hints
        when = {"hours": f"{hours_text(h.get('hours_utc', []))} UTC",
                "below": f"below {h.get('below_c', float('nan')):.1f} degC",
                "after": f"from window {h.get('change_index')}"}.get(str(h.get("when", "")), "always")
        whose = "the whole mass" if self.group == "mass" else f"the mass of {self.group}"
        return f"{100 * float(np.ravel(theta)[0]):.1f} % of {whose} added {when}"

    def time(self, theta: np.ndarray) -> float | None:
        h = self.context.hints
        if h.get("when") == "after" and "change_index" in h:
            return change_time(self.context)
        return None

    def time_span(self, theta: np.ndarray, intervals: dict[str, tuple[float, float]]) -> tuple[float, float] | None:
        return None if self.time(theta) is None else hinted_time_span(self.context)

    def look_elsewhere(self) -> float:
        """From the hinted window on: ln(full range / hinted range) (:func:`._common.hinted_window_look_elsewhere`)."""
        return hinted_window_look_elsewhere(self.context) if self.context.hints.get("when") == "after" else 0.0
