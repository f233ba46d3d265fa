"""The two jobs of a batch: one bag (ingest -> identify), one structure (track -> update).

Module-level functions of picklable arguments, so that any engine can run them; each limits BLAS to
one thread, so that a result does not depend on where it ran.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.batch.archive import ArchiveBag


@dataclass
class BatchSettings:
    """Settings of every stage (the sections of ``--config``: ``identify``, ``track``, ``update``,
    each a mapping of that stage's options)."""

    window_s: float = 600.0
    identify: dict[str, Any] = field(default_factory=dict)
    track: dict[str, Any] = field(default_factory=dict)
    update: dict[str, Any] = field(default_factory=dict)
    run_update: bool = True


@dataclass
class BagResult:
    bag: str
    structure: str
    n_windows: int
    estimates: list  # ModalEstimate, in time order
    records: list[dict[str, Any]]  # the modes JSON record of each window
    errors: list[str]


@dataclass
class StructureResult:
    structure: str
    name: str
    n_windows: int
    tracking: Any  # TrackingResult, or None when tracking failed
    posterior: dict[str, Any] | None
    errors: list[str]


def identify_bag(job: tuple[ArchiveBag, BatchSettings]) -> BagResult:
    from threadpoolctl import threadpool_limits

    from shm_ros.core.identify import IdentifyConfig, identify_window
    from shm_ros.io.modes_json import estimate_record
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    item, settings = job
    spec = load_structure(item.structure)
    cfg = IdentifyConfig.from_dict(settings.identify).validate()
    res = ingest_bag(item.bag, spec, window_s=settings.window_s)
    errors = [f"{item.bag}: {d}" for d in res.diagnostics if d.level >= 2]
    estimates, records = [], []
    with threadpool_limits(1, "blas"):
        for w in res.windows:
            try:
                e = identify_window(w, cfg)
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                errors.append(f"{item.bag}: window {w.window_id}: {exc}")
                continue
            estimates.append(e)
            records.append(estimate_record(e, w))
    return BagResult(item.bag, item.structure, len(res.windows), estimates, records, errors)


def process_structure(job: tuple[str, list, BatchSettings]) -> StructureResult:
    from threadpoolctl import threadpool_limits

    from shm_ros.core.tracking import TrackingConfig, track
    from shm_ros.io.structure import load_structure

    structure, estimates, settings = job
    spec = load_structure(structure)
    errors: list[str] = []
    tracking = posterior = None
    with threadpool_limits(1, "blas"):
        try:
            tracking = track(estimates, TrackingConfig(**settings.track))
        except ValueError as exc:
            errors.append(f"{structure}: track: {exc}")
        if tracking is not None and settings.run_update and spec.parameters:
            from shm_ros.core.bayes.update import UpdateConfig, update
            from shm_ros.core.models import build_model

            try:
                post = update(build_model(spec), tracking.observations, UpdateConfig(**settings.update),
                              priors=spec.parameters)
                posterior = post.to_dict()
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                errors.append(f"{structure}: update: {exc}")
    return StructureResult(structure, spec.name, len(estimates), tracking, posterior, errors)
