"""A whole batch: every bag's job on the engine, then every structure's job, then the files.

Output folder: one sub-folder per structure (named after the structure) with ``modes.json``,
``tracked_modes.csv``, ``tracking.json`` and ``posterior.json`` (when the structure file has
parameters), and ``batch.json`` with what ran where and every error. Every finished bag is kept in
``.bags/`` there until the batch has written its outputs (:mod:`shm_ros.batch.checkpoint`): a batch
killed half-way and started again with the same arguments identifies only the bags it had not
finished.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from shm_ros.batch import checkpoint
from shm_ros.batch.archive import ArchiveBag
from shm_ros.batch.engines import Engine
from shm_ros.batch.jobs import BagResult, BatchSettings, StructureResult, process_structure
from shm_ros.core.progress import Progress


def run_batch(bags: Sequence[ArchiveBag], settings: BatchSettings, engine: Engine, out: str | Path,
              log: Callable[[str], None] = print) -> dict[str, Any]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    log(f"{len(bags)} bags, {len({b.structure for b in bags})} structure(s), engine {engine.name}")
    kept = [checkpoint.path_for(out, b, settings) for b in bags]
    finished = {i: r for i, p in enumerate(kept) if (r := checkpoint.load(p)) is not None}
    if finished:
        log(f"resuming: {len(finished)} of {len(bags)} bags already identified "
            f"({out / checkpoint.FOLDER}); {len(bags) - len(finished)} to go")
    todo = [i for i in range(len(bags)) if i not in finished]
    fresh = engine.map(checkpoint.identify_bag_kept, [(bags[i], settings, str(kept[i])) for i in todo],
                       progress=_progress("bags", log))
    finished.update(zip(todo, fresh, strict=True))
    bag_results: list[BagResult] = [finished[i] for i in range(len(bags))]
    groups: dict[str, list] = {}
    for r in bag_results:
        groups.setdefault(r.structure, []).extend(r.estimates)
    jobs = [(s, sorted(est, key=lambda e: e.start_ns), settings) for s, est in sorted(groups.items())]
    structure_results: list[StructureResult] = engine.map(process_structure, jobs,
                                                          progress=_progress("structures", log))
    summary = _write(out, settings, bag_results, structure_results)
    checkpoint.clear(out)  # finished: the outputs hold everything
    log(f"done in {time.monotonic() - t0:.0f} s -> {out}")
    return summary


def _progress(what: str, log: Callable[[str], None]) -> Callable[[int, int], None]:
    bar = Progress(what, every_s=0.0)
    return lambda done, total: log(bar.line(done, total, time.monotonic() - bar.t0))


def _folder(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name) or "structure"


def _write(out: Path, settings: BatchSettings, bags: list[BagResult], structures: list[StructureResult]
           ) -> dict[str, Any]:
    from shm_ros.core.provenance import stamp_output
    from shm_ros.io.jsonio import dump
    from shm_ros.io.tables import write_tracked_modes

    by_structure: dict[str, list[dict[str, Any]]] = {}
    for b in bags:
        by_structure.setdefault(b.structure, []).extend(b.records)
    config = {"batch": asdict(settings)}
    rows = []
    for s in structures:
        folder = out / _folder(s.name)
        folder.mkdir(parents=True, exist_ok=True)
        records = sorted(by_structure.get(s.structure, []), key=lambda r: r["start"])
        dump(stamp_output({"windows": records}, config | {"structure": s.structure}), folder / "modes.json")
        if s.tracking is not None:
            write_tracked_modes(folder / "tracked_modes.csv", s.tracking.observations)
            dump(stamp_output(_tracking_summary(s.tracking), config), folder / "tracking.json")
        if s.posterior is not None:
            dump(stamp_output(s.posterior, config), folder / "posterior.json")
        rows.append({"structure": s.structure, "name": s.name, "folder": folder.name,
                     "windows_identified": s.n_windows, "tracked": s.tracking is not None,
                     "updated": s.posterior is not None, "errors": s.errors})
    summary = {"bags": [{"bag": b.bag, "structure": b.structure, "windows": b.n_windows,
                         "identified": len(b.estimates), "errors": b.errors} for b in bags],
               "structures": rows}
    dump(stamp_output(summary, config), out / "batch.json")
    return summary


def _tracking_summary(res: Any) -> dict[str, Any]:
    obs = res.observations
    return {"reference_modes": [{"mode": r.number, "frequency_hz": r.frequency_hz} for r in res.reference],
            "n_windows": obs.n_windows, "unassigned_modes": res.unassigned,
            "novelty": {"threshold": _num(res.novelty_threshold), "alarms": int(res.novelty_alarm.sum())},
            "notes": res.notes}


def _num(x: Any) -> float | None:
    v = float(x)
    return v if math.isfinite(v) else None
