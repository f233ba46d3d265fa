"""Faults: recordings with injected faults replayed through real node processes
(ingest -> identify, recorder of windows, estimates and /diagnostics) give diagnostics that name the
topic and field of each fault, flagged samples stay in the windows (flagged, not dropped), and no
node crashes: every process is alive after the faults and exits 0 on SIGINT.

Faults: NaN samples, a duplicated stamp, a gap on every channel, a dead channel, a clock jump
backwards, an Imu topic that no sensor uses, a NaN temperature, an Imu message whose bytes are not
an Imu, malformed AccelBlocks (samples that do not fill the channels, unknown units), a truncated
MCAP bag (`shm-ros replay` replays what it can read and exits non-zero naming the bag) and a
best-effort publisher (the sensor-data subscription must take it).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from ros_helpers.graph import node_process, replay, stop, wait_identified, wait_ready
from test_graph_replay import STRUCTURE as REPLAY_STRUCTURE

FS = 100.0
P = 10_000_000  # ns per sample at 100 Hz
T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z
B2 = T0 + 60 * 10**9  # second burst of the faulty bag
B3 = T0 + 120 * 10**9  # the bag that gets truncated
B4 = T0 + 180 * 10**9  # the best-effort publisher
WINDOW_S = 5.0
NAN_ROWS = (120, 121, 730)  # f1, burst 1
DEAD = slice(500, 1000)  # f3 constant for all of window [5 s, 10 s)
DUP_ROW = 1600  # f2: a second message with this stamp (another value) follows the first
GAP = slice(2000, 2050)  # 0.5 s missing on every channel (shorter than the 1 s burst pause)
JUMP_ROW, JUMP_NS = 700, -3_002_300_000  # f2, burst 2: clock jumps back by 3.0023 s
HERE = Path(__file__).resolve().parent

# The three-storey frame of the replay test, every sensor on its own Imu topic.
STRUCTURE = REPLAY_STRUCTURE.replace(", source: {topic: roof, axis: y, sign: -1}", "")


def _signal(rng, n: int) -> np.ndarray:
    """Three channels of a lightly damped response to noise (two modes), plus sensor noise."""
    t = np.arange(n) / FS
    x = np.zeros((n, 3))
    for f, shape in ((1.7, (0.45, 0.8, 1.0)), (5.1, (1.0, 0.4, -0.7))):
        amp = np.convolve(rng.standard_normal(n), np.exp(-np.arange(400) / 120.0), "same") * 2e-3
        x += np.outer(amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 6)), shape)
    return x + rng.standard_normal((n, 3)) * 2e-4


def _xyz(v: np.ndarray) -> np.ndarray:
    out = np.zeros((v.size, 3))
    out[:, 0] = v
    out[:, 2] = 9.80665
    return out


def write_faulty_bag(path: Path, rng) -> dict:
    """Two bursts of per-sample Imu with faults, plus bad blocks, an unknown topic, NaN temperature."""
    from shm_ros.io.bags import ACCEL_BLOCK, BagWriter

    n1, n2 = 3000, 1500
    x1, x2 = _signal(rng, n1), _signal(rng, n2)
    x1[list(NAN_ROWS), 0] = np.nan
    x1[DEAD, 2] = 0.003
    g1 = T0 + np.arange(n1, dtype=np.int64) * P
    keep = np.ones(n1, bool)
    keep[GAP] = False
    g2 = B2 + np.arange(n2, dtype=np.int64) * P
    with BagWriter(path, compress=True) as w:
        streams = {}
        for j, name in enumerate(["f1", "f2", "f3"]):
            t, v = g1[keep], x1[keep, j]
            if name == "f2":  # the duplicate follows the original, with another value
                at = int(np.searchsorted(t, g1[DUP_ROW])) + 1
                t, v = np.insert(t, at, g1[DUP_ROW]), np.insert(v, at, 0.5)
            streams[f"/site/accel/{name}"] = (t, _xyz(v))
        w.imu_streams(streams)
        w.temperature("/site/temperature/t1", T0 + 10**9, 12.5)
        streams = {}
        for j, name in enumerate(["f1", "f2", "f3"]):
            t = g2.copy()
            if name == "f2":
                t[JUMP_ROW:] += JUMP_NS
            streams[f"/site/accel/{name}"] = (t, _xyz(x2[:, j]))
        streams["/site/accel/f9"] = (g2[:200], _xyz(x2[:200, 0]))
        w.imu_streams(streams)
        w.temperature("/site/temperature/t1", B2 + 2 * 10**9, float("nan"))
        # an Imu message whose bytes are not an Imu (a driver bug): reported, the rest goes on
        w.write_cdr("/site/accel/f1", "sensor_msgs/msg/Imu", B2 + 5 * 10**9,
                    b"\x00\x01\x00\x00" + b"\x07" * 44)
        Block = w._types[ACCEL_BLOCK]
        w.write("/site/daq/accel_block", ACCEL_BLOCK, B2 + 10**9, Block(
            header=w.header(B2 + 10**9), sample_rate_hz=FS, channel_names=["f1", "f2"],
            samples=np.arange(5.0), units="m/s^2"))
        w.write("/site/daq/accel_block", ACCEL_BLOCK, B2 + 2 * 10**9, Block(
            header=w.header(B2 + 2 * 10**9), sample_rate_hz=FS, channel_names=["f1", "f2"],
            samples=np.zeros(20), units="furlong/fortnight^2"))
    return {"x1": x1, "g1": g1, "keep": keep, "x2": x2, "g2": g2}


def write_truncated_bag(path: Path, rng) -> tuple[np.ndarray, np.ndarray]:
    from shm_ros.io.bags import BagWriter

    n = 3000
    x = _signal(rng, n)
    g = B3 + np.arange(n, dtype=np.int64) * P
    with BagWriter(path) as w:
        w.imu_streams({f"/site/accel/{s}": (g, _xyz(x[:, j])) for j, s in enumerate(["f1", "f2", "f3"])})
    mcap = next(path.glob("*.mcap"))
    with open(mcap, "r+b") as fh:
        fh.truncate(int(mcap.stat().st_size * 0.6))
    return g, x


def _diagnostics(bag: Path) -> list[tuple[str, str, str, dict]]:
    from shm_ros.io.bags import read_messages

    out = []
    for m in read_messages(bag, topics=["/diagnostics"]):
        for s in m.decode().status:
            out.append((s.name, s.message, int(s.level), {kv.key: kv.value for kv in s.values}))
    return out


def _windows(bag: Path) -> list:
    from shm_ros.io.bags import read_messages
    from shm_ros.ros.convert import window_from_msg

    return [window_from_msg(m.decode()) for m in read_messages(bag, topics=["/shm/windows"])]


def _rows(w, origin: int) -> slice:
    first = int(round((w.start_ns - origin) / P))
    return slice(first, first + w.n_samples)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))


def test_faults_through_node_processes_are_reported_flagged_and_survived(tmp_path):
    rng = np.random.default_rng(11)
    structure = tmp_path / "structure.yaml"
    structure.write_text(STRUCTURE)
    faulty = tmp_path / "faulty"
    truth = write_faulty_bag(faulty, rng)
    truncated = tmp_path / "truncated"
    g3, x3 = write_truncated_bag(truncated, rng)
    n4 = 1000
    g4 = B4 + np.arange(n4, dtype=np.int64) * P
    x4 = _signal(rng, n4)
    be_data = tmp_path / "best_effort.npz"
    np.savez(be_data, stamps=g4, values=x4, topics=np.array(["f1", "f2", "f3"]))

    out_bag = tmp_path / "pipeline"
    procs = {
        "ingest": node_process("ingest", {"structure": str(structure), "window_s": WINDOW_S,
                                          "idle_flush_s": 2.0}),
        "identify": node_process("identify", {"max_order": 16}),
        "recorder": node_process("recorder", {"output": str(out_bag), "topics": [
            "/shm/windows", "/diagnostics", "/shm/modal_estimates"]}),
    }
    results = {}
    try:
        wait_ready(subscribers={"/shm/windows": 2, "/diagnostics": 1},
                   publishers={"/shm/modal_estimates": 1, "/shm/ingest/received": 1})
        rep_faulty = replay(faulty, timeout=120)
        rep_trunc = replay(truncated, timeout=120)
        be = subprocess.run([sys.executable, str(HERE / "ros_helpers" / "best_effort_imu.py"),
                             str(be_data), "/driver", "2000"], capture_output=True, text=True,
                            timeout=60)
        wait_identified()  # the last windows (cut at the idle flush) are identified
        alive = {k: p.poll() is None for k, p in procs.items()}
    finally:
        for k, p in procs.items():
            results[k] = stop(p)
    detail = "\n".join([rep_faulty.stdout, rep_faulty.stderr, rep_trunc.stdout, rep_trunc.stderr,
                         be.stdout, be.stderr]
                        + [f"{k}: {c}\n{out[-2500:]}" for k, (c, out) in results.items()])
    # -- no node crashed: alive after every fault, clean exit on SIGINT
    assert alive == {"ingest": True, "identify": True, "recorder": True}, detail
    assert {k: c for k, (c, _) in results.items()} == {"ingest": 0, "identify": 0, "recorder": 0}, detail
    assert rep_faulty.returncode == 0 and "lost 0" in rep_faulty.stdout, detail
    assert be.returncode == 0, detail
    assert "subscribed to /driver/accel/f1" in results["ingest"][1]

    # -- truncated bag: what could be read is replayed (and acknowledged); non-zero exit naming it
    assert rep_trunc.returncode != 0, detail
    assert str(truncated) in rep_trunc.stderr and "truncated" in rep_trunc.stderr, detail
    published = int(rep_trunc.stdout.split("replayed ")[1].split()[0])
    assert 0 < published < 3 * len(g3) and "lost 0" in rep_trunc.stdout, detail

    # -- diagnostics name the topic/field of every fault
    diags = _diagnostics(out_bag)
    found = {(name.removeprefix("ingest: ").split(" (sensor")[0], v.get("code")) for name, _, _, v in diags}
    expected = {
        ("accel/f1.linear_acceleration.x", "nan"),
        ("accel/f2.linear_acceleration.x", "duplicate_stamp"),
        ("accel/f1.linear_acceleration.x", "gap"),
        ("accel/f2.linear_acceleration.x", "gap"),
        ("accel/f3.linear_acceleration.x", "gap"),
        ("accel/f3.linear_acceleration.x", "dead_channel"),
        ("accel/f9", "unknown_topic"),
        ("/site/daq/accel_block", "rejected"),
        ("/site/daq/accel_block.units", "rejected"),
        ("temperature/t1.temperature", "nan"),
    }
    assert expected <= found, sorted(expected - found)
    clock = {c for src, c in found if src == "accel/f2.linear_acceleration.x"}
    assert clock & {"unsnappable", "out_of_order", "late_sample", "rate_mismatch"}, clock
    messages = {name: msg for name, msg, _, _ in diags}
    assert "do not fill 2 channels" in messages["ingest: /site/daq/accel_block"]
    assert "furlong" in messages["ingest: /site/daq/accel_block.units"]
    malformed = [m for n, m, level, _ in diags if n == "ingest: /site/accel/f1" and level == 2]
    assert malformed and "malformed Imu" in malformed[0], malformed
    assert not [d for d in diags if "not processed:" in d[1] and "malformed" not in d[1]], \
        "a message raised in the node"

    # -- flagged samples are in the windows, flagged, with their raw values; nothing is interpolated
    from shm_ros.core.types import SampleFlag

    windows = _windows(out_bag)
    b1 = [w for w in windows if T0 <= w.start_ns < B2]
    x1, keep = truth["x1"], truth["keep"]
    covered = np.zeros(len(x1), int)
    for w in b1:
        r = _rows(w, T0)
        covered[r] += 1
        assert keep[r].all(), f"window {w.window_id} spans the gap"
        assert _same(w.samples, x1[r]), w.window_id
    assert np.array_equal(covered, keep.astype(int))  # every row but the gap, once
    by_start = {int(round((w.start_ns - T0) / P)): w for w in windows}
    w0, w1, w3 = by_start[0], by_start[500], by_start[1500]
    for row in NAN_ROWS:
        w = w0 if row < 500 else w1
        f = w.flags[row % 500, 0]
        assert f & SampleFlag.NAN and np.isnan(w.samples[row % 500, 0])
    assert w1.channel_status[2] == "dead" and np.all(w1.samples[:, 2] == 0.003)
    assert w3.flags[DUP_ROW - 1500, 1] & SampleFlag.DUPLICATE_STAMP
    assert w3.samples[DUP_ROW - 1500, 1] == x1[DUP_ROW, 1]  # the first copy is kept
    assert int(np.count_nonzero(w3.flags)) == 1

    # clock jump on f2 in burst 2: f2 leaves the windows after the jump (MISSING), f1/f3 are intact
    b2 = [w for w in windows if B2 <= w.start_ns < B3]
    assert b2, "no window from the burst with the clock jump"
    for w in b2:
        r = _rows(w, B2)
        assert _same(w.samples[:, [0, 2]], truth["x2"][r][:, [0, 2]])
    after = [w for w in b2 if _rows(w, B2).stop > JUMP_ROW + 100]
    assert after and all(w.channel_status[1] == "dropped" for w in after)

    # truncated bag and best-effort publisher: their samples arrived, exactly
    for origin, stop_ns, x, label in ((B3, B4, x3, "truncated bag"), (B4, B4 + 10**12, x4, "best-effort")):
        ws = [w for w in windows if origin <= w.start_ns < stop_ns]
        assert ws, f"no window from the {label}"
        for w in ws:
            assert _same(w.samples, x[_rows(w, origin)]), label
    assert sum(w.n_samples for w in windows if w.start_ns >= B4) >= 0.9 * n4

    # identify downstream took every window (an error would be a diagnostic, not a crash): one
    # modal estimate per window (estimates are transient local, so the recorder has them all even
    # if it matched identify's writers late; volatile diagnostics could miss the first ones)
    from shm_ros.io.bags import read_messages

    estimated = sorted(m.decode().window_id for m in read_messages(out_bag, topics=["/shm/modal_estimates"]))
    errors = [(n, m) for n, m, level, _ in diags if n.startswith("identify") and level == 2]
    assert estimated == sorted(w.window_id for w in windows), (estimated, errors)
    assert not errors, errors


HUNG_INGEST = """
import sys, threading, time
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu
from std_msgs.msg import UInt64
rclpy.init()
node = rclpy.create_node("hung_ingest")
acks = node.create_publisher(UInt64, "/shm/ingest/received", 100)
seen, acked = [0], [0]
def take(msg):
    seen[0] += 1
    if seen[0] <= 300:  # acknowledges 300 messages, then hangs (keeps its subscription)
        acks.publish(UInt64(data=seen[0]))
        acked[0] = seen[0]
