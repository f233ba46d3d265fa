"""Reference placement from the nominal model (shm_ros/core/roving/placement.py): the exhaustive
search agrees with a hand-made case, and the example's references are where it puts them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shm_ros.core.roving.placement import deck_references, place_references
from shm_ros.io.structure import load_structure


def test_the_weakest_mode_is_seen_best():
    # three candidates, two modes: a node of mode 2 at candidate 0, of mode 1 at candidate 2
    shapes = np.array([[1.0, 0.0], [0.7, 0.7], [0.0, 1.0]])
    assert place_references([0.0, 1.0, 2.0], shapes, 2) == [0, 2]  # each mode seen at 1.0
    assert place_references([0.0, 1.0, 2.0], shapes, 1) == [1]  # one reference: both modes at 0.7


def test_the_example_references_are_placed_from_the_nominal_model():
    spec = load_structure(Path(__file__).resolve().parents[1] / "examples" / "girder_roving.yaml")
    assert deck_references(spec, 2, 3) == [s.at["x"] for s in spec.sensors]
