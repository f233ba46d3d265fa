"""Start real node processes for tests and stop them the way a user does (SIGINT)."""

from __future__ import annotations

import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from shm_ros.ros.supervisor import node_process, stop_process  # noqa: F401 (re-exported)


def stop(proc: subprocess.Popen, timeout: float = 20.0) -> tuple[int, str]:
    return stop_process(proc, timeout)


_WAIT = r"""
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
subs, pubs, timeout = json.loads(sys.argv[1]), json.loads(sys.argv[2]), float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("test_wait_ready")
# with an ingest node, its window publisher must itself have matched the window readers (what
# this probe sees of the graph can be ahead of what ingest has matched on a busy machine)
readers = [0]
def on_diag(m):
    for st in m.status:
        if st.name == "ingest: status":
            readers[0] = int({kv.key: kv.value for kv in st.values}.get("window_readers", 0))
node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)
need_readers = subs.get("/shm/windows", 0) if "/shm/ingest/received" in pubs else 0
end, ok = time.monotonic() + timeout, False
while time.monotonic() < end and not ok:
    ok = (all(node.count_subscribers(t) >= k for t, k in subs.items())
          and all(node.count_publishers(t) >= k for t, k in pubs.items())
          and readers[0] >= need_readers)
    rclpy.spin_once(node, timeout_sec=0.1)
node.destroy_node()
rclpy.shutdown()
sys.exit(0 if ok else 1)
"""


def wait_ready(subscribers: dict[str, int] | None = None, publishers: dict[str, int] | None = None,
               timeout: float = 90.0) -> None:
    """Block until the graph has at least these subscriber/publisher counts per topic: node
    processes import for a while, and pipeline topics keep nothing for late joiners."""
    import json

    run = subprocess.run([sys.executable, "-c", _WAIT, json.dumps(subscribers or {}),
                          json.dumps(publishers or {}), str(timeout)],
                         capture_output=True, text=True, timeout=timeout + 30)
    assert run.returncode == 0, f"graph not ready: {subscribers} {publishers}\n{run.stderr[-2000:]}"


_WAIT_IDENTIFIED = r"""
import sys, time
import rclpy
from shm_interfaces.msg import ModalEstimate, Window
from shm_ros.ros.qos import stream_qos
quiet, timeout = float(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("test_wait_identified")
windows, estimates, last = set(), set(), [time.monotonic()]
def on_window(m):
    windows.add(m.window_id); last[0] = time.monotonic()
node.create_subscription(Window, "/shm/windows", on_window, stream_qos())
node.create_subscription(ModalEstimate, "/shm/modal_estimates",
                         lambda m: estimates.add(m.window_id), stream_qos())
end = time.monotonic() + timeout
ok = False
while time.monotonic() < end and not ok:
    rclpy.spin_once(node, timeout_sec=0.1)
    ok = bool(windows) and windows <= estimates and time.monotonic() - last[0] > quiet
node.destroy_node()
rclpy.shutdown()
print(len(windows), len(estimates))
sys.exit(0 if ok else 1)
"""


def wait_identified(quiet_s: float = 5.0, timeout: float = 90.0) -> None:
    """Block until no new window has been published for ``quiet_s`` and every window seen has a
    modal estimate (both topics are transient local, so a late probe still sees the latest)."""
    run = subprocess.run([sys.executable, "-c", _WAIT_IDENTIFIED, str(quiet_s), str(timeout)],
                         capture_output=True, text=True, timeout=timeout + 30)
    assert run.returncode == 0, f"windows not all identified: {run.stdout} {run.stderr[-2000:]}"


@contextmanager
def running(*procs: subprocess.Popen, subscribers: dict[str, int] | None = None,
            publishers: dict[str, int] | None = None):
    wait_ready(subscribers, publishers)
    results: dict[int, tuple[int, str]] = {}
    try:
        yield results
    finally:
        for p in procs:
            results[p.pid] = stop(p)


def replay(bag: Path, *extra: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "shm_ros.cli", "replay", str(bag), *extra],
                          capture_output=True, text=True, timeout=timeout)


def _written(out: Path):
    """The messages in a running recorder's bag so far: every message is on disk once written, and
    the open split, cut short as it is, is read up to its last complete message."""
    from shm_ros.io.errors import BagError
    from shm_ros.io.sources import open_source

    # the recorder's splits: closed ones in ``out``, the one being written in ``out/out_<k>/``
    for split in sorted(p for p in [*out.glob("*"), *out.glob("*/*")] if p.suffix in (".mcap", ".db3")):
        try:
            yield from open_source(split).messages()
        except (BagError, OSError, ValueError):  # the end of what is written so far
            pass


