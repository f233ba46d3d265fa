"""`shm-ros lifecycle ACTION NODE...`: drive managed nodes through the lifecycle_msgs services.

What `ros2 lifecycle set` and a lifecycle manager do, for machines without the `ros2` command line:
``up`` (configure + activate, in the order given: the pipeline's, ingest first), ``down`` (deactivate
+ cleanup, in reverse order), one transition (configure, activate, deactivate, cleanup, shutdown)
or ``state``. NODE is a node's fully qualified name (``/bridge_a/ingest``) or a name under
``--namespace``. Exit code 2 (the node and the transition named) when a node refuses; the reason of
a failed configure is on ``/diagnostics`` and in the node's log.
"""

from __future__ import annotations

import argparse

ACTIONS = ("up", "down", "configure", "activate", "deactivate", "cleanup", "shutdown", "state")


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import positive_float

    p = sub.add_parser("lifecycle", help="bring managed nodes up or down (lifecycle_msgs services)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("action", choices=ACTIONS)
    p.add_argument("nodes", nargs="+", metavar="NODE", help="node names (e.g. ingest identify, or /bridge_a/ingest)")
    p.add_argument("--namespace", default="", metavar="NS", help="namespace of relative node names (e.g. /bridge_a)")
    p.add_argument("--timeout", type=positive_float, default=60.0, help="seconds to wait for each service (default 60)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import rclpy

    from shm_ros.ros.graph_config import normal_namespace
    from shm_ros.ros.lifecycle import LifecycleClient, LifecycleError, bring_down, bring_up

    ns = normal_namespace(args.namespace)
    targets = [n if n.startswith("/") else f"{ns}/{n}" for n in args.nodes]
    rclpy.init()
    node = rclpy.create_node("shm_lifecycle")
    try:
        if args.action == "up":
            bring_up(node, targets)
        elif args.action == "down":
            bring_down(node, targets)
        for target in targets:
            client = LifecycleClient(node, target)
            if args.action not in ("up", "down", "state") and not client.transition(args.action, args.timeout):
                raise LifecycleError(f"{target}: transition {args.action} failed (state {client.state()})")
            print(f"{target}: {client.state(args.timeout)}")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
