"""Random event campaigns from the project's linear simulator, for explain's robustness acceptance.

A campaign is drawn from a seed: an n-story shear building with its ground sensor as the measured
input (the simulator's ``building-earthquake`` scenario: one earthquake per burst), E events of T s at
F Hz, and in some campaigns a dead sensor (the simulator's ``dead`` fault: a channel that records a
constant) or a missing one (the structure file names a sensor the recording lacks). CI draws from a
reduced range (2-3 stories: the simulator's shear building has at least two; 3-6 events of 20 s at
50 or 100 Hz); the full size (``SHM_FULL=1``) from 2-10 stories, 3-30 events of 20-60 s at 50-500 Hz.

Each campaign goes through ``shm-ros explain --bag`` and ``--events``, with or without ``--window``,
in the same process as a user's command line (:func:`shm_ros.cli.main`): the outcome is the exit code,
the verdict file and whether a candidate failed numerically.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from shm_ros.cli import main


@dataclass
class CampaignSpec:
    seed: int
    floors: int
    events: int
    event_s: float
    fs: float
    fault: str  # "", "dead" or "missing"

    @classmethod
    def draw(cls, seed: int, full: bool) -> CampaignSpec:
        rng = np.random.default_rng([7321, seed])
        if full:
            return cls(seed, int(rng.integers(2, 11)), int(rng.integers(3, 31)), float(rng.choice([20, 30, 40, 60])),
                       float(rng.choice([50, 100, 200, 500])), str(rng.choice(["", "", "dead", "missing"])))
        return cls(seed, int(rng.integers(2, 4)), int(rng.integers(3, 7)), 20.0, float(rng.choice([50, 100])),
                   str(rng.choice(["", "", "dead", "missing"])))


def simulate(spec: CampaignSpec, out: Path) -> tuple[Path, Path]:
    """The campaign's bag and structure file (a missing sensor added to the file, not the recording)."""
    args = ["simulate", "building-earthquake", "--out", str(out), "--floors", str(spec.floors), "--windows",
            str(spec.events), "--window-s", str(spec.event_s), "--fs", str(spec.fs), "--seed", str(spec.seed),
            "--quiet"]
    if spec.fault == "dead":
        args += ["--faults", "dead:f1"]
    assert main(args) == 0, spec
    structure = out / "structure.yaml"
    if spec.fault == "missing":
        doc = yaml.safe_load(structure.read_text())
        doc["sensors"].append({"id": "f_missing", "at": {"floor": spec.floors}, "direction": "x"})
        structure.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out / "bag", structure


@dataclass
class Outcome:
    path: str
    window: float | None
    code: int
    verdict: dict | None

    @property
    def failed_candidates(self) -> list[str]:
        return [c["label"] for c in (self.verdict or {}).get("candidates", []) if c.get("failed")]


def explain(bag: Path, structure: Path, path: str, window: float | None, out: Path, within_event: bool = False
            ) -> Outcome:
    """One ``shm-ros explain`` run (``path``: "bag" or "events"). The time-domain path (``--events``, and
    ``--bag`` beside the per-event modal estimates) fits per event only unless ``within_event``: the
    within-event fits have their own tests and cost about half of a run."""
    args = ["explain", "--structure", str(structure), f"--{path}", str(bag), "--out", str(out), "--no-report"]
    if window is not None:
        args += ["--window", str(window)]
    if not within_event:
        args += ["--time-domain.resolutions", "per_event"]
    code = main(args)
    f = out / "verdict.json"
    return Outcome(path, window, code, json.loads(f.read_text()) if f.exists() else None)
