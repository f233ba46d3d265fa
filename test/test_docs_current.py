"""Generated documentation is current: docs/parameters.md is what the configuration dataclasses say."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_parameters_doc_is_generated_from_the_current_configurations():
    from shm_ros.ros.params_doc import render

    assert (ROOT / "docs" / "parameters.md").read_text() == render(), (
        "docs/parameters.md is out of date: python -m shm_ros.ros.params_doc > docs/parameters.md")
