"""Acceleration units: declared unit strings -> factor to m/s^2, and hints from the data when a
channel declared (or assumed) in m/s^2 looks like it is in another unit. Nothing is ever rescaled
on a hint: a wrong guess would silently corrupt the data, a wrong warning only costs a look."""

from __future__ import annotations

import math

G = 9.80665
#: Declared AccelBlock units -> factor to m/s^2 (lower-cased, spaces removed).
UNIT_FACTORS = {
    "": 1.0, "m/s^2": 1.0, "m/s2": 1.0, "m/s**2": 1.0, "ms^-2": 1.0, "m.s-2": 1.0, "ms-2": 1.0,
    "m/sec/sec": 1.0, "m/sec2": 1.0, "m/sec^2": 1.0,
    "g": G,
    "cm/s^2": 0.01, "cm/s2": 0.01, "cm/sec2": 0.01, "cm/sec^2": 0.01, "cm/sec/sec": 0.01, "gal": 0.01,
    "mm/s^2": 0.001, "mm/s2": 0.001, "mm/sec2": 0.001, "mg": G * 1e-3,
}


def unit_factor(units: str) -> float | None:
    """Factor from declared ``units`` to m/s^2, or None when the string is not recognised."""
    return UNIT_FACTORS.get(units.strip().lower().replace(" ", ""))


def _gravity_unit(level: float) -> str | None:
    """The unit in which a reading of ``level`` would be 1 g."""
    if 0.85 < level < 1.15:
        return "g"
    if 850 < level < 1150:
        return "cm/s^2"
    if 8500 < level < 11500:
        return "mm/s^2"
    return None


def units_hint_from_level(median: float, lo: float, hi: float) -> str | None:
    """What one channel's static level (its median) and range in a window suggest its unit is,
    when that is not m/s^2; None when m/s^2 is plausible."""
    peak = max(abs(lo), abs(hi))
    guess = _gravity_unit(abs(median))
    if guess == "g" and peak >= 4.0:
        guess = None  # a channel in g that reaches 4 g is implausible: a level near 1 m/s^2 it is
    if guess is None and peak > 2000:
        guess = "something other than m/s^2 (|a| > 2000 m/s^2)"
    return guess


def units_hint_from_gravity(magnitude: float) -> tuple[str | None, bool]:
    """An Imu at rest reads |a| = g over its three axes together (REP-145): ``(unit, implausible)``
    where ``unit`` is the unit that |a| suggests (None: m/s^2 or unknown) and ``implausible`` says
    that |a| fits no unit at all."""
    guess = _gravity_unit(magnitude)
    implausible = guess is None and not 0 < magnitude < 50 and math.isfinite(magnitude)
    return guess, implausible
