"""Housekeeping timers on the steady clock.

Discovery, acknowledgements, heartbeats and worker polling are about the process, not the data:
they must run under ``use_sim_time:=true`` too, where the node's ROS clock stands still until
``/clock`` arrives (and ``shm-ros replay --clock`` only publishes it once the graph is ready).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node


def steady_timer(node: Node, period_s: float, callback: Callable[[], Any]) -> Any:
    return node.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))
