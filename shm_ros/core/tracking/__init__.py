"""Mode identities across many windows, their environmental dependence, and novelty.

``track(estimates, TrackingConfig())`` (a whole campaign) and ``Tracker(config).add(estimate)``
(one window at a time, the ``track`` node) turn per-window modal estimates (modes unnumbered,
spurious ones possible, true ones sometimes missing, channels coming and going) into the
tracked-modes table of docs/interfaces.md §4. One concept per module:

- :mod:`.reference` - the tracked mode set (first windows, FE model, or both);
- :mod:`.assign` - identity by shape first (MAC-led optimal assignment, relative frequency gate);
- :mod:`.environment` - regression on covariates with a freezing knee, or PCA without covariates;
- :mod:`.novelty` - EWMA control chart on the normalised frequencies (and damping);
- :mod:`.online` - the tracker; :mod:`.batch` - the tracker over a campaign.

docs/tracking.md describes the method and what the tests show.
"""

from shm_ros.core.tracking.batch import TrackingResult, rows_to_result, track
from shm_ros.core.tracking.config import EnvModel, ReferenceSource, TrackingConfig
from shm_ros.core.tracking.environment import EnvironmentalFit
from shm_ros.core.tracking.novelty import NoveltyChart, alarm_episodes
from shm_ros.core.tracking.online import MIN_TRAINING, TrackedRow, Tracker
from shm_ros.core.tracking.reference import ReferenceMode

__all__ = ["TrackingConfig", "ReferenceSource", "EnvModel", "ReferenceMode", "EnvironmentalFit",
           "TrackingResult", "track", "rows_to_result", "Tracker", "TrackedRow", "NoveltyChart",
           "alarm_episodes", "MIN_TRAINING"]
