"""Channel set-up: structure sensors and the topics/channels present are compared up front."""

from __future__ import annotations

import pytest

from shm_ros.core.diagnostics import Diagnostic, Level
from shm_ros.core.ingest import ChannelMap, ChannelSource, IngestConfig, channel_mismatches
from shm_ros.core.timeutil import iso_to_ns, join_ns, ns_to_iso, split_ns


def test_misspelled_topic_names_both_sides_and_the_close_match():
    cmap = ChannelMap.simple(["deck_n1", "deck_s1", "pier"])
    found = channel_mismatches(cmap, ["/shm/accel/deck_n1", "/shm/accel/dekc_s1", "/shm/accel/pier"])
    assert [(d.code, d.level) for d in found] == [("sensor_unmatched", Level.WARN), ("unknown_topic", Level.WARN)]
    sensor, topic = found
    assert sensor.source == "sensor deck_s1" and "/shm/accel/dekc_s1" in sensor.message
    assert topic.source == "/shm/accel/dekc_s1" and "deck_s1" in topic.message


def test_everything_matched_gives_nothing_and_blocks_count():
    cmap = ChannelMap([ChannelSource("a", "a", "z"), ChannelSource("g", None, "x", "ground")])
    assert channel_mismatches(cmap, ["accel/a"], block_channels=["ground"]) == []
    sensor, channel = channel_mismatches(cmap, ["accel/a"], block_channels=["grnd"])
    assert sensor.code == "sensor_unmatched" and "accel_block channel grnd" in sensor.message
    assert channel.code == "unknown_channel" and "ground" in channel.message
    (d,) = channel_mismatches(ChannelMap.simple(["a"]), ["a"], block_channels=["a", "zz"])
    assert d.code == "unknown_channel" and d.source == "accel_block channel zz"


def test_no_close_name_says_so_and_temperature_only_sensor_is_explained():
    cmap = ChannelMap.simple(["s1"])
    found = channel_mismatches(cmap, ["/x/accel/qqqq"], temperature_topics=["/x/temperature/s1"])
    assert {d.code for d in found} == {"sensor_unmatched", "unknown_topic"}
    sensor = next(d for d in found if d.code == "sensor_unmatched")
    assert "temperature topic only" in sensor.message and "no inputs with a similar name" in sensor.message


def test_time_conversions_round_trip():
    t = 1_714_521_600_005_123_456
    assert join_ns(*split_ns(t)) == t
    assert split_ns(-1) == (-1, 999_999_999)
    assert ns_to_iso(t) == "2024-05-01T00:00:00.005Z"
    assert iso_to_ns("2024-05-01T00:00:00.005123Z") == t - 456
    assert iso_to_ns("2024-05-01T02:00:00+02:00") == iso_to_ns("2024-05-01T00:00:00") == t - 5_123_456


def test_levels_and_config_choices():
    assert Level.parse("warn") is Level.WARN and Level.parse("warning") is Level.WARN and Level.parse(2) is Level.ERROR
    d = Diagnostic(1, "gap", "accel/a.z", "m", 0)
    assert d.level is Level.WARN and d.to_dict()["level"] == "warning" and "1970-01-01T00:00:00.000Z" in str(d)
    with pytest.raises(ValueError, match="event_detector"):
        IngestConfig(event_detector="sometimes")
    assert IngestConfig(event_detector="pga").event_detector == "pga"


def test_offline_ingest_and_identify_name_a_misspelt_topic_up_front(tmp_path):
    """A bag whose topic is misspelt against the structure file: the mismatch is reported before
    the first window (ingest result and the command's terminal output), with the close name."""
    import subprocess
    import sys

    import numpy as np

    from shm_ros.io.bags import BagWriter
    from shm_ros.io.recording import ingest_bag

    structure = tmp_path / "s.yaml"
    structure.write_text("""
name: frame
kind: shear_building
shear_building:
  floors: [{mass: 1.0e+5, stiffness: 2.0e+8}, {mass: 1.0e+5, stiffness: 2.0e+8}]
sensors:
  - {id: deck_n1, at: {floor: 1}, direction: x}
  - {id: deck_s1, at: {floor: 2}, direction: x}
""")
    t0, fs, n = 1_714_521_600_000_000_000, 100.0, 3000
    stamps = t0 + np.round(np.arange(n) * 1e9 / fs).astype(np.int64)
    xyz = np.random.default_rng(1).standard_normal((n, 3)) * 0.01
    with BagWriter(tmp_path / "bag") as w:
        w.imu_streams({"/shm/accel/deck_n1": (stamps, xyz), "/shm/accel/dekc_s1": (stamps, xyz)})
    res = ingest_bag(tmp_path / "bag", str(structure), window_s=20.0)
    codes = sorted(d.code for d in res.mismatches)
    assert codes == ["sensor_unmatched", "unknown_topic"]
    assert any("deck_s1" in d.message and "/shm/accel/dekc_s1" in d.message for d in res.mismatches)
    assert res.diagnostics[:2] == res.mismatches  # before anything the data gave
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "identify", str(tmp_path / "bag"), "--structure",
                          str(structure), "--out", str(tmp_path / "modes.json"), "--window", "20"],
                         capture_output=True, text=True, timeout=300)
    assert "dekc_s1" in run.stderr and "deck_s1" in run.stderr, run.stderr
