"""Replay and ingest over DDS: a bag published by ``replay_bag`` into a separate ingest process.

    python -m bench.bench_replay                          # 120 s x 16 channels x 200 Hz
    python -m bench.bench_replay --seconds 10             # the CI size

For each layout (per-sample ``sensor_msgs/Imu`` on 16 topics = 384,000 messages at full size, and
``AccelBlock`` of 0.5 s) a bag is written, an ingest node and a recorder of ``/shm/windows`` are
started as their own processes, and this process replays the bag flat out with flow control
(message and byte credits against the ingest node's acknowledgements). Every sample must come out
in the recorded windows with its exact value and stamp. Figures: the replay's real-time factor
(recording span / wall time from the first publish to the ingest node's last acknowledgement) and
the end-to-end factor (span / time from the first publish to the arrival of the last window at the
recorder, which includes cutting the windows); the targets apply to the end-to-end factor.

Exit status 1 on any lost or altered sample, or when a layout is below its target (>= 2x real time
for Imu, >= 20x for blocks; ``--no-target`` skips the target check, e.g. on a loaded CI machine).
Writes ``bench/results/bench_replay.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from shm_ros.ros.supervisor import node_process, stop_process

T0 = 1_714_521_600_000_000_000
TARGETS = {"imu": 2.0, "block": 20.0}
BLOCK_S = 0.5
RESULTS = Path(__file__).resolve().parent / "results"


def structure_yaml(channels: int) -> str:
    floors = "\n".join("    - {mass: 1.0e+5, stiffness: 2.0e+8}" for _ in range(channels))
    sensors = "\n".join(f"  - {{id: s{c}, at: {{floor: {c + 1}}}, direction: x}}" for c in range(channels))
    return (f"name: bench-{channels}-storey\nkind: shear_building\nshear_building:\n  floors:\n"
            f"{floors}\nsensors:\n{sensors}\n")


def truth(seconds: float, channels: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    n = int(round(seconds * fs))
    stamps = T0 + np.round(np.arange(n) * 1e9 / fs).astype(np.int64)
    data = np.random.default_rng(1).standard_normal((n, channels)) * 0.01
    return stamps, data


def write_bag(path: Path, layout: str, stamps: np.ndarray, data: np.ndarray, fs: float) -> int:
    """Per-sample Imu: one topic per channel, messages interleaved in stamp order as a recorder
    receives them (value on x, gravity on z). Blocks: one AccelBlock per ``BLOCK_S``."""
    from shm_ros.io.bags import BagWriter

    n, channels = data.shape
    with BagWriter(path, compress=True) as w:
        if layout == "imu":
            # Slices of 0.1 s per topic keep writing fast; the replay order is still by stamp
            # within 0.1 s, which the ingest node absorbs like any DDS reordering across topics.
            step = max(1, int(0.1 * fs))
            for i in range(0, n, step):
                sl = slice(i, min(n, i + step))
                for c in range(channels):
                    xyz = np.zeros((sl.stop - sl.start, 3))
                    xyz[:, 0] = data[sl, c]
                    xyz[:, 2] = 9.80665
                    w.imu_series(f"/bench/accel/s{c}", stamps[sl], xyz)
            return n * channels
        step = max(1, int(BLOCK_S * fs))
        names = [f"s{c}" for c in range(channels)]
        for i in range(0, n, step):
            w.accel_block("/bench/daq/accel_block", int(stamps[i]), fs, names, data[i:i + step])
        return (n + step - 1) // step




def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a running process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def check_windows(out_bag: Path, stamps: np.ndarray, data: np.ndarray, fs: float) -> dict:
    """Compare the recorded windows with the truth: every sample once, exact value and grid slot."""
    from shm_ros.io.bags import read_messages
    from shm_ros.ros.convert import time_to_ns

    n, channels = data.shape
    last_receive_ns = 0
    got = np.full((n, channels), np.nan)
    seen = np.zeros(n, dtype=np.int64)
    names = [f"s{c}" for c in range(channels)]
    windows = 0
    wrong_channels = 0
    period = 1e9 / fs
    for m in read_messages(out_bag, topics=["/shm/windows"]):
        w = m.decode()
        windows += 1
        last_receive_ns = max(last_receive_ns, m.receive_ns)  # the recorder's clock on arrival
        if list(w.channel_names) != names:
            wrong_channels += 1
            continue
        k = int(w.n_samples)
        first = int(round((time_to_ns(w.start) - int(stamps[0])) / period))
        if first < 0 or first + k > n:
            wrong_channels += 1
            continue
        got[first:first + k] = np.asarray(w.samples).reshape(k, channels)
        seen[first:first + k] += 1
    missing = int(np.sum(seen == 0))
    duplicated = int(np.sum(seen > 1))
    altered = int(np.sum((seen == 1)[:, None] & (got != data)))
    return {"windows": windows, "rows_missing": missing, "rows_duplicated": duplicated,
            "values_altered": altered, "bad_windows": wrong_channels,
            "samples_windowed": int(np.sum(seen == 1)) * channels, "last_window_ns": last_receive_ns}


def run_layout(layout: str, workdir: Path, seconds: float, channels: int, fs: float,
               window_s: float) -> dict:
    import rclpy

    from shm_ros.ros.replay import replay_bag

    stamps, data = truth(seconds, channels, fs)
    bag = workdir / f"{layout}_in"
    t = time.perf_counter()
    messages = write_bag(bag, layout, stamps, data, fs)
    write_s = time.perf_counter() - t
    structure = workdir / "structure.yaml"
    structure.write_text(structure_yaml(channels))
    out_bag = workdir / f"{layout}_windows"
    ingest = node_process("ingest", {"structure": str(structure), "window_s": window_s})
    recorder = node_process("recorder", {"output": str(out_bag), "topics": ["/shm/windows"]})
    result = None
    try:
        cpu0 = _cpu_s(ingest.pid)
        rclpy.init()
        try:
            # the recorder must be subscribed before the first window goes out
            probe = rclpy.create_node("bench_replay_probe")
            ready_by = time.monotonic() + 60.0
            while probe.count_subscribers("/shm/windows") < 1 and time.monotonic() < ready_by:
                rclpy.spin_once(probe, timeout_sec=0.1)
            probe.destroy_node()
            cpu = time.process_time()
            result = replay_bag(bag, wait_s=20.0, drain_timeout_s=120.0)
            replay_cpu = time.process_time() - cpu
        finally:
            rclpy.try_shutdown()
        ingest_cpu = _cpu_s(ingest.pid) - cpu0
        time.sleep(1.0)  # the flush after /shm/replay/done, and the recorder's last windows
    finally:
        code_i, out_i = stop_process(ingest, timeout=60.0)
        code_r, out_r = stop_process(recorder, timeout=60.0)
    check = check_windows(out_bag, stamps, data, fs) if out_bag.exists() else {
        "windows": 0, "rows_missing": len(stamps), "rows_duplicated": 0, "values_altered": 0,
        "bad_windows": 0, "samples_windowed": 0}
    span = seconds
    factor = span / result.wall_s if result.wall_s > 0 else float("inf")
    # end to end: first publish -> last window recorded (includes cutting the windows at the end)
    e2e_s = (check["last_window_ns"] - result.started_ns) / 1e9 if check["last_window_ns"] else float("inf")
    lost_samples = data.size - check["samples_windowed"]
    row = {
        "layout": layout, "messages": messages, "bag_mb": _size_mb(bag), "bag_write_s": write_s,
        "published": result.published, "acknowledged": result.acknowledged,
        "lost_messages": result.lost, "replay_wall_s": result.wall_s, "realtime_factor": factor,
        "end_to_end_s": e2e_s, "end_to_end_factor": span / e2e_s if e2e_s > 0 else float("inf"),
        "messages_per_s": result.published / result.wall_s if result.wall_s > 0 else 0.0,
        "ingest_cpu_s": ingest_cpu, "replay_cpu_s": replay_cpu, "samples": int(data.size),
        "lost_samples": int(lost_samples),
        "target": TARGETS[layout], "ingest_exit": code_i, "recorder_exit": code_r, **check,
    }
    if code_i != 0 or code_r != 0:
        row["node_output_tail"] = (out_i[-1500:], out_r[-1500:])
    return row


def _size_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 1e6


def ok(row: dict, check_target: bool) -> bool:
    clean = (row["lost_samples"] == 0 and row["lost_messages"] == 0 and row["values_altered"] == 0
             and row["rows_duplicated"] == 0 and row["bad_windows"] == 0
             and row["ingest_exit"] == 0 and row["recorder_exit"] == 0)
    return clean and (not check_target or row["end_to_end_factor"] >= row["target"])


def run(seconds: float = 120.0, channels: int = 16, fs: float = 200.0, window_s: float = 10.0,
        layouts: tuple[str, ...] = ("imu", "block")) -> dict:
    # A private DDS domain on this host, unless the caller chose one.
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 80))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    workdir = Path(tempfile.mkdtemp(prefix="bench_replay_"))
    try:
        rows = [run_layout(layout, workdir, seconds, channels, fs, window_s) for layout in layouts]
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return {"seconds": seconds, "channels": channels, "fs": fs, "window_s": window_s,
            "load_average": os.getloadavg(), "cpus": os.cpu_count(), "python": platform.python_version(),
            "rows": rows}


def markdown(res: dict) -> str:
    lines = [f"{res['seconds']:g} s x {res['channels']} channels x {res['fs']:g} Hz, windows of "
             f"{res['window_s']:g} s; load average after the run "
             f"{', '.join(f'{x:.1f}' for x in res['load_average'])} on {res['cpus']} CPUs", "",
             "| layout | messages | bag MB | replay wall s (x real time) | messages/s | "
             "first publish -> last window s | x real time end to end (target) | ingest CPU s | replay CPU s | "
             "samples lost | values altered |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['layout']} | {r['messages']:,} | {r['bag_mb']:.1f} | {r['replay_wall_s']:.2f} "
                     f"({r['realtime_factor']:.1f}) | {r['messages_per_s']:,.0f} | {r['end_to_end_s']:.2f} | "
                     f"{r['end_to_end_factor']:.1f} (>= {r['target']:g}) | {r['ingest_cpu_s']:.1f} | "
                     f"{r['replay_cpu_s']:.1f} | "
                     f"{r['lost_samples']} | {r['values_altered']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--channels", type=int, default=16)
    ap.add_argument("--fs", type=float, default=200.0)
    ap.add_argument("--window", type=float, default=10.0, help="window length of the ingest node (s)")
    ap.add_argument("--layouts", default="imu,block")
    ap.add_argument("--no-target", action="store_true", help="check only for loss, not the speed")
    args = ap.parse_args(argv)
    res = run(args.seconds, args.channels, args.fs, args.window, tuple(args.layouts.split(",")))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "bench_replay.json").write_text(json.dumps(res, indent=2, default=str))
    (RESULTS / "bench_replay.md").write_text(markdown(res))
    print(markdown(res))
    status = 0
    for r in res["rows"]:
        if not ok(r, not args.no_target):
            print(f"FAIL {r['layout']}: {json.dumps({k: v for k, v in r.items() if k != 'node_output_tail'})}",
                  file=sys.stderr)
            for tail in r.get("node_output_tail", ()):
                print(tail, file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    raise SystemExit(main())
