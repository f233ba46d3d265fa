"""One graph on two hosts: ingest on the acquisition computer, identify and the recorder on an
analysis server, joined only by a network link.

The two hosts are two network namespaces joined by a veth pair (CI runs as root). Fast DDS is told
to use UDP only (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): both namespaces share ``/dev/shm``, and
Fast DDS would otherwise move the data through shared memory, which separate machines cannot do.
The same recording replayed through the same nodes on one host must give the same windows and the
same modal estimates, and the analysis side's veth must have received the windows' bytes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from ros_helpers.graph import recorded_windows, stop

ACQ_IP, ANA_IP = "10.77.0.1", "10.77.0.2"
WINDOW_S = 60.0
N_WINDOWS = 3


def _sh(*args: str) -> None:
    subprocess.run(args, check=True, capture_output=True, text=True)


@contextmanager
def two_hosts():
    """Two network namespaces ``acq`` and ``ana`` joined by a veth pair; yields their names and
    the analysis side's interface."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.fail("the two-host test needs root and iproute2's `ip` (CI runs as root)")
    tag = uuid.uuid4().hex[:6]
    acq, ana = f"shm-acq-{tag}", f"shm-ana-{tag}"
    va, vb = f"va{tag}", f"vb{tag}"
    _sh("ip", "netns", "add", acq)
    _sh("ip", "netns", "add", ana)
    try:
        _sh("ip", "link", "add", va, "type", "veth", "peer", "name", vb)
        _sh("ip", "link", "set", va, "netns", acq)
        _sh("ip", "link", "set", vb, "netns", ana)
        for ns, dev, ip in ((acq, va, ACQ_IP), (ana, vb, ANA_IP)):
            _sh("ip", "-n", ns, "addr", "add", f"{ip}/24", "dev", dev)
            _sh("ip", "-n", ns, "link", "set", dev, "up")
            _sh("ip", "-n", ns, "link", "set", "lo", "up")
            # DDS discovery is multicast: give it a route on the link
            _sh("ip", "-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)
        yield acq, ana, vb
    finally:
        subprocess.run(["ip", "netns", "del", acq], capture_output=True)
        subprocess.run(["ip", "netns", "del", ana], capture_output=True)


def _env(two: bool) -> dict[str, str]:
    env = dict(os.environ, FASTDDS_BUILTIN_TRANSPORTS="UDPv4", PYTHONUNBUFFERED="1")
    if two:
        # the namespaces are a private network: discovery on the subnet, plus each other as peers
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
        env["ROS_STATIC_PEERS"] = f"{ACQ_IP};{ANA_IP}"
    return env


def _prefix(ns: str | None) -> list[str]:
    return ["ip", "netns", "exec", ns] if ns else []


def _node(ns: str | None, kind: str, params: dict, env: dict) -> subprocess.Popen:
    args = _prefix(ns) + [sys.executable, "-m", f"shm_ros.ros.{kind}_node", "--ros-args"]
    for key, value in params.items():
        args += ["-p", f"{key}:={value}"]
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)


_PROBE = r"""
import sys, time
import rclpy
from shm_interfaces.msg import ModalEstimate
from shm_ros.ros.qos import stream_qos
want_subs, n_estimates, timeout = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rclpy.init()
node = rclpy.create_node("test_two_hosts_probe")
seen = set()
node.create_subscription(ModalEstimate, "/shm/modal_estimates", lambda m: seen.add(m.window_id),
                         stream_qos())
end = time.monotonic() + timeout
ok = False
while time.monotonic() < end and not ok:
    rclpy.spin_once(node, timeout_sec=0.1)
    if want_subs == "ready":  # every node of the graph is matched
        ok = (node.count_subscribers("/shm/windows") >= 2
              and node.count_publishers("/shm/ingest/received") >= 1
              and node.count_publishers("/shm/modal_estimates") >= 1)
    else:
        ok = len(seen) >= n_estimates
print(len(seen))
sys.exit(0 if ok else 1)
"""


def _probe(ns: str | None, env: dict, what: str, n: int = 0, timeout: float = 120.0) -> None:
    run = subprocess.run(_prefix(ns) + [sys.executable, "-c", _PROBE, what, str(n), str(timeout)],
                         capture_output=True, text=True, timeout=timeout + 30, env=env)
    assert run.returncode == 0, f"{what} not reached in {ns or 'one host'}: {run.stdout} {run.stderr[-2000:]}"


