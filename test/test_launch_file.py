"""launch/pipeline.launch.py starts what `shm-ros run` starts: the same nodes, executables, namespace,
parameters and respawn policy, for the shipped graph file and for a namespaced, manager-driven one.

`launch`, `launch_ros` and `ament_index_python` are not on PyPI, so the file cannot be launched here.
It is executed against stand-ins of the few names it uses (each records the arguments it was given),
its ``OpaqueFunction`` is called with the launch arguments' values, and the ``Node`` actions it
returns are compared with the supervisor's command lines for the same file (node name, namespace,
``python -m`` module, parameters file content, respawn). Every executable it names is a console
script of the package that runs that module's ``main``. Its imports are checked by parsing: nothing
but those three ROS packages (declared in package.xml), the standard library and shm_ros.
"""

from __future__ import annotations

import ast
import runpy
import shutil
import sys
import types
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / "launch" / "pipeline.launch.py"


class _Action:
    """Stand-in of a launch action: keeps what it was given."""

    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration:
    def __init__(self, name: str) -> None:
        self.name = name

    def perform(self, context: dict[str, str]) -> str:
        return context[self.name]


@pytest.fixture
def launch_stand_ins(monkeypatch, tmp_path):
    share = tmp_path / "share" / "shm_ros"
    (share / "config").mkdir(parents=True)
    shutil.copy(ROOT / "config" / "pipeline.yaml", share / "config" / "pipeline.yaml")
    modules = {name: types.ModuleType(name) for name in (
        "launch", "launch.actions", "launch.substitutions", "launch_ros", "launch_ros.actions",
        "ament_index_python", "ament_index_python.packages")}
    modules["launch"].LaunchDescription = lambda actions: list(actions)
    modules["launch.actions"].DeclareLaunchArgument = _Action
    modules["launch.actions"].OpaqueFunction = _Action
    modules["launch.substitutions"].LaunchConfiguration = _LaunchConfiguration
    modules["launch_ros.actions"].Node = _Action
    modules["ament_index_python.packages"].get_package_share_directory = (
        lambda package: str(share) if package == "shm_ros" else pytest.fail(package))
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    return share


def _launched(arguments: dict[str, str]) -> dict[str, dict]:
    """The launch file's Node actions for these launch arguments (defaults for the others)."""
    description = runpy.run_path(str(LAUNCH))["generate_launch_description"]()
    declared = {a.args[0]: a.kwargs["default_value"] for a in description if "default_value" in a.kwargs}
    assert set(arguments) <= set(declared), declared
    (opaque,) = [a for a in description if "function" in a.kwargs]
    nodes = opaque.kwargs["function"]({**declared, **arguments})
    out = {}
    for node in nodes:
        kw = node.kwargs
        assert kw["package"] == "shm_ros" and kw["output"] == "screen"
        (params,) = kw["parameters"]
        out[kw["name"]] = {"executable": kw["executable"], "namespace": kw["namespace"], "parameters": params,
                           "respawn": kw["respawn"], "respawn_delay": kw["respawn_delay"]}
    return out


def _supervised(config_path: Path, **options) -> dict[str, dict]:
    """What `shm-ros run` starts for the same file: per node, from its command line."""
    from shm_ros.ros.registry import node_kind
    from shm_ros.ros.supervisor import Supervisor, load_graph_config

    autostart = options.pop("autostart", True)
    sup = Supervisor(load_graph_config(config_path, **options), log=lambda s: None, autostart=autostart)
    out = {}
    for launch in sup.plan.values():
        cmd = sup.command(launch)
        assert cmd[:2] == [sys.executable, "-m"] and cmd[3] == "--ros-args"
        module = cmd[2]
        remaps = dict(cmd[i + 1].split(":=") for i, a in enumerate(cmd) if a == "-r")
        params_file = yaml.safe_load(Path(cmd[cmd.index("--params-file") + 1]).read_text())
        fq = (remaps.get("__ns", "") + "/" + remaps["__node"])
        (key,) = params_file
        assert key == fq, (key, fq)  # the file's section is the node's fully qualified name
        entry = node_kind(launch.kind)
        assert module == entry.module
        out[remaps["__node"]] = {"executable": entry.executable, "namespace": remaps.get("__ns", ""),
                                 "parameters": params_file[key]["ros__parameters"],
                                 "respawn": launch.respawn and sup.config.restart,
                                 "respawn_delay": launch.respawn_delay_s}
    sup._tmp.cleanup()
    return out


def test_the_launch_file_starts_what_shm_ros_run_starts(launch_stand_ins):
    launched = _launched({})
    shipped = launch_stand_ins / "config" / "pipeline.yaml"
    assert launched == _supervised(shipped)
    # every node of the registry's shipped graph, explain included, each respawned, each with the
    # file's parameters
    from shm_ros.ros.registry import DEFAULT_KINDS

    assert set(launched) == set(DEFAULT_KINDS)
    file = yaml.safe_load(shipped.read_text())
    for name, node in launched.items():
        assert node["respawn"] is True and node["respawn_delay"] > 0
        assert node["parameters"] == {**file[name]["ros__parameters"], "autostart": True}


def test_namespaced_and_manager_driven_launch_matches_too(launch_stand_ins, tmp_path):
    config = tmp_path / "two.yaml"
    config.write_text("ingest:\n  ros__parameters: {structure: s.yaml, window_s: 60.0}\n"
                      "identify_data:\n  ros__parameters: {method: ssi-data}\n")
    launched = _launched({"params_file": str(config), "namespace": "bridge_a", "autostart": "false"})
    assert launched == _supervised(config, namespace="bridge_a", autostart=False)
    assert {n["namespace"] for n in launched.values()} == {"/bridge_a"}
    assert launched["identify_data"]["executable"] == "shm-ros-identify"
    assert all(n["parameters"]["autostart"] is False for n in launched.values())


def test_every_executable_is_a_console_script_of_its_node_module():
    """`ros2 run shm_ros <executable>` (what the launch file starts) runs the module `shm-ros run` runs."""
    from shm_ros.ros.registry import NODES, entry_points

    scripts = dict(e.replace(" ", "").split("=") for e in entry_points())
    for node in NODES:
        assert scripts[node.executable] == f"{node.module}:main"
        tree = ast.parse((ROOT / Path(*node.module.split("."))).with_suffix(".py").read_text())
        names = {d.name for d in tree.body if isinstance(d, ast.FunctionDef)}
        assert {"main", "make_node"} <= names, node.kind


def test_the_launch_file_needs_only_declared_packages():
    tree = ast.parse(LAUNCH.read_text())
    tops = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            tops |= {a.name.split(".")[0] for a in n.names}
        elif isinstance(n, ast.ImportFrom) and n.module:
            tops.add(n.module.split(".")[0])
    ros = tops - set(sys.stdlib_module_names) - {"shm_ros"}
    assert ros == {"launch", "launch_ros", "ament_index_python"}, ros
    declared = {e.text.strip() for e in ET.parse(ROOT / "package.xml").getroot().iter("exec_depend") if e.text}
    assert ros <= declared, ros - declared
