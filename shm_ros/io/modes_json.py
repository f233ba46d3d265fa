"""The identified-modes JSON of contracts section 3 (``shm-ros identify --out modes.json``)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.provenance import stamp_output
from shm_ros.core.types import ModalEstimate, Mode


def iso(t_ns: int) -> str:
    from datetime import datetime, timezone

    dt = datetime.fromtimestamp(t_ns // 1_000_000_000, tz=timezone.utc)
    frac = t_ns % 1_000_000_000
    text = dt.strftime("%Y-%m-%dT%H:%M:%S")
    return text + (f".{frac // 1_000_000:03d}" if frac else "") + "Z"


def _finite(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def estimate_record(e: ModalEstimate) -> dict[str, Any]:
    modes = sorted(e.modes, key=lambda m: m.frequency_hz)
    record = {
        "window_id": e.window_id,
        "start": iso(e.start_ns),
        "end": iso(e.end_ns),
        "temperature_c": _finite(e.temperature_c) if e.temperature_c is not None else None,
        "method": e.method,
        "modes": [{
            "frequency_hz": float(m.frequency_hz),
            "damping_ratio": float(m.damping_ratio),
            "mpc": _finite(m.mpc),
            "frequency_std_hz": _finite(m.frequency_std_hz),
            "damping_std": _finite(m.damping_std),
            "n_poles": int(m.n_poles),
            "mode_shape": {s: float(v) for s, v in zip(e.sensor_ids, np.asarray(m.mode_shape))},
        } for m in modes],
    }
    if e.covariates:
        record["covariates"] = {k: _finite(v) for k, v in e.covariates.items()}
    return record


def modes_document(estimates: list[ModalEstimate], config: dict | None = None,
                   seed: int | None = None) -> dict[str, Any]:
    ordered = sorted(estimates, key=lambda e: e.start_ns)
    return stamp_output({"windows": [estimate_record(e) for e in ordered]}, config, seed)


def write_modes_json(path: str | Path, estimates: list[ModalEstimate], config: dict | None = None,
                     seed: int | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(modes_document(estimates, config, seed), indent=1))
    return path


def read_modes_json(path: str | Path) -> list[ModalEstimate]:
    """Back to dataclasses (times parsed from ISO 8601)."""
    from datetime import datetime

    def ns(text: str) -> int:
        dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
        return int(round(dt.timestamp() * 1e9))

    doc = json.loads(Path(path).read_text())
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
                                 method=w.get("method", ""), temperature_c=w.get("temperature_c")))
    return out
