"""A bag replayed over DDS through real node processes yields windows holding
exactly the samples that went in (count, order, raw values); unrelated topics are ignored."""

from __future__ import annotations

import numpy as np
import pytest
from ros_helpers.graph import node_process, recorded_windows, replay, running, wait_for_windows

FS = 100.0
T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z
STRUCTURE = """
name: three-storey-test-frame
kind: shear_building
shear_building:
  floors:
    - {mass: 1.0e+5, stiffness: 2.0e+8}
    - {mass: 1.0e+5, stiffness: 2.0e+8}
    - {mass: 1.0e+5, stiffness: 2.0e+8}
sensors:
  - {id: f1, at: {floor: 1}, direction: x}
  - {id: f2, at: {floor: 2}, direction: x}
  - {id: f3, at: {floor: 3}, direction: x, source: {topic: roof, axis: y, sign: -1}}
"""


def _write_bag(path, fmt: str, rng):
    """Two bursts of 25 s, 3 channels, gravity on z, a temperature topic and an unrelated topic."""
    from shm_ros.io.bags import BagWriter

    truth = {}
    with BagWriter(path, compress=(fmt == "block")) as w:
        for b in range(2):
            start = T0 + b * 60 * 10**9
            n = int(25 * FS)
            stamps = start + np.round(np.arange(n) * 1e9 / FS).astype(np.int64)
            data = rng.standard_normal((n, 3)) * 0.01
            truth[b] = (stamps, data)
            if fmt == "imu":
                streams = {}
                for j, topic in enumerate(["f1", "f2", "roof"]):
                    xyz = np.zeros((n, 3))
                    xyz[:, 2] = 9.80665
                    if topic == "roof":
                        xyz[:, 1] = -data[:, j]
                    else:
                        xyz[:, 0] = data[:, j]
                    streams[f"/site/accel/{topic}"] = (stamps, xyz)
                w.imu_streams(streams)
            else:
                blk = 50
                for k in range(0, n, blk):
                    w.accel_block("/site/daq/accel_block", int(stamps[k]), FS, ["f1", "f2", "f3"],
                                  data[k:k + blk])
            for k in range(3):
                w.temperature("/site/temperature/t1", start + k * 10 * 10**9, 10.0 + b + k)
            w.write("/site/chatter", "std_msgs/msg/String", start,
                    w._types["std_msgs/msg/String"](data="unrelated"))
    return truth


@pytest.mark.parametrize("fmt", ["imu", "block"])
def test_replayed_bag_gives_windows_with_exactly_the_samples_that_went_in(tmp_path, fmt):
    rng = np.random.default_rng(7)
    structure = tmp_path / "structure.yaml"
    text = STRUCTURE
    if fmt == "block":  # a DAQ names its channels by sensor id; no Imu topic/axis/sign override
        text = text.replace(", source: {topic: roof, axis: y, sign: -1}", "")
    structure.write_text(text)
    bag = tmp_path / "recording"
    truth = _write_bag(bag, fmt, rng)
    out_bag = tmp_path / "pipeline"
    ingest = node_process("ingest", {"structure": str(structure), "window_s": 10.0})
    recorder = node_process("recorder", {"output": str(out_bag), "topics": ["/shm/windows"]})
    with running(ingest, recorder, subscribers={"/shm/windows": 1},
                 publishers={"/shm/ingest/received": 1}) as results:
        rep = replay(bag)
        wait_for_windows(out_bag, 6)  # the last window may still be on its way to the recorder
    assert rep.returncode == 0, rep.stdout + rep.stderr
    assert "lost 0" in rep.stdout
    assert "skipped /site/chatter" in rep.stdout
    codes = {pid: code for pid, (code, _) in results.items()}
    assert all(c == 0 for c in codes.values()), [(c, out[-1500:]) for c, out in results.values()]

    windows = recorded_windows(out_bag)
    # 25 s bursts with 10 s windows: 10 + 10 + (5 s remainder = half a window: kept) per burst.
    assert [int(w.n_samples) for w, _ in windows] == [1000, 1000, 500] * 2
    for b in range(2):
        stamps, data = truth[b]
        got = np.concatenate([s for w, s in windows[3 * b:3 * b + 3]])
        assert np.array_equal(got, data)  # bit-identical, same order, sign applied for the roof
        first = windows[3 * b][0]
        assert first.start.sec * 10**9 + first.start.nanosec == stamps[0]
        assert list(first.channel_names) == ["f1", "f2", "f3"]
    temps = [w.temperature_c for w, _ in windows]
    # one temperature sample at 0, 10 and 20 s of each burst: one per window, half-open ends
    assert temps == [10.0, 11.0, 12.0, 11.0, 12.0, 13.0]
