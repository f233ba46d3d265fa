"""A lifecycle manager's side: drive managed nodes through the standard ``lifecycle_msgs`` services.

What a robot's or plant's lifecycle manager (or ``ros2 lifecycle set``) does, for machines without
the ``ros2`` command line and for ``shm-ros lifecycle``: each node offers ``<node>/change_state``
and ``<node>/get_state``; :func:`bring_up` configures then activates a list of nodes in order (the
pipeline's order: ingest first), :func:`bring_down` deactivates and cleans them up in reverse order.
A failed ``configure`` leaves the node unconfigured; its reason is on ``/diagnostics`` and in its log.
"""

from __future__ import annotations

import time
from typing import Any

import rclpy
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.node import Node

from shm_ros.errors import ShmError

#: transition names (as ``ros2 lifecycle set`` spells them) and their ids
TRANSITIONS = {"configure": Transition.TRANSITION_CONFIGURE, "activate": Transition.TRANSITION_ACTIVATE,
               "deactivate": Transition.TRANSITION_DEACTIVATE, "cleanup": Transition.TRANSITION_CLEANUP}
_SHUTDOWN = {State.PRIMARY_STATE_UNCONFIGURED: Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,
             State.PRIMARY_STATE_INACTIVE: Transition.TRANSITION_INACTIVE_SHUTDOWN,
             State.PRIMARY_STATE_ACTIVE: Transition.TRANSITION_ACTIVE_SHUTDOWN}


_GOALS = {"configure": "inactive", "activate": "active", "deactivate": "inactive", "cleanup": "unconfigured",
          "shutdown": "finalized"}


class LifecycleError(ShmError, RuntimeError):
    """A managed node did not answer, or refused a transition; the message names the node."""


class LifecycleClient:
    """The lifecycle services of one managed node (``target``: its fully qualified name, ``/a/ingest``)."""

    def __init__(self, node: Node, target: str) -> None:
        self.node, self.target = node, target
        self._change: Any = node.create_client(ChangeState, f"{target}/change_state")
        self._get: Any = node.create_client(GetState, f"{target}/get_state")

    def _call(self, client: Any, request: Any, timeout_s: float, resend_s: float = 2.0) -> Any:
        """The answer to ``request``, sent again every ``resend_s`` (a request sent just after the
        service was discovered can be lost: the server had not matched the client's reader yet)."""
        end = time.monotonic() + timeout_s
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise LifecycleError(f"{self.target}: no lifecycle service {client.srv_name} (is the node running?)")
        while time.monotonic() < end:
            future = client.call_async(request)
            rclpy.spin_until_future_complete(self.node, future, timeout_sec=min(resend_s, end - time.monotonic()))
            if future.done() and future.result() is not None:
                return future.result()
            client.remove_pending_request(future)
        raise LifecycleError(f"{self.target}: {client.srv_name} did not answer within {timeout_s:g} s")

    def state(self, timeout_s: float = 10.0) -> str:
        """The node's primary state: ``unconfigured``, ``inactive``, ``active`` or ``finalized``."""
        return str(self._call(self._get, GetState.Request(), timeout_s).current_state.label)

    def transition(self, name: str, timeout_s: float = 60.0) -> bool:
        """Request ``name`` (configure, activate, deactivate, cleanup, shutdown); True when it succeeded."""
        current = self._call(self._get, GetState.Request(), timeout_s).current_state
        if name == "shutdown":
            transition_id = _SHUTDOWN.get(current.id)
            if transition_id is None:
                return False
        elif name in TRANSITIONS:
            transition_id = TRANSITIONS[name]
        else:
            raise LifecycleError(f"unknown transition {name!r} (one of {', '.join([*TRANSITIONS, 'shutdown'])})")
        request = ChangeState.Request(transition=Transition(id=transition_id))
        end = time.monotonic() + timeout_s
        future = self._change.call_async(request)
        while time.monotonic() < end:
            rclpy.spin_until_future_complete(self.node, future, timeout_sec=2.0)
            if future.done() and future.result() is not None:
                return bool(future.result().success)
            # no answer yet: a transition still running, or a request (or its answer) lost
            now = self._call(self._get, GetState.Request(), max(end - time.monotonic(), 1.0)).current_state
            if now.label == _GOALS.get(name):
                return True
            if now.id == current.id:  # nothing happened: send it again
                self._change.remove_pending_request(future)
                future = self._change.call_async(request)
        raise LifecycleError(f"{self.target}: {name} did not complete within {timeout_s:g} s")


def _drive(node: Node, targets: list[str], steps: tuple[str, ...]) -> None:
    for target in targets:
        client = LifecycleClient(node, target)
        for step in steps:
            if not client.transition(step):
                raise LifecycleError(f"{target}: transition {step} failed (state {client.state()}); "
                                     "the reason is on /diagnostics and in the node's log")


def bring_up(node: Node, targets: list[str]) -> None:
    """configure + activate every node of ``targets`` in order; LifecycleError at the first refusal."""
    _drive(node, targets, ("configure", "activate"))


def bring_down(node: Node, targets: list[str]) -> None:
    """deactivate + cleanup every node of ``targets`` in reverse order."""
    _drive(node, list(reversed(targets)), ("deactivate", "cleanup"))
