"""`shm-ros run CONFIG.yaml`: start the node graph (one process per node, or all in one)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="start the node graph from a YAML config", description=__doc__)
    p.add_argument("config", help="ROS 2 parameters file naming the nodes (see config/pipeline.yaml)")
    p.add_argument("--single-process", action="store_true",
                   help="run every node in this process (default: one process per node)")
    p.add_argument("--no-restart", action="store_true", help="do not restart a node that exits")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_file
    from shm_ros.ros.supervisor import Supervisor, load_graph_config, run_single_process

    input_file(args.config, "CONFIG")
    config = load_graph_config(args.config, mode="single" if args.single_process else None,
                               restart=False if args.no_restart else None)
    if config.mode == "single":
        return run_single_process(config)
    return Supervisor(config, log=lambda s: print(s, flush=True)).run()
