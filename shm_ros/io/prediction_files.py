"""prediction_series.json: the traces behind the predicted-vs-measured figures of ``shm-ros predict``
(per event and predicted location: measured values, predictive mean, 95 % band, nominal model)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from shm_ros.io import jsonio

SERIES = "prediction_series.json"


def series_of(pred: Any) -> dict[str, Any]:
    return {"window_id": pred.window_id, "fs": float(pred.fs),
            "strong_s": [pred.strong.start / pred.fs, pred.strong.stop / pred.fs],
            "channels": {c.name: {"quantity": c.quantity, "measured": bool(c.measured), "mean": c.mean,
                                  "lower": c.lower, "upper": c.upper, "nominal": c.nominal,
                                  "values": c.values} for c in pred.channels}}


def series_text(pred: Any) -> str:
    """One event's traces as compact JSON text (tens of MB for a long record at a high rate: encoded
    once, where the prediction is made, and joined by :func:`write_series`)."""
    return jsonio.dumps(series_of(pred), indent=None)


def write_series(out: str | Path, texts: Iterable[str]) -> Path:
    """prediction_series.json of events already encoded by :func:`series_text`, atomically."""
    from shm_ros.io.atomic import atomic_path

    path = Path(out) / SERIES
    with atomic_path(path) as tmp, tmp.open("w", encoding="utf-8") as fh:
        fh.write('{"events": [')
        for i, text in enumerate(texts):
            fh.write(("," if i else "") + text)
        fh.write("]}\n")
    return path


def write_prediction_series(out: str | Path, preds: list[Any]) -> Path:
    return write_series(out, (series_text(p) for p in preds))


def read_prediction(path: str | Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """(prediction.json, series) from a folder or a prediction.json; series {} when absent."""
    p = Path(path)
    p = p / "prediction.json" if p.is_dir() else p
    payload = jsonio.loads(p.read_text(encoding="utf-8"))
    s = p.with_name(SERIES)
    return payload, (jsonio.loads(s.read_text(encoding="utf-8")) if s.is_file() else {})
