"""Interstory drift-ratio limits of a building (the structure file's optional ``drift_limits``).

```yaml
drift_limits:
  limits: [0.004, 0.01, 0.02]   # drift ratios checked per story (ascending)
  elastic: 0.004                # up to here the model's linear story springs hold
  stories: {1: [0.003, 0.01]}   # optional: a story's own limits (1-based), replacing ``limits``
```

Defaults (:data:`DEFAULT_LIMITS`, no ``drift_limits`` in the file): 0.005 (damage limitation of
buildings with brittle non-structural elements, Eurocode 8 §4.4.3.2: 0.005 h), 0.01 (ductile
non-structural elements or none, EC8: 0.0075-0.010 h) and 0.02 (life safety of frames, ASCE 7
Table 12.12-1: 0.020 h for risk category I/II); the elastic range ends at the smallest limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

DEFAULT_LIMITS = (0.005, 0.01, 0.02)


@dataclass(frozen=True)
class DriftLimits:
    limits: tuple[float, ...] = DEFAULT_LIMITS
    elastic: float = DEFAULT_LIMITS[0]
    stories: dict[int, tuple[float, ...]] = field(default_factory=dict)  # 1-based story -> its limits
    given: bool = False  # from the structure file (else the defaults)

    def for_story(self, story: int) -> tuple[float, ...]:
        return self.stories.get(story, self.limits)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"limits": list(self.limits), "elastic": self.elastic}
        if self.stories:
            out["stories"] = {k: list(v) for k, v in self.stories.items()}
        return out


def parse_drift_limits(c: Any, v: Any, n_stories: int | None) -> DriftLimits:
    """``drift_limits`` read with the structure file's field reader ``c`` (errors name the field)."""
    d = c.mapping(v, "drift_limits")
    c.keys(d, ("limits", "elastic", "stories"), (), "drift_limits")

    def ratios(x: Any, fld: str) -> tuple[float, ...]:
        vals = [c.number(r, f"{fld}[{i}]", nonneg=True) for i, r in enumerate(c.seq(x, fld))]
        if not vals:
            raise c.err("needs at least one drift ratio", fld)
        for i, r in enumerate(vals):
            if not 0.0 < r < 0.2:
                raise c.err(f"a drift ratio is a fraction of the story height in (0, 0.2), got {r:g}", f"{fld}[{i}]")
        if list(vals) != sorted(vals):
            raise c.err("limits must be ascending", fld)
        return tuple(float(r) for r in vals)

    limits = ratios(d["limits"], "drift_limits.limits") if "limits" in d else DEFAULT_LIMITS
    stories: dict[int, tuple[float, ...]] = {}
    if "stories" in d:
        for k, x in c.mapping(d["stories"], "drift_limits.stories").items():
            fld = f"drift_limits.stories.{k}"
            try:
                story = int(k)
            except (TypeError, ValueError):
                raise c.err(f"a story is a number (1 = the lowest), got {k!r}", fld) from None
            if story < 1 or (n_stories is not None and story > n_stories):
                raise c.err(f"no story {story} (the building has {n_stories})", fld)
            stories[story] = ratios(x, fld)
    elastic = float(c.number(d["elastic"], "drift_limits.elastic", nonneg=True)) if "elastic" in d \
        else min(min(limits), *(min(v) for v in stories.values())) if stories else min(limits)
    if not 0.0 < elastic < 0.2:
        raise c.err(f"must be a drift ratio in (0, 0.2), got {elastic:g}", "drift_limits.elastic")
    return DriftLimits(limits, elastic, stories, True)
