"""``schema_version`` and ``provenance`` carried by every JSON output (docs/interfaces.md §3)."""

from __future__ import annotations

import platform
import sys
from datetime import datetime, timezone
from typing import Any

SCHEMA_VERSION = "1.0"


def provenance(config: dict[str, Any] | None = None, seed: int | None = None,
               argv: list[str] | None = None) -> dict[str, Any]:
    from shm_ros import __version__

    return {
        "package": "shm_ros",
        "version": __version__,
        "command_line": list(sys.argv if argv is None else argv),
        "configuration": config or {},
        "random_seed": seed,
        "python": platform.python_version(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds").replace("+00:00", "Z"),
    }


def stamp_output(payload: dict[str, Any], config: dict[str, Any] | None = None,
                 seed: int | None = None) -> dict[str, Any]:
    """A copy of ``payload`` with ``schema_version`` and ``provenance`` first."""
    return {"schema_version": SCHEMA_VERSION, "provenance": provenance(config, seed), **payload}
