"""Load bench: a live stream into a real ingest node process over DDS, held for minutes.

    python -m bench.bench_load                      # 600 s (10 minutes), 64 block channels + 4 Imu at 1 kHz
    python -m bench.bench_load --seconds 30         # what the CI test runs

This process publishes, paced at real time, 64 channels at 1 kHz as ``AccelBlock`` messages (0.1 s
each) and 4 ``Imu`` streams at 1 kHz (one sample per message), all reliable, into an ingest node
started as its own process (``reliable_input: true``); it receives the windows ingest publishes.
At the end the replay-done message makes ingest cut what it holds. Printed: samples in and out per
channel (they must be equal), the publishing lag (whether the stream was held at real time), the
ingest process's CPU time, and its resident memory sampled every second with the slope of a
least-squares line after the warm-up (the first third, at least 15 s), in MB per minute. Writes
``bench/results/bench_load.json``; exit status 1 when samples were lost or the slope is 1 MB/min or
more.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

T0 = 1_714_521_600_000_000_000
FS = 1000.0
BLOCK = 100  # samples per AccelBlock message
N_BLOCK = 64
N_IMU = 4
WINDOW_S = 5.0
WARM_UP_S = 15.0  # three windows: the buffers and DDS history have reached their size
RESULTS = Path(__file__).resolve().parent / "results"


def structure_text() -> str:
    sensors = [f"  - {{id: b{c:02d}, at: {{floor: {c % 3 + 1}}}, direction: x}}" for c in range(N_BLOCK)]
    sensors += [f"  - {{id: i{c}, at: {{floor: {c % 3 + 1}}}, direction: x}}" for c in range(N_IMU)]
    floors = "\n".join(["    - {mass: 1.0e+5, stiffness: 2.0e+8}"] * 3)
    return (f"name: load-bench\nkind: shear_building\nshear_building:\n  floors:\n{floors}\nsensors:\n"
            + "\n".join(sensors) + "\n")


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def ingest_idle(pid: int, seconds: float = 3.0) -> bool:
    """The process used no CPU for ``seconds`` (it has published what it held)."""
    before = _cpu_s(pid)
    time.sleep(seconds)
    return _cpu_s(pid) - before < 0.05


def rss_slope(t_s: list[float], rss: list[float], seconds: float) -> float:
    """MB per minute of a least-squares line through the samples after the warm-up."""
    warm = max(seconds / 3, WARM_UP_S)
    t, r = np.array(t_s), np.array(rss)
    keep = t >= warm
    if keep.sum() < 3:
        return float("nan")
    return float(np.polyfit(t[keep], r[keep], 1)[0] * 60)


READER = r"""
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from shm_interfaces.msg import Window
from std_msgs.msg import String
from shm_ros.ros import topics
from shm_ros.ros.qos import pipeline_qos, stream_qos
rclpy.init()
node = rclpy.create_node("shm_bench_load_reader")
out, state = {}, {"windows": 0, "unawaited": 0, "stop": False}
def on_window(w):
    state["windows"] += 1
    for name in w.channel_names:
        out[name] = out.get(name, 0) + int(w.n_samples)
    print("samples", sum(out.values()), flush=True)  # so far: the bench waits for all it sent
def on_diag(m):
    for st in m.status:
        if st.name == "ingest: status":
            state["unawaited"] = int({kv.key: kv.value for kv in st.values}.get("windows_unawaited", 0))
