"""Errors of reading and writing outside formats; each message names the file and what is wrong."""

from __future__ import annotations

from shm_ros.errors import ShmError


class BagError(ShmError, RuntimeError):
    """A bag cannot be read or written; the message names the bag and what is wrong."""
