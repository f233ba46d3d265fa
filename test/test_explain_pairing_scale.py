"""A nominal model further off than the pairing gate in every mode (a building truth 25 % stiffer in
frequency than its structure file) is paired after one common frequency scale and calibrated from
there, instead of stopping explain (it stopped with a numpy reduction error)."""

from __future__ import annotations

from dataclasses import replace

from explain_fit_synth import building_table

from shm_ros.core.explain.config import ExplainConfig
from shm_ros.core.explain.explain import explain
from shm_ros.io.structure import load_structure
from shm_ros.io.tables import read_tracked_modes


def test_a_model_off_beyond_the_gate_is_paired_after_a_common_scale(tmp_path):
    structure, table = building_table(tmp_path, seed=1, n_windows=96)
    obs = read_tracked_modes(table)
    obs = replace(obs, frequencies_hz=obs.frequencies_hz * 1.25)
    v = explain(obs, load_structure(structure), ExplainConfig(nested_check=False, prior_sensitivity=False,
                                                              n_importance=1000))
    assert v.status == "ok" and v.model_fits is not None
    # the stiffness priors (sd 10 %) hold the calibration short of +56 %: a mode may stay unpaired,
    # and is listed as such; nothing else is named
    named = [c.name for c in v.missing_physics]
    assert set(named) <= {"unmodelled_modes"} and len(named) <= 1, named
