"""How modes move within one earthquake record: moving-window identification, strong-motion
interval, pre-event / strong-motion / post-event estimates (no ROS)."""

from shm_ros.core.event_analysis.analyse import analyse_event, running_median
from shm_ros.core.event_analysis.arias import arias_intensity, significant_interval
from shm_ros.core.event_analysis.config import EventConfig, IntensitySource
from shm_ros.core.event_analysis.results import EventResult, ModeTrack, PhaseEstimate, PhaseMode, StrongMotion

__all__ = ["analyse_event", "running_median", "arias_intensity", "significant_interval", "EventConfig",
           "IntensitySource", "EventResult", "ModeTrack", "PhaseEstimate", "PhaseMode", "StrongMotion"]
