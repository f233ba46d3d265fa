"""Benchmark: a recording replayed over DDS into a separate ingest process with
flow control loses no sample (count, values, grid slots), per-sample Imu and AccelBlock.

CI runs 10 s x 16 channels x 200 Hz (32,000 Imu messages), ``SHM_FULL=1`` the full 120 s (384,000
messages); both only report the real-time factor. The speed targets (>= 2x real time for Imu, >= 20x
for blocks) are checked by ``python -m bench.bench_replay``, not here.
"""

from __future__ import annotations

from conftest import full_size

from bench.bench_replay import ok, run


def test_replay_over_dds_loses_no_sample():
    seconds = 120.0 if full_size() else 10.0
    res = run(seconds=seconds, channels=16, fs=200.0, window_s=10.0)
    rows = {r["layout"]: r for r in res["rows"]}
    assert set(rows) == {"imu", "block"}
    assert rows["imu"]["messages"] == int(seconds * 200) * 16
    for layout, r in rows.items():
        print(f"{layout}: {r['end_to_end_factor']:.1f}x real time end to end, {r['messages_per_s']:.0f} msg/s, "
              f"load {res['load_average'][0]:.1f}")
        assert r["samples_windowed"] == r["samples"] == int(seconds * 200) * 16, r
        assert r["lost_messages"] == 0 and r["values_altered"] == 0 and r["rows_duplicated"] == 0, r
        assert ok(r, check_target=False), r
