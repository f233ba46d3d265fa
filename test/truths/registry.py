"""The campaign registry: ``make_campaign(kind, seed, size)`` -> :class:`Campaign` (files + answer)."""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from . import dense_campaign, dense_effects, event_campaign
from .event_effects import EFFECTS

KINDS: tuple[str, ...] = (*EFFECTS, *dense_effects.ANY, *dense_effects.GIRDER_ONLY)
SIZES = ("reduced", "full")


@dataclass(frozen=True)
class Campaign:
    kind: str
    seed: int
    size: str
    directory: Path
    structure: Path            # nominal structure YAML
    data: Path                 # the bag (event kinds) or tracked_modes.csv (dense kinds)
    truth: Path                # truth.json
    expected: str              # vocabulary name, "none" or "unexplained_structure"
    acceptable: tuple[str, ...]

    @property
    def is_event(self) -> bool:
        return self.kind.startswith("event_")


def make_campaign(kind: str, seed: int, size: str = "reduced", out: str | Path | None = None) -> Campaign:
    """Generate one campaign into ``out`` (default: a new directory under ``$SHM_TRUTHS_DIR`` or the
    temporary directory). Deterministic for a kind, seed and size."""
    if kind not in KINDS:
        raise ValueError(f"unknown campaign kind {kind!r}; known: {', '.join(KINDS)}")
    if size not in SIZES:
        raise ValueError(f"size must be 'reduced' or 'full', got {size!r}")
    if out is None:
        base = Path(os.environ.get("SHM_TRUTHS_DIR", tempfile.gettempdir()))
        base.mkdir(parents=True, exist_ok=True)
        out = Path(tempfile.mkdtemp(prefix=f"{kind}-{seed}-{size}-", dir=base))
    out = Path(out)
    if kind.startswith("event_"):
        truth = event_campaign.generate(kind, seed, size, out)
        data = out / "events"
    else:
        truth = dense_campaign.generate(kind, seed, size, out)
        data = out / "tracked_modes.csv"
    return Campaign(kind=kind, seed=seed, size=size, directory=out, structure=out / "structure.yaml", data=data,
                    truth=out / "truth.json", expected=truth["expected"], acceptable=tuple(truth["acceptable"]))
