"""Band of interest and filters that keep real modes (docs/identify.md, "Band and resolution" and
"Filters").

Acceptance (low-frequency frame, ``test/lowfreq_frame.py``): a plane five-storey moment frame
(first mode 0.51-0.56 Hz, non-classical damping, truth outside the structure file's shear-building
class), 7 minutes at 100 Hz, a shaker's measured force on the top floor (the structure file's
``input`` sensor) plus unmeasured wind, 3 % sensor noise. With the default settings and the
structure file's nominal model (what ``shm-ros identify --structure S.yaml`` does), modes 1-3
must each be found within 2 % of the truth.

Thresholds: at full size (``SHM_FULL=1``, 40 seeds, run once) every seed met it: mean |df/f| of
modes 1-3 0.27 / 0.10 / 0.09 %, worst 0.90 / 0.33 / 0.29 %, against the 2 % tolerance;
a correct method is taken to succeed per window with probability p >= 0.975. CI runs 6 seeds and
allows one failing seed: P(at most 1 failure of 6 | p = 0.975) = p^6 + 6 p^5 (1 - p) = 0.991, so a
correct method passes with >= 99 % probability; full size allows 4 failures of 40
(binomial tail: P(X <= 4 | n = 40, q = 0.025) = 0.997).
The same records with the band off (the previous defaults: 20 block rows at 100 Hz) miss mode 1.
"""

from __future__ import annotations

import json

import lowfreq_frame as lf
import numpy as np
import pytest
import synthetic_oma as so
from conftest import full_size

from shm_ros.cli import main
from shm_ros.core.band import nominal_frequencies
from shm_ros.core.identify import IdentifyConfig, identify_window, identify_window_detailed
from shm_ros.core.simulate.linear import from_state_space
from shm_ros.core.stabilization import PickingConfig, StabilityConfig
from shm_ros.core.structure import structure_from_dict
from shm_ros.core.types import Window

SEEDS = range(40) if full_size() else range(6)
ALLOWED_FAILURES = 4 if full_size() else 1
N_MODES = 3


@pytest.fixture(autouse=True)
def _one_blas_thread():
    with so.single_blas_thread():
        yield


def _default_config(case: lf.FrameCase) -> IdentifyConfig:
    """What the command builds from ``--structure`` alone."""
    spec = structure_from_dict(lf.structure_dict(case), source="frame.yaml")
    cfg = IdentifyConfig()
    cfg.nominal_frequencies_hz = nominal_frequencies(spec, cfg.band_modes)
    return cfg


