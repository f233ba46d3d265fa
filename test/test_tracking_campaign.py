"""Tracking end to end on a simulated campaign: girder bag with a daily temperature cycle and a
temperature-dependent deck (hidden effect) -> windows (ingest) -> modes (identify, SSI-cov) ->
tracked modes. Checked against the simulator's per-window truth (its finer truth model): every
tracked mode is the same physical mode in every window, and the tracked frequency-temperature
slope is the truth's. CI: 48 windows of 300 s over one day; SHM_FULL=1: 96 windows of 600 s."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import full_size

from shm_ros.core.identify import IdentifyConfig, identify_window
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.simulate.scenario import EffectRequest
from shm_ros.core.tracking import TrackingConfig, track
from shm_ros.io.campaign import write_campaign
from shm_ros.io.recording import windows_from_bag
from shm_ros.io.structure import load_structure

N, WIN = (96, 600.0) if full_size() else (48, 300.0)


@pytest.mark.parametrize("seed", [21, 22, 23, 24] if full_size() else [21, 22])
def test_tracked_girder_modes_follow_the_truth_over_a_day(tmp_path, seed):
    sc = named_scenario("girder")
    sc.n_windows, sc.window_s, sc.seed = N, WIN, seed
    sc.pause_s = 86400.0 / N - WIN  # one day of windows: the whole temperature cycle
    sc.effects = [EffectRequest("temperature_linear")]
    files = write_campaign(simulate_campaign(sc), tmp_path / "rec")
    with open(files.truth) as fh:
        truth = json.load(fh)
    spec = load_structure(files.structure)
    windows, _ = windows_from_bag(files.bag, spec, WIN)
    assert len(windows) == N
    cfg = IdentifyConfig(uncertainty=False)
    estimates = [identify_window(w, cfg) for w in windows]
    # the hidden effect is linear in temperature: the linear model's slope is compared with the
    # truth's (with 48 windows of SSI scatter, `auto` may prefer a knee that is not there)
    res = track(estimates, TrackingConfig(reference_windows=12, training_fraction=1.0, env_model="linear"))
    by_start = {int(w["start_ns"]): w for w in truth["windows"]}
    # every true mode, in-plane or not: the records hold the deck's torsion and lateral modes too
    # (off-centre sensors, cross-axis sensitivity), and a tracked mode may be one of them
    n_true = min(len(by_start[e.start_ns]["frequencies_hz"]) for e in estimates)
    true_f = np.array([by_start[e.start_ns]["frequencies_hz"][:n_true] for e in estimates])
    families = by_start[estimates[0].start_ns]["mode_families"]
    temp = np.array([by_start[e.start_ns]["temperature_c"] for e in estimates])
    fr = res.observations.frequencies_hz
    assert res.observations.n_modes >= 3
    checked = 0
    for k in range(min(4, res.observations.n_modes)):
        # which physical mode is tracked mode k: the truth mode nearest its reference frequency
        j = int(np.argmin(np.abs(true_f[0] - res.reference[k].frequency_hz)))
        got = np.isfinite(fr[:, k])
        assert got.mean() >= 0.8, (k, got.mean())
        # the same physical mode in every window: nearest truth mode, within 1 %
        nearest = np.argmin(np.abs(true_f[got][:, :, None] - fr[got, k][:, None, None])[..., 0], axis=1)
        assert np.all(nearest == j), (k, np.unique(nearest))
        err = np.abs(fr[got, k] / true_f[got, j] - 1)
        assert np.median(err) < 0.01, (k, np.median(err))
        # frequency against temperature: the tracked slope is the truth's
        slope_true = np.polyfit(temp, true_f[:, j], 1)[0]
        fit = res.environment[k]
        print(f"mode {k + 1} ({families[j]}): slope {fit.slope_hz_per_unit:.5f} Hz/C, truth {slope_true:.5f}; "
              f"median error {100 * np.median(err):.2f} %; found {got.mean():.2f}")
        assert slope_true < 0 and abs(fit.slope_hz_per_unit / slope_true - 1) < 0.25, (
            k, fit.slope_hz_per_unit, slope_true)
        checked += 1
    assert checked >= 3
