"""The simulator's default truth is richer than any analysis model, and says by how much.

The model-form report (``truth.json`` ``model_form``) fits the nominal file's parameters to the truth's
in-plane modes; what it cannot fit is model-form error. The girder's recordings also hold modes a 2-D
analysis model has no DOF for (torsion seen by off-centre vertical sensors).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import full_size
from scipy.signal import welch

from shm_ros.core.models import build_model
from shm_ros.core.simulate import named_scenario, scenario_from_dict, simulate_campaign
from shm_ros.core.structure import structure_from_dict

FREQ_MISS = 0.003  # a mode is missed by at least 0.3 % in frequency ...
MAC_MISS = 0.03  # ... or by at least 0.03 in MAC
SEEDS = list(range(16)) if full_size() else list(range(5))


def _missed(report: dict) -> list[bool]:
    return [abs(m["relative_error"]) >= FREQ_MISS or 1.0 - m["mac"] >= MAC_MISS for m in report["modes"][:3]]


@pytest.mark.parametrize("name", ["girder", "building"])
def test_best_fitting_analysis_model_misses_modes_1_to_3_of_the_default_campaign(name):
    c = simulate_campaign(named_scenario(name, n_windows=1, window_s=10.0))
    rep = c.truth_header()["model_form"]
    assert len(rep["modes"]) >= 3 and rep["kind"] == c.truth_model.kind
    assert all(_missed(rep)), rep["modes"][:3]
    # realistic, not absurd: a calibrated model is within 10 % on every in-plane mode
    assert rep["max_abs_relative_error"] < 0.10, rep["modes"]
    # the fitted factors are what a posterior should be compared with; they are not all 1
    theta = np.array(list(rep["theta_best"].values()))
    assert theta.size == len(c.truth_model.nominal.parameters) and np.all(theta > 0)
    # out-of-plane modes lie among the in-plane ones (a planar model cannot pair them)
    f_in = [m["truth_frequency_hz"] for m in rep["modes"]]
    oop = [o for o in rep["out_of_plane"] if f_in[0] < o["frequency_hz"] < f_in[-1]]
    fams = {o["family"] for o in oop}
    assert fams == ({"lateral", "torsion"} if name == "girder" else {"y", "torsion"}), rep["out_of_plane"]


@pytest.mark.parametrize("name", ["girder", "building"])
def test_model_form_error_is_not_one_seed_s_luck(name):
    """Per seed (the truth's scatter drawn anew) each of modes 1-3 is missed. When the defaults were
    set, each mode was missed in 15 or 16 of 16 seeds per kind (p >= 0.94 per mode and seed); at
    p = 0.94, at least 3 of 5 seeds (CI size) miss it with probability 0.997 and at least 11 of 16
    (full size) with probability > 0.999 (binomial tails)."""
    missed = np.array([_missed(simulate_campaign(named_scenario(name, n_windows=1, window_s=10.0, seed=seed))
                               .model_form_report()) for seed in SEEDS])
    need = 3 if len(SEEDS) == 5 else int(np.ceil(2 * len(SEEDS) / 3))
    assert np.all(missed.sum(axis=0) >= need), missed


def _peak_ratio(x: np.ndarray, fs: float, f0: float) -> float:
    f, p = welch(x - x.mean(), fs=fs, nperseg=1024)
    at = (f > f0 * 0.98) & (f < f0 * 1.02)
    near = (f > f0 * 0.85) & (f < f0 * 1.15)
    return float(p[at].max() / np.median(p[near]))


def test_girder_recordings_hold_torsion_modes_that_a_planar_model_cannot_have():
    c = simulate_campaign(named_scenario("girder", n_windows=1, window_s=120.0, seed=0))
    rep = c.model_form_report()
    tors = [o["frequency_hz"] for o in rep["out_of_plane"] if o["family"] == "torsion"]
    assert tors, rep["out_of_plane"]
    f_t = tors[0]
    # no analysis-model mode (nominal or best fit) sits near it
    nominal = build_model(structure_from_dict(c.nominal_structure)).modes(n_modes=8).frequencies_hz
    assert np.min(np.abs(nominal / f_t - 1)) > 0.05, (f_t, nominal)
    assert min(abs(m["model_frequency_hz"] / f_t - 1) for m in rep["modes"]) > 0.05
    w = c.window(0)
    y_off = c.truth_model.info["sensor_y"]
    sid = max(y_off, key=lambda s: abs(y_off[s]))  # the sensor farthest off the centre line
    col = w.sensor_ids.index(sid)
    ratio = _peak_ratio(w.recording.values[:, col], c.scenario.fs, f_t)
    assert ratio > 5.0, (sid, f_t, ratio)
    # the same window of a planar truth has no such peak: the torsion mode is what makes it
    flat = simulate_campaign(named_scenario("girder", n_windows=1, window_s=120.0, seed=0, model_form=False))
    w0 = flat.window(0)
    assert "model_form" not in flat.truth_model_summary()
    ratio0 = _peak_ratio(w0.recording.values[:, col], flat.scenario.fs, f_t)
    assert ratio0 < ratio / 3, (ratio0, ratio)


def test_truth_entries_mark_mode_families_and_model_form_switches_off():
    for name, inplane, others in (("girder", "vertical", {"lateral", "torsion"}), ("building", "x", {"y", "torsion"})):
        c = simulate_campaign(named_scenario(name, n_windows=1, window_s=10.0, seed=2))
        e = c.window(0).truth
        fam = e["mode_families"]
        assert len(fam) == len(e["frequencies_hz"]) and np.all(np.diff(e["frequencies_hz"]) >= 0)
        assert fam.count(inplane) == c.scenario.n_truth_modes  # n_truth_modes counts in-plane modes
        assert set(fam) - {inplane} == others
        off = scenario_from_dict({"scenario": name, "n_windows": 1, "window_s": 10.0, "seed": 2, "model_form": False})
        assert off.model_form is False
        c0 = simulate_campaign(off)
        e0 = c0.window(0).truth
        assert set(e0["mode_families"]) == {inplane} and len(e0["frequencies_hz"]) == c0.scenario.n_truth_modes
        assert c0.model_form_report()["out_of_plane"] == []
        assert all(s["sensitivity_xyz"] is None for s in c0.truth_header()["sensors"])
        assert all(0.5 <= s["misalignment_deg"] <= 2.0 and 0.97 <= abs(s["gain"]) <= 1.03
                   and abs(abs(s["gain"]) - 1) >= 0.01 for s in c.truth_header()["sensors"])
