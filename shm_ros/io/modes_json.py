"""The identified-modes JSON of docs/interfaces.md section 3 (``shm-ros identify --out modes.json``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.provenance import stamp_output
from shm_ros.core.types import ModalEstimate, Mode, Window
from shm_ros.io import jsonio


def iso(t_ns: int) -> str:
    from shm_ros.core.timeutil import ns_to_iso as iso_utc

    return iso_utc(t_ns)


def _finite(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def estimate_record(e: ModalEstimate, window: Window | None = None) -> dict[str, Any]:
    """One window of the modes JSON (docs/interfaces.md §3); ``window`` adds its event flag and PGA.
    ``covariates`` are the estimate's (identify copies the window's ``rms_accel_m_s2`` and, for an
    event, ``pga_m_s2``)."""
    modes = sorted(e.modes, key=lambda m: m.frequency_hz)
    record: dict[str, Any] = {
        "start": iso(e.start_ns),
        "end": iso(e.end_ns),
        "temperature_c": None if e.temperature_c is None else _finite(e.temperature_c),
        "window_id": e.window_id,
        "method": e.method,
        "sensor_ids": list(e.sensor_ids),
        "modes": [{
            "frequency_hz": float(m.frequency_hz),
            "damping_ratio": float(m.damping_ratio),
            "mpc": _finite(m.mpc),
            "mode_shape": {s: float(v) for s, v in zip(e.sensor_ids, np.asarray(m.mode_shape), strict=True)},
            "frequency_std_hz": _finite(m.frequency_std_hz),
            "damping_std": _finite(m.damping_std),
            "frequency_spread_hz": _finite(getattr(m, "frequency_spread_hz", float("nan"))),
            "damping_spread": _finite(getattr(m, "damping_spread", float("nan"))),
            "n_poles": int(m.n_poles),
        } for m in modes],
    }
    if window is not None:
        record["is_event"] = bool(window.is_event)
        record["pga_m_s2"] = _finite(window.pga_m_s2)
    if e.covariates:
        record["covariates"] = {k: _finite(v) for k, v in e.covariates.items()}
    return record


def modes_document(estimates: list[ModalEstimate], config: dict | None = None,
                   seed: int | None = None) -> dict[str, Any]:
    ordered = sorted(estimates, key=lambda e: e.start_ns)
    return stamp_output({"windows": [estimate_record(e) for e in ordered]}, config, seed)


def dump(document: dict[str, Any], path: str | Path) -> Path:
    """Write a JSON document strictly (NaN/Inf are written as null, :mod:`shm_ros.io.jsonio`)."""
    return jsonio.dump(document, path)


def write_modes_json(path: str | Path, estimates: list[ModalEstimate], config: dict | None = None,
                     seed: int | None = None) -> Path:
    return dump(modes_document(estimates, config, seed), path)


def read_modes_json(path: str | Path) -> list[ModalEstimate]:
    """Back to dataclasses (times parsed from ISO 8601)."""
    from datetime import datetime

    def ns(text: str) -> int:
        dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
        return int(round(dt.timestamp() * 1e9))

    doc = jsonio.load(path)
    out = []
    for k, w in enumerate(doc.get("windows", [])):
        sensors = list(w["modes"][0]["mode_shape"]) if w.get("modes") else []
        modes = [Mode(frequency_hz=m["frequency_hz"], damping_ratio=m["damping_ratio"],
                      mode_shape=np.array([m["mode_shape"][s] for s in sensors]),
                      mpc=m.get("mpc") if m.get("mpc") is not None else float("nan"),
                      n_poles=int(m.get("n_poles", 0)))
                 for m in w.get("modes", [])]
        out.append(ModalEstimate(window_id=w.get("window_id", str(k)), start_ns=ns(w["start"]),
                                 end_ns=ns(w["end"]), sensor_ids=sensors, modes=modes,
                                 method=w.get("method", ""), temperature_c=w.get("temperature_c"),
                                 covariates={k: float(v) for k, v in (w.get("covariates") or {}).items()
                                             if v is not None}))
    return out
