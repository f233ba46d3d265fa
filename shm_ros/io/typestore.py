"""The rosbags typestore of the pipeline: the ROS distribution's types plus ``shm_interfaces``.

The ``.msg`` texts are read from the installed interface package (``share/shm_interfaces/msg`` in
the ament index) or, in a source checkout without a build, from ``msg_defs/msg``. Both hold the same
files, so bags written here read in ``ros2 bag`` and vice versa.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

from shm_ros.errors import ShmError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

PACKAGE = "shm_interfaces"
SOURCE_MSG_DIR = Path(__file__).resolve().parents[2] / "msg_defs" / "msg"


class InterfaceError(ShmError, RuntimeError):
    """The project's interface definitions cannot be found."""


def distribution() -> str:
    """The ROS 2 distribution whose standard types are used: ``$ROS_DISTRO``, else Kilted."""
    return (os.environ.get("ROS_DISTRO") or "kilted").lower()


def msg_dir() -> Path:
    """Directory holding the ``.msg`` files of ``shm_interfaces``."""
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) + [_venv_prefix()]:
        if prefix:
            candidate = Path(prefix) / "share" / PACKAGE / "msg"
            if candidate.is_dir():
                return candidate
    if SOURCE_MSG_DIR.is_dir():
        return SOURCE_MSG_DIR
    raise InterfaceError(
        f"cannot find the {PACKAGE} .msg files: build msg_defs/ (./dev setup) or set AMENT_PREFIX_PATH"
    )


def _venv_prefix() -> str:
    import sys

    return sys.prefix


def message_definitions() -> dict[str, str]:
    """``{"shm_interfaces/msg/Name": msg_text}`` for every project message."""
    return {
        f"{PACKAGE}/msg/{path.stem}": path.read_text()
        for path in sorted(msg_dir().glob("*.msg"))
    }


@cache
def typestore() -> Typestore:
    """The typestore of the current distribution with the project's messages registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    name = f"ROS2_{distribution().upper()}"
    store = get_typestore(getattr(Stores, name, Stores.ROS2_KILTED))
    types: dict = {}
    for msgtype, text in message_definitions().items():
        types.update(get_types_from_msg(text, msgtype))
    store.register(types)
    return store
