"""Issue 4: `shm-ros run` starts a three-node graph from a config, restarts a node that was killed,
and Ctrl-C stops everything with exit code 0."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from test_graph_replay import STRUCTURE


def _children(pid: int) -> dict[int, str]:
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                out[int(entry.name)] = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, IndexError, ValueError):
            continue
    return out


def _wait_for(pred, timeout: float = 30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = pred()
        if value:
            return value
        time.sleep(0.2)
    return None


def test_supervisor_restarts_a_killed_node_and_stops_cleanly(tmp_path):
    structure = tmp_path / "structure.yaml"
    structure.write_text(STRUCTURE)
    config = tmp_path / "graph.yaml"
    config.write_text(yaml.safe_dump({
        "graph": {"mode": "processes", "restart": True},
        "nodes": {
            "ingest": {"parameters": {"structure": str(structure), "window_s": 10.0}},
            "identify": {"parameters": {"method": "ssi-cov"}},
            "recorder": {"parameters": {"output": str(tmp_path / "out")}},
        },
    }))
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        kids = _wait_for(lambda: k if len(k := _children(sup.pid)) == 3 else None)
        assert kids, "three node processes expected"
        assert sorted(c.split("shm_ros.ros.")[1].split()[0] for c in kids.values()) == [
            "identify_node", "ingest_node", "recorder_node"]
        time.sleep(2.0)  # let the nodes come up
        victim = next(p for p, c in kids.items() if "identify_node" in c)
        os.kill(victim, signal.SIGKILL)
        restarted = _wait_for(lambda: next((p for p, c in _children(sup.pid).items()
                                             if "identify_node" in c and p != victim), None))
        assert restarted, "the killed node was not restarted"
        assert len(_children(sup.pid)) == 3
        time.sleep(1.0)
        sup.send_signal(signal.SIGINT)
        out, _ = sup.communicate(timeout=40)
    finally:
        if sup.poll() is None:
            sup.kill()
            sup.communicate()
    assert sup.returncode == 0, out
    assert "restarting" in out
    assert "all nodes stopped" in out
    assert not _children(sup.pid)
    assert (tmp_path / "out" / "metadata.yaml").exists()  # the recorder closed its bag cleanly


def test_bad_graph_config_names_the_field(tmp_path):
    config = tmp_path / "graph.yaml"
    config.write_text(yaml.safe_dump({"nodes": {"x": {"kind": "nonsense"}}}))
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert "nodes.x.kind" in run.stderr and str(config) in run.stderr


@pytest.mark.parametrize("mode", ["single"])
def test_single_process_graph_stops_on_sigint(tmp_path, mode):
    structure = tmp_path / "structure.yaml"
    structure.write_text(STRUCTURE)
    config = tmp_path / "graph.yaml"
    config.write_text(yaml.safe_dump({
        "graph": {"mode": mode},
        "nodes": {"ingest": {"parameters": {"structure": str(structure)}},
                  "identify": {"parameters": {}}},
    }))
    proc = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []

    def read() -> None:
        for line in proc.stdout:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    # both nodes constructed (each logs a line when it is up), not just some seconds elapsed
    up = _wait_for(lambda: any("identify with" in x for x in lines) and any(
        "ingest for sensors" in x for x in lines), timeout=90)
    assert proc.poll() is None, "".join(lines)
    assert up, "".join(lines)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    reader.join(timeout=10)
    out = "".join(lines)
    assert proc.returncode == 0, out