node.create_subscription(Imu, "/site/accel/f1", take, qos_profile_sensor_data)
node.create_timer(0.3, lambda: seen[0] == 0 and acks.publish(UInt64(data=0)))
closed = threading.Event()  # the test closes stdin to stop this node
threading.Thread(target=lambda: (sys.stdin.read(), closed.set()), daemon=True).start()
print("ready", flush=True)
end = time.monotonic() + 600  # (a safety net only)
while rclpy.ok() and not closed.is_set() and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
print("acknowledged", acked[0], flush=True)
"""


def test_replay_stops_with_an_error_when_the_ingest_node_stops_acknowledging(tmp_path):
    """A flow-controlled replay whose ingest node hangs neither waits forever nor floods: it stops
    after ``stall_s`` with an error naming the bag, having sent at most one credit past the last
    acknowledgement, and counts as acknowledged only what the node acknowledged."""
    import threading

    import rclpy

    from shm_ros.io.bags import BagWriter
    from shm_ros.ros.replay import ReplayResult, replay_bag

    n, credit = 3000, 256
    bag = tmp_path / "recording"
    with BagWriter(bag) as w:
        w.imu_series("/site/accel/f1", T0 + np.arange(n, dtype=np.int64) * P,
                     _xyz(_signal(np.random.default_rng(5), n)[:, 0]))
    hung = subprocess.Popen([sys.executable, "-c", HUNG_INGEST], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    results: list[ReplayResult] = []
    try:
        assert hung.stdout is not None and hung.stdout.readline().strip() == "ready"
        rclpy.init()
        try:
            # wait_s only bounds the wait for the node to appear (it returns as soon as it has)
            replay = threading.Thread(target=lambda: results.append(
                replay_bag(bag, credit=credit, wait_s=60.0, stall_s=3.0)), daemon=True)
            replay.start()
            replay.join(timeout=300)  # a hang detector, not a speed target: "never waits forever"
            assert results, "the replay did not return"
        finally:
            rclpy.try_shutdown()
        out, _ = hung.communicate(input="", timeout=60)
    finally:
        if hung.poll() is None:
            hung.kill()
            hung.communicate()
    result = results[0]
    node_acked = int(out.split("acknowledged")[-1].split()[0])
    assert str(bag) in result.error and "no acknowledgement" in result.error, result
    # the replay counts only acknowledged messages (the node's own count is the bound) ...
    assert 0 < result.acknowledged <= node_acked <= 300, (result, out)
    # ... used its credit (stopped because nothing came back, not early) and never more than it
    assert result.acknowledged < result.published <= result.acknowledged + credit, result
    assert result.lost == result.published - result.acknowledged
