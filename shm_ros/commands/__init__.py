"""Subcommands of ``shm-ros``, one module each with ``add_parser(subparsers)``.

Each module's parser sets ``func`` (called with the parsed namespace, returns an exit code). Offline
commands call ``shm_ros.core`` directly; live ones start the nodes of ``shm_ros.ros``.
"""

# Order is the order of ``shm-ros --help``; data flows top to bottom.
COMMANDS = [
    "example",
    "simulate",
    "import_",
    "replay",
    "run",
    "lifecycle",
    "ingest",
    "identify",
    "event",
    "track",
    "update",
    "batch",
    "predict",
    "explain",
    "report",
]
