"""The shipped graph file is a standard ROS 2 parameters file: a node started with
``--ros-args --params-file config/pipeline.yaml`` has exactly the parameters it has under
``shm-ros run config/pipeline.yaml``; every node of that graph reports on /diagnostics; a launch
file for ROS installations starts the same nodes with the same file."""

from __future__ import annotations

import ast
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import yaml
from ros_helpers.graph import diagnostics_seen, node_parameters, stop

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
    assert set(nodes) == {"ingest", "identify", "track", "update", "predict", "recorder"}
    graph = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", "pipeline.yaml", "--no-restart"],
                             cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             start_new_session=True)
    try:
        under_run = {name: node_parameters(name) for name in nodes}
        # every node of the graph reports on /diagnostics, busy or idle
        status = diagnostics_seen([f"{name}: status" for name in nodes])
    finally:
        graph.send_signal(signal.SIGINT)
        out, _ = graph.communicate(timeout=60)
    assert graph.returncode == 0, out[-3000:]
    assert "all nodes stopped" in out
    assert "0 windows published" in status["ingest: status"] and "recorded" in status["recorder: status"]

    for name, given in nodes.items():
        shutil.rmtree(cwd / "out", ignore_errors=True)
        proc = subprocess.Popen([sys.executable, "-m", f"shm_ros.ros.{node_kind(name, 'test')}_node", "--ros-args",
                                 "-r", f"__node:={name}", "--params-file", "pipeline.yaml"],
                                cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                env=dict(os.environ))
        try:
            alone = node_parameters(name)
        finally:
            code, log = stop(proc)
        assert code == 0, log[-3000:]
        assert alone == under_run[name], name
        for key, value in _flat(given).items():  # what the file says is what the node has
            assert alone[key]["value"] == value, (name, key)


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[prefix + k] = v
    return out


def test_launch_file_starts_the_same_nodes_with_the_same_file():
    """`launch`/`launch_ros` are not on PyPI: the launch file is checked by parsing it."""
    tree = ast.parse((ROOT / "launch" / "pipeline.launch.py").read_text())
    calls = [n for n in ast.walk(tree)
             if isinstance(n, ast.Call) and getattr(n.func, "id", getattr(n.func, "attr", "")) == "Node"]
    started = {}
    for call in calls:
        kw = {k.arg: k.value for k in call.keywords}
        assert ast.literal_eval(kw["package"]) == "shm_ros"
        name = ast.literal_eval(kw["name"])
        started[name] = ast.literal_eval(kw["executable"])
        params = kw["parameters"]
        assert isinstance(params, ast.List) and len(params.elts) == 1
        assert isinstance(params.elts[0], ast.Name) and params.elts[0].id == "params_file", name
    from shm_ros.ros.supervisor import node_kind

    assert started == {name: node_kind(name, "launch") for name in _nodes()}
    for executable in started.values():  # `ros2 run shm_ros <executable>` exists
        assert (ROOT / "executables" / executable).is_file(), executable
    text = (ROOT / "launch" / "pipeline.launch.py").read_text()
    assert "'config', 'pipeline.yaml'" in text or '"config", "pipeline.yaml"' in text
