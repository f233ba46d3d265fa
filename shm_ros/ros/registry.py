"""The one list of the pipeline's nodes.

Everything that names the nodes reads it: the console scripts (``setup.py``, one ``shm-ros-<kind>``
per node, installed into ``lib/shm_ros`` in a ROS workspace, where ``ros2 run`` and the launch file
look), the launch file (``launch/pipeline.launch.py``), the supervisor behind ``shm-ros run``
(:mod:`shm_ros.ros.graph_config`) and the node table of ``docs/parameters.md``
(:mod:`shm_ros.ros.params_doc`). A new node is a ``<kind>_node.py`` module with ``main`` and
``make_node`` plus one entry here.

This module imports nothing but the standard library: ``setup.py`` loads it before the package's
dependencies are installed.
"""

from __future__ import annotations

from dataclasses import dataclass

PACKAGE = "shm_ros"
#: seconds a respawned node waits before it starts again (launch's ``respawn_delay``, the supervisor's)
RESPAWN_DELAY_S = 2.0


@dataclass(frozen=True)
class NodeKind:
    """One kind of node: the module that holds it and what it does."""

    kind: str
    summary: str
    #: configuration dataclasses whose options are the node's parameters, as ``module:Class``
    configs: tuple[str, ...]
    respawn: bool = True
    #: part of the shipped graph (config/pipeline.yaml); False: started where a graph file names it
    default: bool = True
    #: a restarted node takes up what the dead one held from its inputs' history (transient-local
    #: topics, its store) within their depth; False: what it held is lost when it dies (ingest: the
    #: samples of the windows it was filling; roving: the robot's plan)
    recovers: bool = True

    @property
    def module(self) -> str:
        return f"shm_ros.ros.{self.kind}_node"

    @property
    def executable(self) -> str:
        """The console script (pip's ``bin/``, a ROS workspace's ``lib/shm_ros``)."""
        return f"shm-ros-{self.kind}"

    @property
    def entry_point(self) -> str:
        return f"{self.executable} = {self.module}:main"


NODES: tuple[NodeKind, ...] = (
    NodeKind("ingest", "recording topics in, validated and aligned windows out",
             ("shm_ros.ros.ingest_node:IngestNodeConfig", "shm_ros.core.ingest:IngestConfig"), recovers=False),
    NodeKind("identify", "windows in, modal estimates out",
             ("shm_ros.ros.identify_node:IdentifyNodeConfig", "shm_ros.core.identify:IdentifyConfig")),
    NodeKind("track", "modal estimates in, tracked modes and novelty out",
             ("shm_ros.ros.track_node:TrackNodeConfig", "shm_ros.core.tracking:TrackingConfig")),
    NodeKind("update", "tracked modes (or modal estimates) in, posterior out (sampling in a worker process)",
             ("shm_ros.ros.update_node:UpdateNodeConfig", "shm_ros.core.bayes.update:UpdateConfig")),
    NodeKind("predict", "event windows in, response predictions out (a worker process)",
             ("shm_ros.ros.predict_node:PredictNodeConfig", "shm_ros.core.predict:PredictConfig")),
    NodeKind("explain", "tracked modes (and event windows) in, verdicts on missing physics out (a worker process)",
             ("shm_ros.ros.explain_node:ExplainNodeConfig", "shm_ros.core.explain.config:ExplainConfig")),
    NodeKind("recorder", "pipeline topics into a bag", ("shm_ros.ros.recorder_node:RecorderNodeConfig",)),
    NodeKind("roving", "roving sensors and tf in, advice to the robot (RecordPoint action) and global modes out "
             "(for a structure with roving sensors; not in the shipped graph)",
             ("shm_ros.ros.roving_node:RovingNodeConfig",), default=False, recovers=False),
)
KINDS: tuple[str, ...] = tuple(n.kind for n in NODES)
DEFAULT_KINDS: tuple[str, ...] = tuple(n.kind for n in NODES if n.default)


def node_kind(kind: str) -> NodeKind:
    """The registry entry of ``kind``; KeyError when there is none."""
    for entry in NODES:
        if entry.kind == kind:
            return entry
    raise KeyError(kind)


def entry_points() -> list[str]:
    """``console_scripts`` of setup.py: the command line and one script per node."""
    return ["shm-ros = shm_ros.cli:main"] + [n.entry_point for n in NODES]


def node_table() -> list[str]:
    """The node table of the docs (Markdown rows)."""
    rows = ["| node | what it does | executable | respawned | module |", "|---|---|---|---|---|"]
    for n in NODES:
        rows.append(f"| `{n.kind}` | {n.summary} | `{n.executable}` | {'yes' if n.respawn else 'no'} | "
                    f"`{n.module}` |")
    return rows