node.create_subscription(Window, topics.WINDOWS, on_window, stream_qos())
node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diag, pipeline_qos())
node.create_subscription(String, "shm_bench_load/stop", lambda m: state.update(stop=True), 10)
print("ready", flush=True)
while not state["stop"]:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps({"out": out, **state}), flush=True)
"""


def run(seconds: float = 600.0) -> dict:
    import rclpy
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu
    from shm_interfaces.msg import AccelBlock
    from std_msgs.msg import String

    from shm_ros.ros import topics
    from shm_ros.ros.qos import latched_qos
    from shm_ros.ros.supervisor import node_process, stop_process

    tmp = Path(tempfile.mkdtemp(prefix="shm_bench_load_"))
    structure = tmp / "structure.yaml"
    structure.write_text(structure_text())
    ingest = node_process("ingest", {"structure": str(structure), "window_s": WINDOW_S, "reliable_input": True,
                                     "idle_flush_s": 30.0}, capture=True)
    rclpy.init()
    node = rclpy.create_node("shm_bench_load")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    block_pub = node.create_publisher(AccelBlock, "site/daq/accel_block", qos)
    imu_pubs = [node.create_publisher(Imu, f"site/accel/i{c}", qos) for c in range(N_IMU)]
    done_pub = node.create_publisher(String, topics.REPLAY_DONE, latched_qos())
    stop_pub = node.create_publisher(String, "shm_bench_load/stop", 10)
    # the windows are counted in a process of its own, so that this one's publishing does not slow
    # the reader (ingest holds windows for a slow reader)
    reader = subprocess.Popen([sys.executable, "-c", READER], stdout=subprocess.PIPE, text=True)
    assert reader.stdout is not None and reader.stdout.readline().strip() == "ready"
    counted_so_far = [0]
    reader_lines: list[str] = []

    def follow(stream) -> None:
        for line in stream:
            if line.startswith("samples "):
                counted_so_far[0] = int(line.split()[1])
            else:
                reader_lines.append(line)
    follower = threading.Thread(target=follow, args=(reader.stdout,), daemon=True)
    follower.start()
    retries = [0]

    def publish(pub, msg) -> None:
        """Publish; a reliable writer whose reader is behind refuses for a moment (the DDS writer's
        blocking time ran out): wait and try again, as a buffering source would (back-pressure)."""
        from rclpy._rclpy_pybind11 import RCLError

        while True:
            try:
                pub.publish(msg)
                return
            except RCLError:
                retries[0] += 1
                rclpy.spin_once(node, timeout_sec=0.01)
    try:
        end = time.monotonic() + 120
        while time.monotonic() < end and not (
                block_pub.get_subscription_count() and all(p.get_subscription_count() for p in imu_pubs)
                and node.count_publishers(topics.WINDOWS) and stop_pub.get_subscription_count()
                and node.count_subscribers(topics.WINDOWS)):
            rclpy.spin_once(node, timeout_sec=0.2)
        assert time.monotonic() < end, "the ingest node did not subscribe"
        rng = np.random.default_rng(1)
        names = [f"b{c:02d}" for c in range(N_BLOCK)]
        block = AccelBlock()
        block.sample_rate_hz, block.channel_names, block.units = FS, names, "m/s^2"
        imu = Imu()
        imu.linear_acceleration.z = 9.80665
        n_total = int(seconds * FS)
        sent = 0
        t_start = time.monotonic()
        c_start = _cpu_s(ingest.pid)
        marks: list[float] = []
        rss: list[float] = []
        next_sample = 0.0
        max_lag = 0.0
        while sent < n_total:
            due = t_start + sent / FS
            lag = time.monotonic() - due
            max_lag = max(max_lag, lag)
            if lag < 0:
                rclpy.spin_once(node, timeout_sec=-lag)
                continue
            k = min(BLOCK, n_total - sent)
            t_ns = T0 + int(sent * 1e9 / FS)
            block.header.stamp.sec, block.header.stamp.nanosec = divmod(t_ns, 10**9)
            block.samples = (rng.standard_normal(k * N_BLOCK) * 0.01).tolist()
            publish(block_pub, block)
            values = rng.standard_normal((k, N_IMU)) * 0.01
            for j in range(k):
                s = T0 + int((sent + j) * 1e9 / FS)
                imu.header.stamp.sec, imu.header.stamp.nanosec = divmod(s, 10**9)
                for c, pub in enumerate(imu_pubs):
                    imu.linear_acceleration.x = float(values[j, c])
                    publish(pub, imu)
            sent += k
            rclpy.spin_once(node, timeout_sec=0)
            now = time.monotonic() - t_start
            if now >= next_sample:
                marks.append(now)
                rss.append(_rss_mb(ingest.pid))
                next_sample = now + 1.0
        wall = time.monotonic() - t_start
        cpu = _cpu_s(ingest.pid) - c_start
        done_pub.publish(String(data="load bench"))
        expected = {**{n: sent for n in names}, **{f"i{c}": sent for c in range(N_IMU)}}
        # ingest cuts what it holds; the last window travels: until the reader has every sample
        # sent (at most 60 s; short of that samples were lost, and once ingest is idle none come)
        end = time.monotonic() + 60
        while time.monotonic() < end and counted_so_far[0] < sent * (N_BLOCK + N_IMU):
            rclpy.spin_once(node, timeout_sec=0.2)
            if time.monotonic() > end - 50 and ingest_idle(ingest.pid):
                break
        code, log = stop_process(ingest)
        stop_pub.publish(String(data="stop"))
        reader.wait(timeout=60)
        follower.join(timeout=10)
        counted = json.loads(reader_lines[-1])
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for proc in (ingest, reader):
            if proc.poll() is None:
                proc.kill()
    samples_in = sent * (N_BLOCK + N_IMU)
    out = counted["out"]
    samples_out = sum(out.get(n, 0) for n in expected)
    slope = rss_slope(marks, rss, seconds)
    return {"seconds": seconds, "block_channels": N_BLOCK, "imu_streams": N_IMU, "sample_rate_hz": FS,
            "messages_per_s": round((sent / BLOCK + sent * N_IMU) / wall), "samples_in": samples_in,
            "samples_out": samples_out, "channels_short": sorted(n for n in expected if out.get(n, 0) != sent),
            "windows": counted["windows"], "windows_unawaited": counted["unawaited"], "wall_s": round(wall, 1),
            "max_publish_lag_s": round(max_lag, 3),
            "ingest_cpu_s": round(cpu, 1), "ingest_cpu_per_s": round(cpu / wall, 3),
            "rss_mb_start": round(rss[0], 1), "rss_mb_end": round(rss[-1], 1), "rss_mb_max": round(max(rss), 1),
            "rss_slope_mb_per_min": round(slope, 3), "ingest_exit_code": code, "publish_retries": retries[0],
            "rss_mb_every_10_s": [round(v, 1) for v in rss[::10]],
            "ingest_log_tail": log[-1500:] if code else "", "load_average": [round(v, 2) for v in os.getloadavg()]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seconds", type=float, default=600.0)
    a = p.parse_args(argv)
    r = run(a.seconds)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_load.json").write_text(json.dumps(r, indent=1))
    print(json.dumps(r, indent=1))
    ok = r["samples_in"] == r["samples_out"] and r["rss_slope_mb_per_min"] < 1.0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