def _rx_bytes(ns: str, dev: str) -> int:
    out = subprocess.run(["ip", "netns", "exec", ns, "cat", f"/sys/class/net/{dev}/statistics/rx_bytes"],
                         check=True, capture_output=True, text=True)
    return int(out.stdout)


def _run_graph(bag: Path, structure: Path, out_bag: Path, acq: str | None, ana: str | None) -> None:
    env = _env(two=acq is not None)
    # reliable recording subscriptions: with UDP only (no shared memory), best-effort samples dropped
    # from a full socket buffer on a busy host never arrive, and the replay then waits out its drain
    # limit for acknowledgements that cannot come
    ingest = _node(acq, "ingest", {"structure": str(structure), "window_s": WINDOW_S, "reliable_input": True}, env)
    identify = _node(ana, "identify", {}, env)
    recorder = _node(ana, "recorder", {"output": str(out_bag),
                                       "topics": "[/shm/windows,/shm/modal_estimates]"}, env)
    procs = [ingest, identify, recorder]
    problem = ""
    try:
        _probe(ana, env, "ready")
        # longer than the replay's own drain limit (300 s), so that it reports rather than is killed
        rep = subprocess.run(_prefix(acq) + [sys.executable, "-m", "shm_ros.cli", "replay", str(bag)],
                             capture_output=True, text=True, timeout=420, env=env)
        if rep.returncode != 0 or "lost 0" not in rep.stdout:
            problem = f"replay: exit {rep.returncode}\n{rep.stdout}\n{rep.stderr[-3000:]}"
        else:
            try:
                _probe(ana, env, "estimates", N_WINDOWS)
            except AssertionError as exc:
                problem = str(exc)
    finally:
        outs = [stop(p) for p in reversed(procs)]
    # on a failure, what every node said: the only record of why a graph stalled
    logs = "\n".join(f"--- {name} (exit {code}):\n{text[-2500:]}"
                     for name, (code, text) in zip(("recorder", "identify", "ingest"), outs, strict=True))
    assert not problem, problem + "\n" + logs
    for code, _ in outs:
        assert code == 0, logs


def _estimates(bag: Path) -> dict[str, np.ndarray]:
    from shm_ros.io.bags import read_messages

    out = {}
    for m in read_messages(bag):
        if m.topic == "/shm/modal_estimates":
            e = m.decode()
            out[e.window_id] = np.array([[md.frequency_hz, md.damping_ratio] for md in e.modes], float).reshape(-1, 2)
    return out


def test_ingest_on_one_host_and_analysis_on_another_give_the_one_host_results(tmp_path):
    from shm_ros.core.simulate import named_scenario, simulate_campaign
    from shm_ros.io.campaign import write_campaign

    scenario = named_scenario("girder")
    scenario.n_windows, scenario.window_s, scenario.seed = N_WINDOWS, WINDOW_S, 11
    files = write_campaign(simulate_campaign(scenario), tmp_path / "recording")

    one = tmp_path / "one_host"
    _run_graph(Path(files.bag), Path(files.structure), one, None, None)
    with two_hosts() as (acq, ana, dev):
        rx0 = _rx_bytes(ana, dev)
        t0 = time.monotonic()
        two = tmp_path / "two_hosts"
        _run_graph(Path(files.bag), Path(files.structure), two, acq, ana)
        received = _rx_bytes(ana, dev) - rx0
    print(f"two hosts: {received / 1e6:.1f} MB received by the analysis host in {time.monotonic() - t0:.0f} s")

    w_one, w_two = recorded_windows(one), recorded_windows(two)
    assert len(w_one) == len(w_two) == N_WINDOWS
    window_bytes = 0
    for (a, va), (b, vb) in zip(w_one, w_two, strict=True):
        assert a.window_id == b.window_id
        np.testing.assert_array_equal(va, vb)
        window_bytes += vb.nbytes
    e_one, e_two = _estimates(one), _estimates(two)
    assert sorted(e_one) == sorted(e_two) and len(e_one) == N_WINDOWS
    for wid, f in e_one.items():
        np.testing.assert_array_equal(f, e_two[wid])
        assert len(f) >= 2, f"window {wid}: too few modes identified ({f})"
    # the windows crossed the link: at least 1 MB, and at least their own size
    assert received >= max(1_000_000, window_bytes), (received, window_bytes)