def windows_written(out: Path) -> int:
    """Windows in a running recorder's bag so far (closed splits and the open one)."""
    return sum(m.topic == "/shm/windows" for m in _written(out))


def ids_written(out: Path, topics: tuple[str, ...]) -> dict[str, set[str]]:
    """The window ids of each of ``topics`` (window-keyed types) in a running recorder's bag so far."""
    from shm_ros.ros.recorder_node import window_id_of

    ids: dict[str, set[str]] = {t: set() for t in topics}
    for m in _written(out):
        if m.topic in ids:
            ids[m.topic].add(window_id_of(m.data))
    return ids


def wait_for_windows(out: Path, n: int, timeout: float = 15.0) -> None:
    """Until ``n`` windows are in the running recorder's bag at ``out`` (or ``timeout`` s): a replay
    ends when ingest has acknowledged the samples, and the last window may still be on its way to
    the recorder; stopping the nodes before it arrives would lose it. The recorder flushes every
    message to its split as it writes it, so the count is exact and the wait ends with the n-th
    window; ``timeout`` is a bound well above a message's delivery time on a loaded machine."""
    end = time.monotonic() + timeout
    while windows_written(out) < n and time.monotonic() < end:
        time.sleep(0.2)


def recorded_windows(bag: Path) -> list:
    from shm_ros.io.bags import read_messages

    out = []
    for m in read_messages(bag):
        if m.topic == "/shm/windows":
            w = m.decode()
            n, c = int(w.n_samples), len(w.channel_names)
            out.append((w, np.asarray(w.samples).reshape(n, c)))
    return out


_PARAMETERS = r"""
import json, sys
import rclpy
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
from rclpy.parameter import parameter_value_to_python

targets = json.loads(sys.argv[1])
rclpy.init()
node = rclpy.create_node("test_parameter_probe")

def call(target, srv, name, request):
    client = node.create_client(srv, f"/{target}/{name}")
    if not client.wait_for_service(timeout_sec=120.0):
        sys.exit(f"no service /{target}/{name}")
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=60.0)
    if future.result() is None:
        sys.exit(f"/{target}/{name}: no answer")
    return future.result()

found = {}
for target in targets:
    names = list(call(target, ListParameters, "list_parameters", ListParameters.Request()).result.names)
    values = call(target, GetParameters, "get_parameters", GetParameters.Request(names=names)).values
    descriptors = call(target, DescribeParameters, "describe_parameters",
                       DescribeParameters.Request(names=names)).descriptors
    assert len(values) == len(names) == len(descriptors), (target, len(values), len(names))
    found[target] = {n: {"value": parameter_value_to_python(v), "type": d.type,
                         "dynamic": d.dynamic_typing, "description": d.description,
                         "constraints": d.additional_constraints, "read_only": d.read_only}
                     for n, v, d in zip(names, values, descriptors, strict=True)}
print(json.dumps(found))
"""


def node_parameters(name: str, timeout: float = 300.0) -> dict[str, dict]:
    """Every parameter of the running node ``/name`` as its services report them: value, type,
    dynamic typing, description, constraints, read-only (waits for the node's services)."""
    return nodes_parameters([name], timeout)[name]


def nodes_parameters(names: list[str], timeout: float = 300.0) -> dict[str, dict[str, dict]]:
    """:func:`node_parameters` of each of the running nodes ``names``, asked by one probe process."""
    import json

    run = subprocess.run([sys.executable, "-c", _PARAMETERS, json.dumps(names)], capture_output=True, text=True,
                         timeout=timeout)
    assert run.returncode == 0, run.stdout + run.stderr
    return json.loads(run.stdout.strip().splitlines()[-1])


_DIAGNOSTICS = r"""
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
wanted, timeout = set(json.loads(sys.argv[1])), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("test_diagnostics_probe")
seen = {}
def on(msg):
    for s in msg.status:
        seen.setdefault(s.name, s.message)
node.create_subscription(DiagnosticArray, "/diagnostics", on, 50)
end = time.monotonic() + timeout
while time.monotonic() < end and not wanted <= set(seen):
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps(seen))
sys.exit(0 if wanted <= set(seen) else 1)
"""


def diagnostics_seen(names: list[str], timeout: float = 60.0) -> dict[str, str]:
    """Wait until a /diagnostics status of each of ``names`` arrived; returns name -> message."""
    import json

    run = subprocess.run([sys.executable, "-c", _DIAGNOSTICS, json.dumps(names), str(timeout)],
                         capture_output=True, text=True, timeout=timeout + 60)
    assert run.returncode == 0, f"no /diagnostics from {names}: {run.stdout[-2000:]} {run.stderr[-2000:]}"
    return json.loads(run.stdout.strip().splitlines()[-1])
