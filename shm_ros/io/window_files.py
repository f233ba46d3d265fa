"""Windows on disk: one ``.npz`` per window (what ``shm-ros ingest`` writes)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from shm_ros.core.ingest.events import window_event_kind
from shm_ros.core.types import Window
from shm_ros.errors import InputError


def window_filename(index: int, w: Window) -> str:
    return f"w{index:05d}_{w.window_id.replace(':', '').replace('-', '')}.npz"


def save_window(path: str | Path, w: Window) -> None:
    """One window as ``.npz``: samples, flags (empty = clean), and every other field."""
    np.savez(
        path,
        samples=w.samples,
        flags=w.flags if w.flags is not None else np.zeros((0, 0), np.uint8),
        start_ns=np.int64(w.start_ns),
        sample_rate_hz=np.float64(w.sample_rate_hz),
        channel_names=np.asarray(w.channel_names, dtype=str),
        channel_status=np.asarray(w.channel_status or [], dtype=str),
        temperature_c=np.float64(np.nan if w.temperature_c is None else w.temperature_c),
        is_event=np.bool_(w.is_event),
        pga_m_s2=np.float64(w.pga_m_s2),
        input_channel=np.asarray(w.input_channel or ""),
        window_id=np.asarray(w.window_id),
        notes=np.asarray(w.notes, dtype=str),
        event_kind=np.asarray(w.event_kind or ""),
    )


def load_window(path: str | Path) -> Window:
    """The :class:`Window` saved by :func:`save_window`; :class:`InputError` naming the file when it
    is not one."""
    try:
        return _load_window(path)
    except (OSError, EOFError, KeyError, IndexError, TypeError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a window file of shm-ros ingest: {type(exc).__name__}: {exc}") from None


def _load_window(path: str | Path) -> Window:
    with np.load(path, allow_pickle=False) as z:
        flags = z["flags"]
        t = float(z["temperature_c"])
        w = Window(
            window_id=str(z["window_id"]),
            start_ns=int(z["start_ns"]),
            sample_rate_hz=float(z["sample_rate_hz"]),
            channel_names=[str(c) for c in z["channel_names"]],
            samples=np.array(z["samples"]),
            flags=None if flags.size == 0 else np.array(flags),
            channel_status=[str(c) for c in z["channel_status"]] or None,
            temperature_c=None if np.isnan(t) else t,
            is_event=bool(z["is_event"]),
            pga_m_s2=float(z["pga_m_s2"]),
            input_channel=str(z["input_channel"]) or None,
            notes=[str(n) for n in z["notes"]],
            event_kind=str(z["event_kind"]) if "event_kind" in z.files else "",
        )
    if not w.event_kind:  # written before windows were named: named with the ingest defaults
        w.event_kind = window_event_kind(w).value
    return w
