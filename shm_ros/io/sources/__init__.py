"""Bag back ends: each reads one kind of bag into raw CDR messages by topic (see :mod:`.base`);
:func:`open_source` picks the one for a bag."""

from shm_ros.io.sources.base import Batch, MessageSource, TopicMessages
from shm_ros.io.sources.choose import open_source

__all__ = ["Batch", "MessageSource", "TopicMessages", "open_source"]
