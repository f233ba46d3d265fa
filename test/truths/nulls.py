"""Dense null campaigns as (ModalObservations, StructureSpec): the generator of the threshold's
calibration under realistic nulls (``bench/calibrate_explain.py --generator truths.nulls:dense_null
--with-locate``, docs/explain.md "The threshold").

A replicate's seed picks its null: a slow unmeasured AR(1) driver, a random walk, or none (each third
of the seeds), on the girder or the building as :mod:`.dense_campaign` chooses; ``n_windows`` picks the
size (the full size's hourly windows or more: full; else reduced). ``kind`` (the calibration's
girder / building alternation) is not used: the campaign draws its own structure.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from .dense_campaign import WINDOWS
from .registry import make_campaign

DENSE_NULLS = ("dense_ar1_null", "dense_random_walk_null", "dense_clean")


def dense_null(seed: int, kind: str, n_windows: int):
    from shm_ros.io.structure import load_structure
    from shm_ros.io.tables import read_tracked_modes

    size = "full" if n_windows >= WINDOWS["full"] else "reduced"
    with tempfile.TemporaryDirectory() as tmp:
        c = make_campaign(DENSE_NULLS[seed % len(DENSE_NULLS)], seed, size, Path(tmp) / "campaign")
        return read_tracked_modes(c.data), load_structure(c.structure)
