"""The shipped graph file is a standard ROS 2 parameters file: a node started with
``--ros-args --params-file config/pipeline.yaml`` has exactly the parameters it has under
``shm-ros run config/pipeline.yaml``; every node of that graph reports on /diagnostics (the launch
file for ROS installations is checked in test_launch_file.py)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import yaml
from ros_helpers.graph import diagnostics_seen, nodes_parameters, stop

ROOT = Path(__file__).resolve().parents[1]
PIPELINE = ROOT / "config" / "pipeline.yaml"


def _workdir(tmp_path: Path) -> Path:
    """The shipped file with its relative paths resolvable: a copy next to the examples."""
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    shutil.copy(PIPELINE, tmp_path / "pipeline.yaml")
    return tmp_path


def _nodes() -> dict[str, dict]:
    return {name: spec["ros__parameters"] for name, spec in yaml.safe_load(PIPELINE.read_text()).items()}


def test_params_file_gives_every_node_the_parameters_it_has_under_shm_ros_run(tmp_path):
    from shm_ros.ros.supervisor import node_kind

    cwd = _workdir(tmp_path)
    nodes = _nodes()
    assert set(nodes) == {"ingest", "identify", "track", "update", "predict", "explain", "recorder"}
    graph = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", "pipeline.yaml", "--no-restart"],
                             cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             start_new_session=True)
    try:
        under_run = nodes_parameters(list(nodes))
        # every node of the graph reports on /diagnostics, busy or idle
        status = diagnostics_seen([f"{name}: status" for name in nodes])
    finally:
        graph.send_signal(signal.SIGINT)
        out, _ = graph.communicate(timeout=60)
    assert graph.returncode == 0, out[-3000:]
    assert "all nodes stopped" in out
    assert "0 windows published" in status["ingest: status"] and "recorded" in status["recorder: status"]

    # each node on its own (not under `shm-ros run`), all of them at once: one start-up for the seven
    shutil.rmtree(cwd / "out", ignore_errors=True)
    procs = {name: subprocess.Popen([sys.executable, "-m", f"shm_ros.ros.{node_kind(name, 'test')}_node",
                                     "--ros-args", "-r", f"__node:={name}", "--params-file", "pipeline.yaml"],
                                    cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                    env=dict(os.environ))
             for name in nodes}
    try:
        alone = nodes_parameters(list(nodes))
    finally:
        for proc in procs.values():  # all asked to stop first, then each waited for
            proc.send_signal(signal.SIGINT)
        stopped = {name: stop(proc) for name, proc in procs.items()}
    for name, given in nodes.items():
        code, log = stopped[name]
        assert code == 0, log[-3000:]
        assert alone[name] == under_run[name], name
        for key, value in _flat(given).items():  # what the file says is what the node has
            assert alone[name][key]["value"] == value, (name, key)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out
