"""`shm-ros replay BAG`: publish a recording through the running node graph.

Exit status: 0 when the graph acknowledged every message; 1 when messages were lost, when the
ingest node restarted during the replay (what the process that died held is lost; the replay goes on
with the new one) or when the replay was stopped by SIGINT or SIGTERM before the end of the bag (what
was sent is still drained); 2 when the bag cannot be read
(a truncated MCAP is replayed up to where it ends, then reported) or the ingest node stopped
acknowledging.
"""

from __future__ import annotations

import argparse
import sys


def add_parser(sub: argparse._SubParsersAction) -> None:
    from shm_ros.commands.checks import nonneg_float, nonneg_int, positive_int

    p = sub.add_parser("replay", help="publish a bag through the running graph (flow-controlled)",
                       description=__doc__)
    p.add_argument("bag", help="rosbag2 folder (MCAP or sqlite3)")
    p.add_argument("--rate", type=nonneg_float, default=0.0,
                   help="1 = real time, N = N x real time, 0 = as fast as the graph keeps up (default)")
    p.add_argument("--credit", type=positive_int, default=256,
                   help="messages in flight at most when flow-controlled (default 256; the shared-memory "
                        "transport queues 512 per reader)")
    p.add_argument("--credit-bytes", type=positive_int, default=192 * 1024,
                   help="bytes in flight at most when flow-controlled (default 192 KiB)")
    p.add_argument("--all-topics", action="store_true",
                   help="also replay topics that are not recording topics")
    p.add_argument("--wait", type=nonneg_float, default=15.0, help="seconds to wait for the graph")
    p.add_argument("--clock", type=nonneg_float, nargs="?", const=40.0, default=0.0, metavar="HZ",
                   help="publish /clock with the recording's time (every 1/HZ s of it, default 40), for "
                        "nodes started with use_sim_time:=true, as `ros2 bag play --clock` does")
    p.add_argument("--clock-readers", type=nonneg_int, default=0, metavar="N",
                   help="with --clock, wait (up to --wait s) until N nodes on sim time read /clock before "
                        "replaying (default: those found once the graph has been stable for 1 s)")
    p.add_argument("--namespace", default="", metavar="NS",
                   help="the graph's namespace (e.g. /bridge_a, as its nodes' __ns): the recording's topics "
                        "and the flow control go under it (default: the root)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from shm_ros.commands.checks import input_path

    input_path(args.bag, "BAG")
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from shm_ros.ros.node_main import StopSignals
    from shm_ros.ros.replay import replay_bag

    with StopSignals(restore=False) as stop:
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        try:
            result = replay_bag(args.bag, rate=args.rate, credit=args.credit, credit_bytes=args.credit_bytes,
                                wait_s=args.wait,
                                recording_only=not args.all_topics, progress=True, clock_hz=args.clock,
                                clock_readers=args.clock_readers, namespace=args.namespace,
                                stop=lambda: stop.stopping)
        finally:
            rclpy.try_shutdown()
        return _report(result)  # a signal from here on is too late to stop anything: noted, ignored


def _report(result) -> int:
    for topic, why in sorted(result.skipped_topics.items()):
        print(f"skipped {topic}: {why}")
    speed = result.bag_span_s / result.wall_s if result.wall_s > 0 else float("inf")
    print(f"replayed {result.published} messages in {result.wall_s:.1f} s "
          f"({speed:.1f}x real time); acknowledged {result.acknowledged}, lost {result.lost}")
    if result.ingest_restarts:
        print(f"shm-ros replay: the ingest node restarted {result.ingest_restarts} time(s) during the replay: "
              "what the process that died held (samples not yet in a published window) is lost", file=sys.stderr)
        return 1
    if result.stopped:
        print(f"shm-ros replay: stopped by a signal after {result.published} messages; the rest of the bag "
              "was not replayed", file=sys.stderr)
        return 1
    if result.error:
        print(f"shm-ros replay: {result.error} (replayed the {result.published} messages read "
              "before it)", file=sys.stderr)
        return 2
    return 1 if result.lost else 0