def _errors(freqs: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """|relative error| of the identified frequency nearest each true mode (inf: none)."""
    if freqs.size == 0:
        return np.full(truth.size, np.inf)
    return np.array([np.min(np.abs(freqs / t - 1)) for t in truth])


def test_low_frequency_frame_first_three_modes_with_default_settings():
    rows, fails = [], 0
    for seed in SEEDS:
        case = lf.frame_case(seed)
        res = identify_window_detailed(case.window, _default_config(case))
        f = np.array([m.frequency_hz for m in res.estimate.modes])
        err = _errors(f, case.frequency_hz[:N_MODES])
        rows.append(err)
        fails += int(np.any(err > 0.02))
        assert res.band is not None and res.band.source == "model"
        assert res.band.decimation > 1 and res.band.block_rows / res.band.sample_rate_hz \
            >= 1.9 / case.frequency_hz[0]  # about 2 periods of mode 1 (nominal, not the truth)
    e = np.array(rows)
    summary = (f"failing seeds {fails}/{len(SEEDS)}, mean |df/f| {np.round(100 * e.mean(0), 3)} %, "
               f"worst {np.round(100 * e.max(0), 3)} %")
    print(summary)
    assert fails <= ALLOWED_FAILURES, summary


def test_the_previous_resolution_misses_the_first_mode():
    """The test can fail: 20 block rows at 100 Hz (band off) do not resolve the 0.5 Hz mode."""
    missed = 0
    for seed in SEEDS[:3]:
        case = lf.frame_case(seed)
        est = identify_window(case.window, IdentifyConfig(band="off", uncertainty=False))
        f = np.array([m.frequency_hz for m in est.modes])
        missed += int(_errors(f, case.frequency_hz[:1])[0] > 0.02)
    assert missed >= 2


def test_the_spectrum_sets_the_band_without_a_structure_and_explicit_options_win():
    case = lf.frame_case(7)
    res = identify_window_detailed(case.window, IdentifyConfig(uncertainty=False))
    band = res.band
    assert band is not None and band.source == "spectrum"
    assert abs(band.low_hz / case.frequency_hz[0] - 1) < 0.05  # the lowest prominent peak is mode 1
    f = np.array([m.frequency_hz for m in res.estimate.modes])
    assert np.all(_errors(f, case.frequency_hz[:N_MODES]) <= 0.02)
    assert any("block rows" in n for n in res.notes)
    cfg = IdentifyConfig(uncertainty=False, block_rows=30)
    cfg.preprocess.target_rate_hz = 50.0
    res = identify_window_detailed(case.window, cfg)
    assert res.band is not None and res.band.block_rows == 30 and res.band.decimation == 1
    assert res.sample_rate_hz == 50.0


def test_a_40_hz_mode_at_1_khz():
    """The same rule at another scale: modes at 40 and 110 Hz sampled at 1 kHz."""
    rng = np.random.default_rng(5)
    fs, n = 1000.0, 120_000
    w = 2 * np.pi * np.array([40.0, 110.0])
    z = np.array([0.01, 0.015])
    phi = np.array([[1.0, 0.8, 0.4], [-0.5, 0.3, 1.0]]).T  # 3 sensors x 2 modes
    a = np.zeros((4, 4))
    a[:2, 2:] = np.eye(2)
    a[2:, :2] = -np.diag(w**2)
    a[2:, 2:] = -np.diag(2 * z * w)
    b = np.vstack([np.zeros((2, 3)), phi.T])
    c = np.hstack([-phi @ np.diag(w**2), -phi @ np.diag(2 * z * w)])
    y = from_state_space(a, b, c, phi @ phi.T).simulate(rng.standard_normal((n, 3)), 1 / fs)
    y += 0.02 * y.std(axis=0) * rng.standard_normal(y.shape)
    res = identify_window_detailed(Window("khz", 0, fs, ["s1", "s2", "s3"], y),
                                   IdentifyConfig(uncertainty=False))
    band = res.band
    assert band is not None and band.decimation >= 2
    assert band.block_rows / band.sample_rate_hz >= 1.9 / 40.0
    f = np.array([m.frequency_hz for m in res.estimate.modes])
    assert np.all(_errors(f, np.array([40.0, 110.0])) <= 0.01), f


def _two_mode_record(seed: int) -> tuple[Window, np.ndarray]:
    """Four sensors, a lightly (0.5 %) and a heavily (8 %) damped mode, white forcing, 10 min at 25 Hz."""
    rng = np.random.default_rng(seed)
    fs, n = 25.0, 15_000
    f0 = np.array([1.2, 3.1])
    w, z = 2 * np.pi * f0, np.array([0.005, 0.08])
    phi = np.array([[0.4, 0.7, 0.9, 1.0], [1.0, 0.5, -0.4, -0.9]]).T
    a = np.zeros((4, 4))
    a[:2, 2:] = np.eye(2)
    a[2:, :2] = -np.diag(w**2)
    a[2:, 2:] = -np.diag(2 * z * w)
    b = np.vstack([np.zeros((2, 4)), phi.T])
    c = np.hstack([-phi @ np.diag(w**2), -phi @ np.diag(2 * z * w)])
    # the heavily damped mode gets more force: both stand out of the noise alike
    u = rng.standard_normal((n, 4)) * np.array([1.0, 1.0, 3.0, 3.0])
    y = from_state_space(a, b, c, np.zeros((4, 4))).simulate(u, 1 / fs)
    y += 0.03 * y.std(axis=0) * rng.standard_normal(y.shape)
    return Window(f"two{seed}", 0, fs, ["s1", "s2", "s3", "s4"], y), f0


@pytest.mark.parametrize("seed", [1, 2])
def test_filters_keep_clean_columns_of_light_and_heavy_damping(seed):
    w, f0 = _two_mode_record(seed)
    res = identify_window_detailed(w, IdentifyConfig(uncertainty=False))
    rep = res.filters
    assert rep is not None
    f = np.array([m.frequency_hz for m in res.estimate.modes])
    z = np.array([m.damping_ratio for m in res.estimate.modes])
    err = _errors(f, f0)
    assert np.all(err <= 0.01), (f, rep.to_dict())
    for target, zt in zip(f0, (0.005, 0.08), strict=True):
        k = int(np.argmin(np.abs(f - target)))
        assert abs(z[k] - zt) <= 0.5 * zt, (z, zt)
        # the column near the mode was never removed by a filter
        near = np.abs(res.diagram.poles.frequency_hz / target - 1) < 0.01
        column = near & res.diagram.flags.stable & res.diagram.flags.physical_ok
        assert not np.any(np.isin(rep.removed_by[column], ["two-A", "MPC"])), rep.to_dict()
    d = json.loads(json.dumps(rep.to_dict()))
    assert set(d["removed"]) >= {"physical", "two-A", "MPC"}
    assert d["stable_poles"] >= sum(d["removed"].values())


def test_strict_pole_by_pole_filters_lose_a_clean_column():
    """The test above can fail: relative tolerances only (no standard-error term) and a column
    vote that needs nearly every order remove at least one of the two clean columns."""
    lost = 0
    for seed in (1, 2):
        w, f0 = _two_mode_record(seed)
        strict = IdentifyConfig(uncertainty=False, stability=StabilityConfig(damping_sigmas=0.0, two_a_sigmas=0.0),
                                picking=PickingConfig(column_pass_fraction=0.9))
        f = np.array([m.frequency_hz for m in identify_window(w, strict).modes])
        lost += int(np.any(_errors(f, f0) > 0.01))
    assert lost >= 1


def test_cli_reports_the_band_and_the_filters(tmp_path, capsys):
    d = tmp_path / "sim"
    assert main(["simulate", "building", "--out", str(d), "--windows", "1", "--window-s", "120",
                 "--quiet", "--seed", "4"]) == 0
    out = tmp_path / "modes.json"
    capsys.readouterr()
    assert main(["identify", str(d / "bag"), "--structure", str(d / "structure.yaml"), "--out",
                 str(out), "--window", "120"]) == 0
    printed = capsys.readouterr().out
    assert "(model)" in printed and "block rows in 1 window" in printed, printed
    doc = json.loads(out.read_text())
    (rec,) = doc["windows"]
    assert rec["band"]["source"] == "model" and rec["band"]["reasons"]
    assert set(rec["filters"]["removed"]) >= {"physical", "two-A", "MPC"}
    conf = doc["provenance"]["configuration"]
    assert list(conf["bands_used"].values()) == [1]
    assert conf["identify"]["nominal_frequencies_hz"]
    # an explicit option wins
    assert main(["identify", str(d / "bag"), "--structure", str(d / "structure.yaml"), "--out",
                 str(out), "--window", "120", "--block-rows", "24", "--band", "off", "--overwrite"]) == 0
    (rec,) = json.loads(out.read_text())["windows"]
    assert rec["band"]["block_rows"] == 24 and rec["band"]["decimation"] == 1
