"""The time-domain calibration on recorded events, the modal posterior as prior.

A monitoring system has, before a later earthquake, the modal posterior of its ambient windows and
the records of the earthquakes it has seen. Those records calibrate in the time domain, where the
input is measured: likelihood ``time``, each event its own error variance, the prior per parameter a
normal of the modal posterior's mean and standard deviation
(:func:`~shm_ros.core.bayes.modal_prior.modal_priors`). The records are prepared as the prediction
prepares them (:func:`~shm_ros.core.predict.signals.prepare`: baseline from the pre-event part), so the
posterior, the events and the model error the prediction learns from them agree. The update node
runs it (``calibration_windows``, docs/parameters.md); the prediction then uses this posterior and
not the modal one, whose information it already holds through the prior.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from shm_ros.core.bayes.modal_prior import modal_priors
from shm_ros.core.bayes.records import RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.bayes.update import Posterior, UpdateConfig, update
from shm_ros.core.config import option
from shm_ros.core.models import AffineModel
from shm_ros.core.structure import StructureSpec
from shm_ros.core.types import Window

from .config import PredictConfig
from .record import event_from_window
from .signals import prepare


@dataclass
class EventCalibrationConfig:
    """The time-domain step's sampler (the update node's ``calibration.*`` parameters)."""

    n_chains: int = option(8, "walkers / chains")
    n_steps: int = option(150, "first run length before the diagnostics are checked")
    max_steps: int = option(150, "upper bound on steps")
    ess_target: float = option(50.0, "effective sample size target per parameter")
    rhat_target: float = option(1.2, "R-hat target")
    residual_ar_order: int = option(0, "order of the autoregressive model of the residuals (0: white)")
    variance_per_event: bool = option(True, "each event its own error variance")
    seed: int = option(0, "random seed")

    def update_config(self) -> UpdateConfig:
        """The updating's settings: likelihood ``time``, no evidence (a posterior, not a model choice)."""
        return UpdateConfig(likelihood="time", evidence=False, **asdict(self))


def event_records(windows: Sequence[Window], model: AffineModel) -> RecordSet:
    """The events' input and output records, baseline-corrected as the prediction does."""
    cfg = PredictConfig()
    recs = []
    for w in windows:
        ev = event_from_window(w, model)
        u, y, _ = prepare(ev, cfg)
        recs.append(AccelerationRecord(1.0 / ev.fs, u, y, ev.channel_ids))
    return RecordSet(recs)


def calibrate_on_events(model: AffineModel, spec: StructureSpec, windows: Sequence[Window],
                        modal: Mapping[str, Mapping[str, Any]], config: EventCalibrationConfig) -> Posterior:
    """The time-domain posterior of the events ``windows``, the modal posterior ``modal``
    (``{name: {"mean", "std"}}``) as the prior."""
    return update(model, event_records(windows, model), config.update_config(), modal_priors(spec, modal))
