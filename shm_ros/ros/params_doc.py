"""``docs/parameters.md``: every node's parameters, generated from the configuration dataclasses
(``python -m shm_ros.ros.params_doc > docs/parameters.md``; a test checks that the file is current)."""

from __future__ import annotations

import sys

from shm_ros.core.config import OptionSpec, format_value, nested_configs, option_specs
from shm_ros.ros.registry import node_table


def _rows(cls: type, prefix: str = "") -> list[tuple[str, OptionSpec]]:
    rows = [(prefix + s.name, s) for s in option_specs(cls) if s.ros]
    for field, sub in nested_configs(cls):
        rows += _rows(sub, f"{prefix}{field}.")
    return rows


def _nodes() -> list[tuple[str, str, list[type]]]:
    """(kind, what it does, configuration classes) of every node of the registry."""
    import importlib

    from shm_ros.ros.registry import NODES

    out = []
    for node in NODES:
        classes = []
        for ref in node.configs:
            module, _, name = ref.partition(":")
            classes.append(getattr(importlib.import_module(module), name))
        out.append((node.kind, node.summary, classes))
    return out


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render() -> str:
    out = ["# Node parameters", "",
           "Generated from the configuration dataclasses by `python -m shm_ros.ros.params_doc` (do not edit",
           "by hand; a test checks that this file is current). The same options, with the same names,",
           "defaults and help, are the flags of the `shm-ros` command of each stage (`--max-order` for",
           "`max_order`, `--preprocess.lowpass-hz` for `preprocess.lowpass_hz`), except where a setting",
           "belongs to the live node only. Options of nested configurations are dotted; in a parameters",
           "file they may be nested (`preprocess: {lowpass_hz: 20.0}`). Parameters are read once at",
           "start (read-only); an unset option is declared without a value. Every node also has the",
           "standard `use_sim_time` (see `shm-ros replay --clock`). `ros2 param describe <node> <name>`",
           "shows the same help on a running node.", "",
           "## Nodes", "",
           "The node registry (`shm_ros/ros/registry.py`): the console scripts, the launch file, `shm-ros run`",
           "and this table come from it. Every node is a managed (lifecycle) node with the parameter",
           "`autostart` (default true: it configures and activates itself; false: a lifecycle manager",
           "drives it through the `lifecycle_msgs` services, docs/deployment.md).", "",
           *node_table(), ""]
    for name, what, classes in _nodes():
        out += [f"## {name}", "", f"{what.capitalize()}; `shm_ros/ros/{name}_node.py`, "
                f"console script `shm-ros-{name}`, `ros2 run shm_ros shm-ros-{name}`.", "",
                "| parameter | type | default | choices | what it does |", "|---|---|---|---|---|"]
        for cls in classes:
            for pname, spec in _rows(cls):
                kind = {bool: "bool", int: "integer", float: "double", str: "string",
                        list: "string array"}[spec.value_type]
                default = ("unset" if spec.default is None else "empty" if spec.default in ("", []) else
                           f"`{format_value(spec.default)}`")
                choices = " \\| ".join(f"`{c}`" for c in spec.choices) if spec.choices else ""
                out.append(f"| `{pname}` | {kind} | {_cell(default)} | {choices} | {_cell(spec.help)} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    sys.stdout.write(render())
