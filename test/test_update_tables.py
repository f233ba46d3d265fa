"""Tracked-modes table (docs/interfaces.md §4): round trip and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.observations import ModalObservations
from shm_ros.io.tables import TableError, read_tracked_modes, write_tracked_modes


def test_round_trip_with_gaps_and_covariates(tmp_path):
    rng = np.random.default_rng(0)
    f = 2.0 + 0.01 * rng.standard_normal((5, 2))
    f[2, 1] = np.nan
    shapes = rng.standard_normal((5, 2, 3))
    shapes[1, 0, 2] = np.nan
    obs = ModalObservations(times=1.7e9 + 600 * np.arange(5), mode_numbers=[1, 2], frequencies_hz=f,
                            shapes=shapes, sensor_ids=["s1", "s2", "s3"],
                            damping=np.full((5, 2), 0.02),
                            covariates={"temperature_c": np.arange(5.0), "rms_accel": np.ones(5)},
                            time_kind="iso")
    path = tmp_path / "modes.csv"
    write_tracked_modes(path, obs)
    text = path.read_text()
    assert text.splitlines()[0].startswith("time,mode1_hz,mode1_damping,mode1_shape_s1")
    assert "Z," in text.splitlines()[1]
    back = read_tracked_modes(path)
    np.testing.assert_allclose(back.times, obs.times)
    np.testing.assert_array_equal(np.isnan(back.frequencies_hz), np.isnan(f))
    np.testing.assert_allclose(back.frequencies_hz, f)
    np.testing.assert_allclose(back.shapes, shapes)
    assert back.sensor_ids == ["s1", "s2", "s3"] and back.mode_numbers == [1, 2]
    assert set(back.covariates) == {"temperature_c", "rms_accel"} and back.notes == []


def test_bad_cells_are_reported_not_fatal(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,mode1_hz,mode2_hz,temperature_c\n"
                    "0,1.0,3.0,5\n"
                    "600,abc,3.1,6\n"
                    "yesterday,1.0,3.0,7\n"
                    "1200,-1,3.05,\n"
                    "1800,1.01,,8\n")
    obs = read_tracked_modes(path)
    assert obs.n_windows == 4
    assert np.isnan(obs.frequencies_hz[1, 0]) and np.isnan(obs.frequencies_hz[2, 0])
    assert np.isnan(obs.frequencies_hz[3, 1]) and np.isnan(obs.covariates["temperature_c"][2])
    joined = "\n".join(obs.notes)
    assert "row 3, column 'mode1_hz'" in joined and "row 4: unreadable time" in joined
    assert "<= 0" in joined and str(path) in joined


@pytest.mark.parametrize("content,msg", [
    ("mode1_hz\n1.0\n", "no 'time' column"),
    ("time,temperature_c\n0,1\n", "no 'mode<k>_hz' column"),
    ("time,mode1_hz,mode1_hz\n0,1,1\n", "duplicated column"),
    ("time,mode1_hz\n0,1\n2024-01-01T00:00:00Z,1\n", "mixes ISO 8601"),
    ("", "empty table"),
])
def test_structural_errors_name_the_file(tmp_path, content, msg):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(TableError) as exc:
        read_tracked_modes(path)
    assert msg in str(exc.value) and "bad.csv" in str(exc.value)


def test_missing_file(tmp_path):
    with pytest.raises(TableError, match="no such file"):
        read_tracked_modes(tmp_path / "nope.csv")


def test_referring_frequencies_to_a_temperature_removes_the_trend():
    rng = np.random.default_rng(3)
    temp = rng.uniform(-5, 25, 60)
    f = np.column_stack([2.0 - 0.004 * (temp - 10), 5.0 - 0.01 * (temp - 10)])
    f += 0.002 * rng.standard_normal(f.shape)
    temp[7] = np.nan
    obs = ModalObservations(np.arange(60.0), [1, 2], f, covariates={"temperature_c": temp})
    ref = obs.referred_to("temperature_c", 10.0)
    assert ref.n_windows == 59
    assert np.all(np.std(ref.frequencies_hz, axis=0) < 0.003)
    assert np.all(np.std(obs.frequencies_hz[np.isfinite(temp)], axis=0) > 0.03)
    np.testing.assert_allclose(ref.frequencies_hz.mean(axis=0), [2.0, 5.0], atol=0.002)
    assert "slopes per mode" in ref.notes[-1]
    with pytest.raises(ValueError, match="no covariate column 'wind'"):
        obs.referred_to("wind")
