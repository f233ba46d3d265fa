"""Node parameters, command-line options and the core's configuration dataclasses agree.

For each stage, the real node runs in its own process and its parameters are read over ROS
(``list_parameters`` / ``get_parameters`` / ``describe_parameters`` services) by a client node; the
command's parser is built from ``shm_ros.cli``. Every option must have the same default in the
dataclass, on the node and on the command line, the same choices and help, and node and command
must offer the same options apart from the exceptions listed here.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest
from ros_helpers.graph import node_parameters, node_process, stop

from shm_ros.core.bayes.update import UpdateConfig
from shm_ros.core.config import OptionSpec, nested_configs, option_specs
from shm_ros.core.identify import IdentifyConfig
from shm_ros.core.ingest import IngestConfig
from shm_ros.core.predict.event_calibration import EventCalibrationConfig
from shm_ros.core.tracking import TrackingConfig
from shm_ros.ros.identify_node import IdentifyNodeConfig
from shm_ros.ros.ingest_node import IngestNodeConfig
from shm_ros.ros.track_node import TrackNodeConfig
from shm_ros.ros.update_node import UpdateNodeConfig

ROOT = Path(__file__).resolve().parents[1]
# every rclpy node has the first two; every managed node of the project has autostart
ROS_OWN = {"use_sim_time", "start_type_description_service", "autostart"}
CLI_OWN = {"help", "overwrite"}  # every command writing outputs refuses a non-empty --out without --overwrite

# stage -> (core configuration, the node's own settings, node start parameters,
#           node-only parameters, command-only options, in both but required on the command line)
STAGES: dict[str, tuple[type, type, dict[str, Any], set[str], set[str], set[str]]] = {
    "ingest": (IngestConfig, IngestNodeConfig, {"structure": str(ROOT / "examples" / "building.yaml")},
               # live-graph settings: offline reading knows when a window is complete
               {"reliable_input", "idle_flush_s", "discovery_period_s", "discovery_timeout_s", "frame_id",
                "close_wait_s", "max_latency_s", "settle_s", "check_interval_s"},
               {"bag", "out", "no_samples", "quiet"},
               {"structure"}),
    "identify": (IdentifyConfig, IdentifyNodeConfig, {},
                 {"frame_id"},
                 # the recording, the files, and the window length of ingest (IngestConfig's)
                 {"bag", "out", "window", "plots", "config"},
                 {"structure"}),
    "track": (TrackingConfig, TrackNodeConfig, {"store": "none"},
              # the node trains on a number of windows, the command on a fraction of the campaign;
              # the node writes its store, the command exports a time range of one
              {"training_windows", "frame_id", "retention_days", "checkpoint_every"},
              {"modes", "out", "no_plot", "training_fraction", "t_from", "t_to"},
              set()),
    "update": (UpdateConfig, UpdateNodeConfig, {"structure": str(ROOT / "examples" / "building.yaml")},
               # the node chains the time-domain step on recorded events after each modal posterior;
               # (a graph's job: the command runs one updating)
               {"input", "min_windows", "min_new_windows", "output_dir", "calibration_windows",
                *(f"calibration.{s.name}" for s in option_specs(EventCalibrationConfig))},
               {"modes", "bag", "out", "study", "refer_to", "window", "no_plots"},
               {"structure"}),
}


# rcl_interfaces/msg/ParameterType
ROS_TYPE = {bool: 1, int: 2, float: 3, str: 4, list: 9}


def _specs(cls: type, prefix: str = "") -> dict[str, OptionSpec]:
    out = {prefix + s.name: s for s in option_specs(cls)}
    for field, sub in nested_configs(cls):
        out.update(_specs(sub, f"{prefix}{field}."))
    return out


def _node_parameters(kind: str, params: dict[str, Any]) -> dict[str, dict[str, Any]]:
    node = node_process(kind, params)
    try:
        found = node_parameters(kind)
    finally:
        code, log = stop(node)
    assert code == 0, log[-3000:]
    return found


def _command_options(command: str) -> dict[str, argparse.Action]:
    from shm_ros.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a for a in sub.choices[command]._actions if a.dest not in CLI_OWN}


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_node_command_and_core_agree_on_every_option(stage):
    core, own, start, node_only, cli_only, cli_required = STAGES[stage]
    specs = _specs(core)
    node_specs = _specs(own)
    ros = {n: p for n, p in _node_parameters(stage, start).items() if n not in ROS_OWN}
    cli = _command_options(stage)

    # the same options, apart from the listed exceptions (which must exist where they are listed)
    assert node_only <= set(ros) and not node_only & set(cli), node_only
    assert cli_only <= set(cli) and not cli_only & set(ros), cli_only
    assert set(ros) - node_only == set(cli) - cli_only, (
        sorted((set(ros) - node_only) ^ (set(cli) - cli_only)))
    # every parameter comes from a dataclass option; the core's are all offered where flagged
    assert set(ros) == {n for n, s in {**specs, **node_specs}.items() if s.ros}
    assert {n for n, s in specs.items() if s.cli} <= set(cli)

    for name, spec in {**specs, **node_specs}.items():
        if spec.ros:
            p = ros[name]
            started = start.get(name, spec.default)
            assert p["value"] == started, (name, p["value"], started)
            assert spec.help in p["description"], (name, p["description"])
            assert p["read_only"], name
            if spec.default is None:
                assert p["dynamic"], name
            else:
                assert not p["dynamic"] and p["type"] == ROS_TYPE[spec.value_type], (name, p["type"])
            if spec.choices:
                assert p["constraints"] == f"one of {'|'.join(spec.choices)}", (name, p["constraints"])
        if spec.cli and name in cli and name not in cli_required:
            action = cli[name]
            assert action.default == spec.default, (name, action.default, spec.default)
            assert "--" + name.replace("_", "-") in action.option_strings, (name, action.option_strings)
            assert (list(action.choices) if action.choices else None) == (
                list(spec.choices) if spec.choices else None), name
            assert action.help and spec.help in action.help.replace("%%", "%"), name
    for name in cli_required:
        assert cli[name].required and name in ros, name


def test_a_bad_choice_stops_the_node_naming_node_parameter_and_choices():
    node = node_process("identify", {"preprocess.detrend": "quadratic"})
    try:
        log, _ = node.communicate(timeout=120.0)  # it stops by itself
    finally:
        stop(node)
    assert node.returncode == 2, log
    assert "identify: parameter 'preprocess.detrend' must be one of none|constant|linear" in log, log
    assert "'quadratic'" in log


def test_command_options_override_a_configuration_file_only_when_given(tmp_path):
    from shm_ros.cli import build_parser
    from shm_ros.commands.identify import build_config

    cfg = tmp_path / "identify.yaml"
    cfg.write_text("method: ssi-data\nmax_order: 40\npreprocess: {lowpass_hz: 20.0}\n")
    base = ["identify", "bag", "--structure", "s.yaml", "--out", "m.json", "--config", str(cfg)]
    kept = build_config(build_parser().parse_args(base))
    assert (kept.method, kept.max_order, kept.preprocess.lowpass_hz) == ("ssi-data", 40, 20.0)
    assert kept.uncertainty is True and kept.preprocess.detrend == "linear"  # the defaults
    given = build_config(build_parser().parse_args(
        [*base, "--max-order", "30", "--no-uncertainty", "--lowpass", "25", "--references", "a,b"]))
    assert (given.method, given.max_order, given.uncertainty) == ("ssi-data", 30, False)
    assert given.preprocess.lowpass_hz == 25.0 and given.reference_channels == ["a", "b"]
