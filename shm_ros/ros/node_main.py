"""How every node process starts and stops: init, spin, clean exit 0 on Ctrl-C / SIGINT."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.parameter import Parameter


def overrides(parameters: dict[str, Any] | None) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in (parameters or {}).items()]


def spin(factory: Callable[[], Any], args: list[str] | None = None) -> int:
    """Run one node until shutdown. Callbacks run in a single-threaded executor (the
    multi-threaded one is far slower for data topics)."""
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    rclpy.init(args=sys.argv if args is None else args)
    node = None
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
