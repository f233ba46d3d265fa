"""Hidden effects: physics the truth model has and the nominal structure file does not mention.

Each effect is switched on by its key and parameterised by a small dict; :func:`make_effect` fills in
the defaults. Per window, an effect turns the window's conditions (time, temperature, local hour)
into multiplicative factors on groups of truth-model terms:

==================  ===========================================================================
group               girder truth model                      shear-building truth model
==================  ===========================================================================
``EI``              bending stiffness of every span         story stiffness of every story
``EI:<k>``          span k (1-based)                        story k (1-based)
``bearings``        vertical and rotational bearing springs (not used)
``mass``            deck mass                               every floor mass
``damper``          (not used)                              stiffness and dashpot of damper braces
==================  ===========================================================================

Effects that change the model's form (foundation sway of a building, damper braces) or that depend
on the response amplitude are carried out by :mod:`shm_ros.core.simulate.truth` and
:mod:`shm_ros.core.simulate.newmark`; their entries here only hold parameters and the documented
amount. ``docs/simulator.md`` states for each effect how much it changes the modal properties.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

from shm_ros.core.simulate.truth_kinds import TRUTH_KINDS, truth_class
from shm_ros.errors import InputError

# key -> (vocabulary name of docs/interfaces.md section 5, one line on what it does). The default
# parameters per structure kind belong to each kind's truth model (``TruthModel.effect_defaults``).
EFFECTS: dict[str, tuple[str, str]] = {
    "temperature_linear": ("temperature_dependent_stiffness", "stiffness linear in the air temperature"),
    "temperature_bilinear": ("temperature_dependent_stiffness", "stiffness bilinear in the air temperature"),
    "damage": ("stiffness_change_at_time", "stiffness drops at a time"),
    "repair": ("stiffness_change_at_time", "stiffness rises at a time"),
    "added_mass": ("added_mass", "mass added at some times"),
    "support_flexibility": ("support_flexibility", "soil under the supports"),
    "amplitude_stiffness": ("amplitude_dependent_stiffness", "stiffness falls with the response amplitude"),
    "amplitude_damping": ("amplitude_dependent_damping", "damping grows with the response amplitude"),
    "damper": ("damper_stiffness", "damper braces, which may fail"),
}

# frozen elastomeric bearings lock up: their springs (chiefly the small rotational restraint) grow
# by orders of magnitude below the knee, which is what shifts a girder's frequencies
BEARING_DEFAULTS: dict[str, dict[str, Any]] = {
    "temperature_linear": {"alpha_per_c": -0.02},
    "temperature_bilinear": {"alpha_per_c": -0.01, "below_per_c": -20.0},
}

RUSH_HOURS = ((7.0, 9.5), (17.0, 19.5))  # local time, added mass of slow or jammed traffic


class EffectError(InputError):
    """An effect is unknown, not available for the structure kind, or badly parameterised."""


@dataclass
class Conditions:
    """What an effect may depend on in one window."""

    t_s: float  # mid-window time since the campaign start, s
    temperature_c: float  # true mean air temperature over the window
    local_hour: float  # local time of day at mid-window, h


@dataclass
class Effect:
    key: str
    name: str
    params: dict[str, Any]
    kind: str
    start_epoch_s: float = 0.0
    _at_s: float | None = field(default=None, repr=False)

    # -- time ---------------------------------------------------------------------------------
    def time_s(self, value: Any) -> float | None:
        """Seconds since the campaign start of ``value`` ("48h", "2d", "90m", "3600s", ISO time)."""
        return parse_time(value, self.start_epoch_s)

    # -- per-window factors -------------------------------------------------------------------
    def factors(self, c: Conditions) -> dict[str, float]:
        p = self.params
        if self.key in ("temperature_linear", "temperature_bilinear"):
            f = 1.0 + p["alpha_per_c"] * (c.temperature_c - p["t_ref_c"])
            if self.key == "temperature_bilinear":
                f += p["below_per_c"] * min(c.temperature_c - p["knee_c"], 0.0)
            return {self._stiffness_group(): max(f, 0.05)}
        if self.key in ("damage", "repair"):
            at = self.time_s(p["at"])
            if at is not None and c.t_s >= at:
                return {self._stiffness_group(): float(p["factor"])}
            return {}
        if self.key == "added_mass":
            return {"mass": 1.0 + p["fraction"]} if self._mass_active(c) else {}
        if self.key == "damper":
            at = self.time_s(p.get("fail_at"))
            if at is not None and c.t_s >= at:
                return {"damper": float(p["fail_factor"])}
            return {}
        return {}

    def _stiffness_group(self) -> str:
        where = str(self.params.get("where", "deck"))
        if where in ("deck", "stories", "all"):
            return "EI"
        extra = truth_class(self.kind).stiffness_wheres
        if where in extra:
            return extra[where]
        m = re.fullmatch(r"(span|story)(\d+)", where)
        if m is None:
            more = [w for c in TRUTH_KINDS for w in c.stiffness_wheres if c is not truth_class(self.kind)]
            hint = f"; {', '.join(more)} exist for other kinds only" if more else ""
            raise EffectError(f"effect {self.key}: where={where!r} "
                              f"(deck, stories, all, {''.join(w + ', ' for w in extra)}spanK or storyK{hint})")
        return f"EI:{int(m.group(2))}"

    def _mass_active(self, c: Conditions) -> bool:
        when = str(self.params.get("when", "always"))
        if when == "always":
            return True
        if when == "rush_hours":
            return any(a <= c.local_hour < b for a, b in RUSH_HOURS)
        if when.startswith("below:"):
            return c.temperature_c < float(when.split(":", 1)[1])
        if when.startswith("after:"):
            at = self.time_s(when.split(":", 1)[1])
            return at is not None and c.t_s >= at
        raise EffectError(f"effect added_mass: when={when!r} (always, rush_hours, below:T, after:TIME)")

    def describe(self) -> dict[str, Any]:
        return {"key": self.key, "name": self.name, "parameters": dict(self.params),
                "form": self.form(), "where": self.params.get("where", _default_where(self.key, self.kind))}

    def form(self) -> str:
        p = self.params
        if self.key == "temperature_linear":
            return f"linear, {p['alpha_per_c'] * 100:+.2f} %/degC of stiffness about {p['t_ref_c']} degC"
        if self.key == "temperature_bilinear":
            return (f"bilinear, knee at {p['knee_c']} degC, {p['alpha_per_c'] * 100:+.2f} %/degC above, "
                    f"{(p['alpha_per_c'] + p['below_per_c']) * 100:+.2f} %/degC below")
        if self.key in ("damage", "repair"):
            return f"stiffness x{p['factor']} from {p['at']}"
        if self.key == "added_mass":
            return f"mass x{1 + p['fraction']:.3f} when {p['when']}"
        forms = truth_class(self.kind).effect_forms
        if self.key in forms:
            return forms[self.key]
        if self.key == "damper":
            return f"{p['model']} damper braces, k_d = {p['k_rel']} k_story, c_d = {p['c_rel_s']} s x k_d"
        return self.key


def _default_where(key: str, kind: str) -> str:
    where = truth_class(kind).effect_where
    return where.get(key, where.get("*", "all"))


def make_effect(key: str, kind: str, params: dict[str, Any] | None = None, start_epoch_s: float = 0.0) -> Effect:
    """Effect ``key`` for structure ``kind`` with ``params`` over the defaults (unknown params fail)."""
    if key not in EFFECTS:
        raise EffectError(f"unknown effect {key!r} (known: {', '.join(EFFECTS)})")
    name = EFFECTS[key][0]
    available = [c.name for c in TRUTH_KINDS if key in c.effect_defaults]
    if kind not in available:
        raise EffectError(f"effect {key!r} is not available for {kind} structures "
                          f"(available for: {', '.join(available)})")
    merged = dict(truth_class(kind).effect_defaults[key])
    if (params or {}).get("where") == "bearings" and key in BEARING_DEFAULTS:
        merged.update(BEARING_DEFAULTS[key])
    for k, v in (params or {}).items():
        if k not in merged:
            raise EffectError(f"effect {key!r}: unknown parameter {k!r} (known: {', '.join(merged)})")
        merged[k] = v
    eff = Effect(key=key, name=name, params=merged, kind=kind, start_epoch_s=start_epoch_s)
    if key in ("temperature_linear", "temperature_bilinear", "damage", "repair"):
        eff._stiffness_group()  # validate where
    for k in ("at", "fail_at"):
        if merged.get(k) is not None:
            eff.time_s(merged[k])
    return eff


def parse_effects(text: str) -> list[tuple[str, dict[str, Any]]]:
    """``"temperature_bilinear,damage@48h:factor=0.9:where=span1"`` -> [(key, params), ...].

    ``key[@TIME][:name=value]...``; ``@TIME`` sets ``at`` (damage, repair) or ``fail_at`` (damper).
    """
    out = []
    for item in [t.strip() for t in text.split(",") if t.strip()]:
        parts = item.split(":")
        head, params = parts[0], {}
        for kv in parts[1:]:
            if "=" not in kv:
                raise EffectError(f"--effects: {item!r}: expected name=value after ':', got {kv!r}")
            k, v = kv.split("=", 1)
            params[k.strip()] = _value(v.strip())
        if "@" in head:
            head, at = head.split("@", 1)
            params["fail_at" if head == "damper" else "at"] = at
        out.append((head.strip(), params))
    return out


def _value(v: str) -> Any:
    for conv in (int, float):
        try:
            return conv(v)
        except ValueError:
            pass
    return {"none": None, "true": True, "false": False}.get(v.lower(), v)


def parse_time(value: Any, start_epoch_s: float = 0.0) -> float | None:
    if value is None:
        return None
    if isinstance(value, (int, float)):
        return float(value)
    s = str(value).strip()
    m = re.fullmatch(r"([0-9.]+)\s*(s|m|min|h|d)?", s)
    if m:
        unit = {"s": 1.0, None: 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}[m.group(2)]
        return float(m.group(1)) * unit
    try:
        t = datetime.fromisoformat(s.replace("Z", "+00:00"))
    except ValueError:
        raise EffectError(f"bad time {s!r}: use 48h, 2d, 90m, 3600s or an ISO time") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=timezone.utc)
    return t.timestamp() - start_epoch_s
