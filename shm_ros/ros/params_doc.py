"""``docs/parameters.md``: every node's parameters, generated from the configuration dataclasses
(``python -m shm_ros.ros.params_doc > docs/parameters.md``; a test checks that the file is current)."""

from __future__ import annotations

import sys

from shm_ros.core.config import OptionSpec, format_value, nested_configs, option_specs


def _rows(cls: type, prefix: str = "") -> list[tuple[str, OptionSpec]]:
    rows = [(prefix + s.name, s) for s in option_specs(cls) if s.ros]
    for field, sub in nested_configs(cls):
        rows += _rows(sub, f"{prefix}{field}.")
    return rows


def _nodes() -> list[tuple[str, str, list[type]]]:
    from shm_ros.core.bayes.update import UpdateConfig
    from shm_ros.core.explain.config import ExplainConfig
    from shm_ros.core.identify import IdentifyConfig
    from shm_ros.core.ingest import IngestConfig
    from shm_ros.core.predict import PredictConfig
    from shm_ros.core.tracking import TrackingConfig
    from shm_ros.ros.explain_node import ExplainNodeConfig
    from shm_ros.ros.identify_node import IdentifyNodeConfig
    from shm_ros.ros.ingest_node import IngestNodeConfig
    from shm_ros.ros.predict_node import PredictNodeConfig
    from shm_ros.ros.recorder_node import RecorderNodeConfig
    from shm_ros.ros.track_node import TrackNodeConfig
    from shm_ros.ros.update_node import UpdateNodeConfig

    return [
        ("ingest", "recording topics in, validated and aligned windows out", [IngestNodeConfig, IngestConfig]),
        ("identify", "windows in, modal estimates out", [IdentifyNodeConfig, IdentifyConfig]),
        ("track", "modal estimates in, tracked modes and novelty out", [TrackNodeConfig, TrackingConfig]),
        ("update", "tracked modes (or modal estimates) in, posterior out (sampling in a worker process)",
         [UpdateNodeConfig, UpdateConfig]),
        ("predict", "event windows in, response predictions out (a worker process)",
         [PredictNodeConfig, PredictConfig]),
        ("explain", "tracked modes (and event windows) in, verdicts on missing physics out (a worker process)",
         [ExplainNodeConfig, ExplainConfig]),
        ("recorder", "pipeline topics into a bag", [RecorderNodeConfig]),
    ]


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
           "shows the same help on a running node.", ""]
    for name, what, classes in _nodes():
        out += [f"## {name}", "", f"{what.capitalize()}; `shm_ros/ros/{name}_node.py`, "
                f"console script `shm-ros-{name}`, `ros2 run shm_ros {name}`.", "",
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
