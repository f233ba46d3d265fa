"""The explain case generator (test/explain_cases.py): each effect does what the generator states."""

from __future__ import annotations

import numpy as np
import pytest
from explain_cases import EFFECTS, MIN_COVARIATE_PTP, MIN_MASS_FRACTION, MIN_STEP, draw_case

SEED = 11


@pytest.mark.parametrize("effect,kind", [
    ("temperature_dependent_stiffness", "girder"), ("temperature_dependent_stiffness", "building"),
    ("amplitude_dependent_stiffness", "building"), ("stiffness_change_at_time", "girder"),
    ("damper_stiffness", "building"), ("support_flexibility", "girder"), ("added_mass", "building")])
def test_effect_changes_frequencies_by_the_stated_amount(effect, kind):
    c = draw_case(SEED, effect, kind, n_windows=432)
    ip = [c.obs.mode_numbers.index(m) for m in c.truth.in_plane_modes]
    lf = np.log(c.f_true[:, ip])
    if c.truth.change_index is not None and effect != "added_mass":
        assert c.truth.size >= 0.9 * MIN_STEP  # the step's own part (scaled to >= 1.5 % within 10 %)
    elif effect == "added_mass":
        assert c.truth.parameters["fraction"] >= MIN_MASS_FRACTION
        assert np.max(np.ptp(lf, axis=0)) > 0.002
    else:
        assert np.max(np.quantile(lf, 0.99, axis=0) - np.quantile(lf, 0.01, axis=0)) >= 0.9 * MIN_COVARIATE_PTP
    assert c.truth.where
    assert c.truth.out_of_plane_modes  # the tracker also holds out-of-plane modes
    assert set(c.truth.out_of_plane_modes).isdisjoint(c.truth.in_plane_modes)


def test_clean_case_has_no_effect_and_in_plane_modes_only():
    c = draw_case(SEED, "clean", "girder", n_windows=288)
    assert c.truth.out_of_plane_modes == []
    assert np.allclose(np.ptp(c.f_true, axis=0), 0.0)
    scatter = np.nanstd(np.log(c.obs.frequencies_hz), axis=0)
    assert np.all((scatter > 0.0015) & (scatter < 0.006))  # identification scatter 0.2-0.5 %


def test_amplitude_damping_raises_damping_with_the_amplitude():
    c = draw_case(SEED, "amplitude_dependent_damping", "girder", n_windows=432)
    a = c.obs.covariates["rms_accel_m_s2"]
    hi, lo = a > np.quantile(a, 0.8), a < np.quantile(a, 0.2)
    z = np.log(c.obs.damping)
    assert np.nanmean(z[hi]) - np.nanmean(z[lo]) > 0.15
    assert np.allclose(np.ptp(c.f_true, axis=0), 0.0)


def test_every_effect_is_drawn_and_tables_are_consistent():
    names = {draw_case(s, n_windows=72).truth.name for s in range(40)}
    assert names == set(EFFECTS)
