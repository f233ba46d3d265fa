"""`shm-ros run CONFIG.yaml`: start the node graph (one process per node, or all in one).

It starts what `ros2 launch shm_ros pipeline.launch.py params_file:=CONFIG.yaml` starts: the same
nodes, executables, parameters and respawn policy (docs/deployment.md). Every node is a managed
(lifecycle) node that configures and activates itself; `--no-autostart` leaves them unconfigured for
a lifecycle manager. `--namespace /bridge_a` puts the whole graph (nodes, topics, services) under
that namespace, so several structures can share one ROS domain."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="start the node graph from a YAML config", description=__doc__)
    p.add_argument("config", help="ROS 2 parameters file naming the nodes (see config/pipeline.yaml)")
    p.add_argument("--single-process", action="store_true",
                   help="run every node in this process (default: one process per node)")
    p.add_argument("--no-restart", action="store_true", help="do not restart a node that exits")
    p.add_argument("--namespace", default=None, metavar="NS",
                   help="namespace of every node, topic and service of the graph (e.g. /bridge_a; default: the root)")
    p.add_argument("--no-autostart", action="store_true",
                   help="leave every node unconfigured: a lifecycle manager brings them up through the "
                        "lifecycle_msgs services")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_file
    from shm_ros.ros.supervisor import Supervisor, load_graph_config, run_single_process

    input_file(args.config, "CONFIG")
    config = load_graph_config(args.config, mode="single" if args.single_process else None,
                               restart=False if args.no_restart else None, namespace=args.namespace)
    if config.mode == "single":
        return run_single_process(config, autostart=not args.no_autostart)
    return Supervisor(config, log=lambda s: print(s, flush=True), autostart=not args.no_autostart).run()
