"""Managed (lifecycle) nodes: every pipeline node configures in the standard ``configure`` transition.

A node's ``setup()`` reads its parameters, loads its files and creates its publishers,
subscriptions and timers; it runs in ``on_configure``. A bad parameter or structure file
(:class:`~shm_ros.errors.ShmError`) fails the transition: the node stays *unconfigured*, logs the
reason and reports it on ``/diagnostics`` (``<node>: configure``, ERROR, naming the file and field);
nothing leaves its constructor as ``SystemExit``. ``activate`` lets data in (subscriptions and
timers only call the node while it is active), ``deactivate`` stops it, ``cleanup`` destroys
everything ``setup()`` made (and calls ``teardown()``: stores closed, worker processes stopped), so
a later ``configure`` starts afresh with the files as they are then.

The standard services (``<node>/change_state``, ``<node>/get_state``, ... of ``lifecycle_msgs``)
let a lifecycle manager drive the transitions. With the parameter ``autostart`` (default true) the
node configures and activates itself when it is made, as an unmanaged node would; a manager sets
``autostart:=false``.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from shm_ros.errors import ShmError
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides


class ManagedNode(LifecycleNode):
    """Base of the pipeline's nodes: subclasses set ``kind`` and implement ``setup()``."""

    kind = "node"

    def __init__(self, name: str | None = None, parameters: dict[str, Any] | None = None,
                 namespace: str = "") -> None:
        self.active = False
        self.configured = False
        self.config_error = ""
        self._owning = False
        self._owned: list[tuple[str, Any]] = []
        super().__init__(name or self.kind, namespace=namespace or "", parameter_overrides=overrides(parameters))
        self.autostart = bool(self.declare_parameter(
            "autostart", True, ParameterDescriptor(
                description="configure and activate at start (false: wait for a lifecycle manager's "
                "transitions through the lifecycle_msgs services)", read_only=True)).value)
        self.diag = Diagnostics(self, self.kind)
        if self.autostart:
            self.start()

    # -- what a node defines ----------------------------------------------------------------------
    def setup(self) -> None:
        """Read parameters, load files, create publishers, subscriptions and timers."""

    def teardown(self) -> None:
        """Release what ``setup()`` holds besides ROS entities (stores, worker processes)."""

    # -- bring-up without a manager ----------------------------------------------------------------
    def start(self) -> bool:
        """``configure`` then ``activate``; False (the reason in ``config_error``) when it failed."""
        if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
            return False
        return self.trigger_activate() == TransitionCallbackReturn.SUCCESS

    # -- transitions -------------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.config_error = ""
        self._owning = True
        try:
            self.setup()
        except Exception as exc:  # the transition fails with the reason; the node stays up
            text = str(exc) if isinstance(exc, ShmError | OSError | ValueError) else f"configure failed: {exc!r}"
            if not isinstance(exc, ShmError | OSError | ValueError):
                self.get_logger().error(traceback.format_exc())
            self.config_error = text if text.startswith(f"{self.get_name()}:") else f"{self.get_name()}: {text}"
            self._release()
            self.diag.report("error", self.config_error, "configure")
            self.diag.publish()
            return TransitionCallbackReturn.FAILURE
        self.configured = True
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        self.active = False
        if self.configured:
            self.teardown()
        self.configured = False
        self._owning = False
        owned, self._owned = self._owned, []
        for kind, entity in reversed(owned):
            getattr(self, f"destroy_{kind}")(entity)

    def destroy_node(self) -> None:
        if self.configured:
            self.teardown()
            self.configured = False
        super().destroy_node()

    # -- entities made while configured belong to the configuration ---------------------------------
    def _own(self, kind: str, entity: Any) -> Any:
        if getattr(self, "_owning", False):
            self._owned.append((kind, entity))
        return entity

    def _gate(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        if not getattr(self, "_owning", False):
            return callback

        def gated(*args: Any) -> Any:
            return callback(*args) if self.active else None
        return gated

    def create_publisher(self, *args: Any, **kwargs: Any) -> Any:
        return self._own("publisher", super().create_publisher(*args, **kwargs))

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[..., Any], *args: Any,
                            **kwargs: Any) -> Any:
        return self._own("subscription",
                         super().create_subscription(msg_type, topic, self._gate(callback), *args, **kwargs))

    def create_timer(self, timer_period_sec: float, callback: Any, *args: Any, **kwargs: Any) -> Any:
        if getattr(self, "_owning", False):
            plain = callback

            def callback() -> Any:  # no arguments: rclpy passes a TimerInfo to callbacks that take one
                return plain() if self.active else None
        return self._own("timer", super().create_timer(timer_period_sec, callback, *args, **kwargs))
