"""recorder: writes pipeline topics (CDR as received) into an output bag, under their fully
qualified names (the node's namespace resolves the relative ones)."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from shm_ros.core.config import option
from shm_ros.io.bags import BagWriter
from shm_ros.ros import topics
from shm_ros.ros.managed import ManagedNode
from shm_ros.ros.node_main import spin
from shm_ros.ros.params import load_config
from shm_ros.ros.qos import latched_qos, pipeline_qos, stream_qos

DEFAULT_TOPICS = [topics.WINDOWS, topics.MODAL_ESTIMATES, topics.TRACKED_MODES, topics.POSTERIOR,
                  topics.PREDICTION, topics.VERDICT, topics.DIAGNOSTICS]
LATCHED = {topics.POSTERIOR, topics.VERDICT}
STREAMS = {topics.WINDOWS, topics.MODAL_ESTIMATES, topics.TRACKED_MODES}


class Storage(enum.StrEnum):
    MCAP = "mcap"  # what `ros2 bag record` writes
    SQLITE3 = "sqlite3"


@dataclass
class RecorderNodeConfig:
    output: str = option("shm_output_bag", "output bag directory")
    topics: list[str] = option(DEFAULT_TOPICS, "topics to record (pipeline topics of known type)")
    storage: str = option(Storage.MCAP.value, "bag storage", choices=Storage)


class RecorderNode(ManagedNode):
    """Parameters: the options of :class:`RecorderNodeConfig`."""

    kind = "recorder"

    def setup(self) -> None:
        settings = load_config(self, RecorderNodeConfig)
        out = Path(settings.output)
        self.writer = BagWriter(out, storage=settings.storage)
        self.writer.__enter__()
        self.count = 0
        self.diag.summarize(lambda: (
            "ok", f"{self.count} messages recorded to {out}", {"messages": self.count, "output": out}))
        for topic in settings.topics:
            msgtype = topics.type_of(topic)
            if msgtype is None:
                self.get_logger().error(f"parameter topics: no known type for {topic!r}; not recorded")
                continue
            name = topics.relative(topic)
            qos = (latched_qos() if name in LATCHED else
                   stream_qos() if name in STREAMS else pipeline_qos())
            # the bag holds the fully qualified name (/bridge_a/shm/windows), as `ros2 bag record` writes it
            self.create_subscription(topics.message_class(msgtype), topic,
                                     self._writer_for(self.resolve_topic_name(topic), msgtype), qos, raw=True)
        self.get_logger().info(f"recording to {out}")

    def _writer_for(self, topic: str, msgtype: str):
        def write(data: bytes) -> None:
            self.writer.write_cdr(topic, msgtype, self.get_clock().now().nanoseconds, data)
            self.count += 1
        return write

    def teardown(self) -> None:
        """Close the bag (shutdown, cleanup): what was recorded stays readable."""
        self.writer.__exit__(None, None, None)
        self.get_logger().info(f"recorded {self.count} messages")


def make_node(name: str, parameters: dict[str, Any], namespace: str = "") -> RecorderNode:
    return RecorderNode(name, parameters, namespace)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: RecorderNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
