"""From raw accelerometer samples to analysis windows: validation, alignment, windowing, events.

The package's modules, each readable on its own:

=================  ============================================================================
``config``         :class:`IngestConfig` (every setting with its default and help)
``channels``       :class:`ChannelMap` (which input feeds which window column),
                   :func:`channel_mismatches` (sensors without input, inputs without sensor)
``units``          declared unit strings -> m/s^2, hints when the data look like another unit
``buffers``        per-channel sample buffers
``grid``           the common sample grid: rate estimate, snapping, following a drifting clock
``segment``        bursts and windows: where the stream is cut
``span``           placing one span's samples on the grid and splitting it at gaps
``quality``        per-channel checks: NaN, dead, clipped, spikes, noisy
``events``         STA/LTA and PGA event detection
``window``         a piece of the grid -> a checked :class:`~shm_ros.core.types.Window`
``diagnostics``    the repeat-limited record of diagnostics
``results``        dropped spans, counters, the plain per-window summary
``core``           :class:`IngestCore`, the facade the node and the bag reader feed
=================  ============================================================================

The rules (time grid, windows, fault policy) are written out in ``docs/ingest.md``.
"""

from shm_ros.core.diagnostics import Diagnostic, Level
from shm_ros.core.ingest.channels import AXES, ChannelMap, ChannelSource, channel_mismatches, topic_id
from shm_ros.core.ingest.config import EventDetector, IngestConfig
from shm_ros.core.ingest.core import IngestCore
from shm_ros.core.ingest.events import detect_event, sta_lta
from shm_ros.core.ingest.grid import estimate_rate
from shm_ros.core.ingest.results import DroppedSpan, IngestStats, windows_summary
from shm_ros.core.ingest.units import UNIT_FACTORS, G, unit_factor

__all__ = [
    "AXES", "G", "UNIT_FACTORS", "ChannelMap", "ChannelSource", "Diagnostic", "DroppedSpan", "EventDetector",
    "IngestConfig", "IngestCore", "IngestStats", "Level", "channel_mismatches", "detect_event", "estimate_rate",
    "sta_lta", "topic_id", "unit_factor", "windows_summary",
]
