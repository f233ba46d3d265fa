"""The tracking history store: an embedded SQLite database (WAL, one writer, versioned schema).

It holds every window's modal estimate (with its covariates), the tracked row the tracker made of
it (assignments, normalised frequencies, novelty), the alarms, the models fitted on them
(reference modes, environmental fits, threshold) and a checkpoint of the tracker. Each window is
one transaction: estimate, rows, alarms and (every ``checkpoint_every`` windows) the checkpoint
commit together, so a process killed at any instant leaves a store that is a prefix of the
undisturbed run's. :func:`resume` rebuilds the tracker from the checkpoint and replays the
estimates stored after it (the tracker is deterministic), so a restart neither loses nor repeats a
window; an estimate whose window is already stored is skipped (:meth:`TrackStore.has`).

One writer: the writer holds an exclusive ``flock`` on ``<path>.lock``; readers (``shm-ros track
--store``) open the database read-only and may run at any time (WAL). Retention: rows and estimates
older than ``retention_days`` before the newest window are deleted (models and alarms are kept).
The checkpoint is the tracker's state in the typed, data-only encoding of
:mod:`shm_ros.io.checkpoint` (never a pickle: opening a crafted store must not run code). A checkpoint
that does not load - an older program's pickle, a different tracking configuration, a damaged row -
is discarded with a notice (:attr:`TrackStore.notices`, logged) and the tracker is rebuilt by
replaying the stored estimates.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import sqlite3
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.core.tracking import TrackedRow, Tracker
from shm_ros.core.tracking.config import EnvModel, ReferenceSource
from shm_ros.core.tracking.environment import EnvironmentalFit, PcaModel
from shm_ros.core.tracking.novelty import NoveltyChart
from shm_ros.core.tracking.reference import ReferenceMode
from shm_ros.core.types import ModalEstimate, Mode
from shm_ros.errors import ShmError
from shm_ros.io.atomic import DiskFullError
from shm_ros.io.checkpoint import CheckpointError, Codec
from shm_ros.io.faults import disk_full_point, fault_point

log = logging.getLogger(__name__)
CHECKPOINT_MAGIC = b"shm-ros-checkpoint 1\n"  # then the tracker's state (shm_ros.io.checkpoint)
# what a tracker's state may hold; its configuration and structure come from the node, not the file
CHECKPOINT_CLASSES = (ReferenceMode, EnvironmentalFit, PcaModel, NoveltyChart, ModalEstimate, Mode, EnvModel,
                      ReferenceSource)
_CODEC = Codec(CHECKPOINT_CLASSES)
_NOT_STATE = ("config", "structure")

SCHEMA_VERSION = 1
NS_PER_DAY = 86400 * 10**9

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS estimates (seq INTEGER PRIMARY KEY AUTOINCREMENT, window_id TEXT UNIQUE NOT NULL,
    start_ns INTEGER NOT NULL, record TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS rows (window_id TEXT PRIMARY KEY, start_ns INTEGER NOT NULL, record TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS rows_time ON rows (start_ns);
CREATE TABLE IF NOT EXISTS alarms (window_id TEXT PRIMARY KEY, start_ns INTEGER NOT NULL, score REAL,
    threshold REAL, modes TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS models (id INTEGER PRIMARY KEY AUTOINCREMENT, after_seq INTEGER NOT NULL,
    kind TEXT NOT NULL, record TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS checkpoint (id INTEGER PRIMARY KEY CHECK (id = 1), seq INTEGER NOT NULL,
    state BLOB NOT NULL);
"""


_COUNTS = {"rows": "SELECT COUNT(*) FROM rows", "estimates": "SELECT COUNT(*) FROM estimates",
           "alarms": "SELECT COUNT(*) FROM alarms", "models": "SELECT COUNT(*) FROM models"}


class StoreError(ShmError, RuntimeError):
    """The store cannot be opened (another writer, a newer schema); the message names the file."""


def _f(v: Any) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _fin(xs: list[float]) -> list[float | None]:
    return [x if math.isfinite(x) else None for x in xs]


def _arr(v: Any) -> Any:
    a = np.asarray(v, dtype=float)
    if a.ndim == 1:  # the common cases, through tolist (one C call) rather than element by element
        return _fin(a.tolist())
    if a.ndim == 2:
        return [_fin(r) for r in a.tolist()]
    return [_arr(x) for x in a]


def _nan(v: Any) -> np.ndarray:
    return np.array(v if v is not None else [], dtype=float) if not isinstance(v, list) else np.array(
        [[math.nan if x is None else x for x in r] if isinstance(r, list) else (math.nan if r is None else r)
         for r in v], dtype=float)


def estimate_record(e: ModalEstimate) -> dict[str, Any]:
    return {"window_id": e.window_id, "start_ns": e.start_ns, "end_ns": e.end_ns, "sensor_ids": list(e.sensor_ids),
            "method": e.method, "temperature_c": e.temperature_c, "covariates": dict(e.covariates),
            "modes": [[m.frequency_hz, m.damping_ratio, [float(x) for x in m.mode_shape]] for m in e.modes]}


def estimate_from_record(r: dict[str, Any]) -> ModalEstimate:
    return ModalEstimate(r["window_id"], int(r["start_ns"]), int(r["end_ns"]), list(r["sensor_ids"]),
                         [Mode(float(f), float(d), np.array(s, float)) for f, d, s in r["modes"]], r["method"],
                         r["temperature_c"], dict(r["covariates"]))


def row_record(r: TrackedRow) -> dict[str, Any]:
    return {"window_id": r.window_id, "start_ns": r.start_ns, "modes": list(r.mode_numbers),
            "frequencies_hz": _arr(r.frequencies_hz), "damping": _arr(r.damping), "macs": _arr(r.macs),
            "sensor_ids": list(r.sensor_ids), "shapes": _arr(r.shapes), "covariates": {
                k: _f(v) for k, v in r.covariates.items()}, "normalised_hz": _arr(r.normalised_hz),
            "novelty_score": _f(r.novelty_score), "novelty_threshold": _f(r.novelty_threshold),
            "novelty_alarm": bool(r.novelty_alarm), "alarm_modes": list(r.alarm_modes), "unassigned": r.unassigned}


def row_from_record(r: dict[str, Any]) -> TrackedRow:
    """The inverse of :func:`row_record` (``None`` back to NaN)."""
    def num(v: Any) -> float:
        return math.nan if v is None else float(v)

    return TrackedRow(r["window_id"], int(r["start_ns"]), [int(k) for k in r["modes"]], _nan(r["frequencies_hz"]),
                      _nan(r["damping"]), _nan(r["macs"]), list(r["sensor_ids"]), _nan(r["shapes"]),
                      {k: num(v) for k, v in r["covariates"].items()}, num(r["novelty_score"]),
                      num(r["novelty_threshold"]), bool(r["novelty_alarm"]), _nan(r["normalised_hz"]),
                      [int(k) for k in r["alarm_modes"]], int(r["unassigned"]))


class TrackStore:
    """See the module docstring. ``writer=False`` opens read-only."""

    def __init__(self, path: str | Path, writer: bool = True, retention_days: float = 0.0,
                 checkpoint_every: int = 100) -> None:
        self.path = Path(path)
        self.writer = writer
        self.retention_days = retention_days
        self.checkpoint_every = max(1, checkpoint_every)
        self._lock = None
        if writer:
            import fcntl

            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._lock = open(str(self.path) + ".lock", "w")  # noqa: SIM115 - held for the store's life
            try:
                fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                self._lock.close()
                raise StoreError(f"{self.path}: another process writes this store") from exc
            self.db = sqlite3.connect(self.path, isolation_level=None)
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            self.db.executescript(_SCHEMA)
            got = self.meta("schema_version")
            if got is None:
                self.db.execute("INSERT INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
            elif int(got) > SCHEMA_VERSION:
                raise StoreError(f"{self.path}: schema version {got} is newer than this program's {SCHEMA_VERSION}")
        else:
            if not self.path.is_file():
                raise StoreError(f"{self.path}: no such store")
            self.db = sqlite3.connect(f"file:{self.path}?mode=ro", uri=True)
        self._since_checkpoint = 0
        self.notices: list[str] = []  # e.g. a checkpoint discarded on open
        self._model_key: tuple[Any, ...] | None = None  # the tracker's model state at the last record

    def close(self) -> None:
        self.db.close()
        if self._lock is not None:
            self._lock.close()

    def __enter__(self) -> TrackStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- reading --------------------------------------------------------------------------------
    def meta(self, key: str) -> str | None:
        row = self.db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def has(self, window_id: str) -> bool:
        return self.db.execute("SELECT 1 FROM estimates WHERE window_id = ?", (window_id,)).fetchone() is not None

    def row(self, window_id: str) -> TrackedRow | None:
        """The tracked row of one stored window (None: not stored, or a window without a row)."""
        got = self.db.execute("SELECT record FROM rows WHERE window_id = ?", (window_id,)).fetchone()
        return None if got is None else row_from_record(json.loads(got[0]))

    def count(self, table: str = "rows") -> int:
        if table not in _COUNTS:
            raise ValueError(f"no table {table!r} (one of {', '.join(_COUNTS)})")
        return int(self.db.execute(_COUNTS[table]).fetchone()[0])

    def rows(self, start_ns: int | None = None, end_ns: int | None = None) -> list[dict[str, Any]]:
        """Tracked rows with ``start_ns <= window start < end_ns``, in time order."""
        q = "SELECT record FROM rows WHERE start_ns >= ? AND start_ns < ? ORDER BY start_ns, window_id"
        lo, hi = start_ns if start_ns is not None else -(2**63), end_ns if end_ns is not None else 2**63 - 1
        return [json.loads(r[0]) for r in self.db.execute(q, (lo, hi))]

    def alarms(self) -> list[dict[str, Any]]:
        return [{"window_id": w, "start_ns": t, "score": s, "threshold": th, "modes": json.loads(m)}
                for w, t, s, th, m in self.db.execute("SELECT * FROM alarms ORDER BY start_ns")]

    def models(self, kind: str | None = None) -> list[dict[str, Any]]:
        q = ("SELECT kind, after_seq, record FROM models WHERE kind = ? ORDER BY id" if kind else
             "SELECT kind, after_seq, record FROM models ORDER BY id")
        return [{"kind": k, "after_seq": s, **json.loads(r)} for k, s, r in self.db.execute(q, (kind,) if kind else ())]

    def estimates_after(self, seq: int) -> list[tuple[int, ModalEstimate]]:
        q = "SELECT seq, record FROM estimates WHERE seq > ? ORDER BY seq"
        return [(int(s), estimate_from_record(json.loads(r))) for s, r in self.db.execute(q, (seq,))]

    def observations(self, start_ns: int | None = None, end_ns: int | None = None,
                     normalised: bool = False) -> ModalObservations:
        """The tracked-modes table (docs/interfaces.md §4) of a time range."""
        rows = self.rows(start_ns, end_ns)
        if not rows:
            raise ValueError(f"{self.path}: no tracked window in that time range")
        numbers = max((r["modes"] for r in rows), key=len)
        sensors: list[str] = []
        for r in rows:
            sensors += [s for s in r["sensor_ids"] if s not in sensors]
        n_w, n_m, n_s = len(rows), len(numbers), len(sensors)
        freq, damp = np.full((n_w, n_m), np.nan), np.full((n_w, n_m), np.nan)
        shapes = np.full((n_w, n_m, n_s), np.nan)
        names: list[str] = []
        for r in rows:
            names += [c for c in r["covariates"] if c not in names]
        for w, r in enumerate(rows):
            k = len(r["modes"])
            freq[w, :k] = _nan(r["normalised_hz"] if normalised else r["frequencies_hz"])[:k] if k else []
            damp[w, :k] = _nan(r["damping"])
            cols = [sensors.index(s) for s in r["sensor_ids"]]
            if k and cols:
                shapes[w, :k][:, cols] = _nan(r["shapes"]).reshape(k, len(cols))
        cov = {c: np.array([math.nan if r["covariates"].get(c) is None else r["covariates"][c] for r in rows])
               for c in names}
        return ModalObservations(np.array([r["start_ns"] / 1e9 for r in rows]), list(numbers), freq, shapes,
                                 sensors, damp, cov, [], "iso")

    # -- writing --------------------------------------------------------------------------------
    def _rollback(self) -> None:
        if self.db.in_transaction:
            self.db.execute("ROLLBACK")
        self._model_key = None

    def record(self, est: ModalEstimate, rows: list[TrackedRow], tracker: Tracker) -> int:
        """One window in one transaction; returns its sequence number."""
        db = self.db
        db.execute("BEGIN IMMEDIATE")
        try:
            cur = db.execute("INSERT INTO estimates (window_id, start_ns, record) VALUES (?, ?, ?)",
                             (est.window_id, est.start_ns, json.dumps(estimate_record(est))))
            seq = int(cur.lastrowid or 0)
            for r in rows:
                db.execute("INSERT OR REPLACE INTO rows VALUES (?, ?, ?)",
                           (r.window_id, r.start_ns, json.dumps(row_record(r))))
                if r.novelty_alarm:
                    db.execute("INSERT OR REPLACE INTO alarms VALUES (?, ?, ?, ?, ?)",
                               (r.window_id, r.start_ns, _f(r.novelty_score), _f(r.novelty_threshold),
                                json.dumps(r.alarm_modes)))
            self._models(tracker, seq)
            self._since_checkpoint += 1
            if self._since_checkpoint >= self.checkpoint_every:
                db.execute("INSERT OR REPLACE INTO checkpoint VALUES (1, ?, ?)", (seq, checkpoint_bytes(tracker)))
                self._since_checkpoint = 0
                self._retain(est.start_ns)
            fault_point("store", "commit")  # a test hook: killed inside the transaction
            disk_full_point("store", self.path)
            db.execute("COMMIT")
        except (sqlite3.OperationalError, OSError) as exc:
            self._rollback()
            code = getattr(exc, "sqlite_errorcode", 0)
            if getattr(exc, "errno", None) == errno.ENOSPC or code == sqlite3.SQLITE_FULL:
                raise DiskFullError(errno.ENOSPC, f"{self.path}: no space left on the device: window "
                                    f"{est.window_id} not stored; the {self.count('estimates')} windows "
                                    "stored before are kept") from exc
            raise
        except BaseException:
            self._rollback()
            raise
        return seq

    def _models(self, tracker: Tracker, seq: int) -> None:
        """A new model record whenever the tracker's reference set or fits change."""
        # the record is costly to build (every fit's dataclass, JSON) and changes rarely: it is built
        # only when the model state changed since the last window. The key holds the reference modes
        # and fits themselves (compared by identity, so never a recycled id) and every field the record
        # reads from them by value; fits are never modified in place (a refit makes new ones).
        key = (tuple((r, r.number, r.frequency_hz, r.presence, r.source, r.shape.tobytes()) for r in tracker.reference),
               tuple(tracker.environment), tracker.trained, tracker.threshold if tracker.trained else None)
        old = self._model_key
        if old is not None and len(old[0]) == len(key[0]) and len(old[1]) == len(key[1]) and \
                all(a[0] is b[0] and a[1:] == b[1:] for a, b in zip(old[0], key[0], strict=True)) and \
                all(a is b for a, b in zip(old[1], key[1], strict=True)) and old[2:] == key[2:]:
            return  # same state as the last window: its record is already the newest one
        self._model_key = key
        record = {"reference": [{"mode": r.number, "frequency_hz": _f(r.frequency_hz), "presence": _f(r.presence),
                                 "source": r.source, "shape": _arr(r.shape)} for r in tracker.reference],
                  "environment": [{k: (_f(v) if isinstance(v, float) else v) for k, v in asdict(f).items()}
                                  for f in tracker.environment],
                  "threshold": _f(tracker.threshold) if tracker.trained else None}
        text = json.dumps(record, sort_keys=True)
        last = self.db.execute("SELECT record FROM models ORDER BY id DESC LIMIT 1").fetchone()
        if tracker.reference and (last is None or last[0] != text):
            self.db.execute("INSERT INTO models (after_seq, kind, record) VALUES (?, 'tracking', ?)", (seq, text))

    def _retain(self, newest_ns: int) -> None:
        if self.retention_days <= 0:
            return
        cut = newest_ns - int(self.retention_days * NS_PER_DAY)
        ck = self.db.execute("SELECT seq FROM checkpoint WHERE id = 1").fetchone()
        keep_seq = int(ck[0]) if ck else 0  # estimates after the checkpoint are needed to resume
        self.db.execute("DELETE FROM estimates WHERE start_ns < ? AND seq <= ?", (cut, keep_seq))
        self.db.execute("DELETE FROM rows WHERE start_ns < ?", (cut,))

    def checkpoint(self, make_tracker: Callable[[], Tracker]) -> tuple[int, Tracker | None]:
        """The stored checkpoint as ``(seq, tracker)`` on a fresh ``make_tracker()``; ``(0, None)`` when
        there is none or it is discarded (with a notice)."""
        row = self.db.execute("SELECT seq, state FROM checkpoint WHERE id = 1").fetchone()
        if row is None:
            return 0, None
        fresh = make_tracker()
        try:
            return int(row[0]), tracker_from_checkpoint(bytes(row[1]), fresh)
        except CheckpointError as exc:
            self._notice(f"{self.path}: tracker checkpoint discarded ({exc}); rebuilding it from the stored "
                         "estimates")
            return 0, None

    def _notice(self, text: str) -> None:
        self.notices.append(text)
        log.warning(text)


def _config_text(tracker: Tracker) -> str:
    return json.dumps(asdict(tracker.config), sort_keys=True, default=str)


def checkpoint_bytes(tracker: Tracker) -> bytes:
    """The tracker's state as a checkpoint (configuration fingerprint, then the typed encoding)."""
    state = {k: v for k, v in vars(tracker).items() if k not in _NOT_STATE}
    return CHECKPOINT_MAGIC + _CODEC.dumps({"config": _config_text(tracker), "state": state})


def tracker_from_checkpoint(data: bytes, fresh: Tracker) -> Tracker:
    """``fresh`` (a new tracker with the node's configuration) brought to the checkpoint's state;
    :class:`CheckpointError` when the data is not a checkpoint of this program (e.g. a pickle, which
    is never loaded) or was written under another tracking configuration."""
    if not data.startswith(CHECKPOINT_MAGIC):
        raise CheckpointError("not a typed checkpoint (an older program's pickle is never loaded)")
    doc = _CODEC.loads(data[len(CHECKPOINT_MAGIC):])
    if not isinstance(doc, dict) or set(doc) != {"config", "state"} or not isinstance(doc["state"], dict):
        raise CheckpointError("malformed checkpoint")
    if doc["config"] != _config_text(fresh):
        raise CheckpointError("written under another tracking configuration")
    state = doc["state"]
    expected = {k: type(v) for k, v in vars(fresh).items() if k not in _NOT_STATE}
    if set(state) != set(expected):
        raise CheckpointError(f"fields {sorted(set(state) ^ set(expected))[:5]} differ from this program's tracker")
    for k, cls in expected.items():
        if state[k] is not None and cls is not type(None) and not isinstance(state[k], cls):
            raise CheckpointError(f"field {k!r} is a {type(state[k]).__name__}, expected {cls.__name__}")
    fresh.__dict__.update(state)
    return fresh


def resume(store: TrackStore, make_tracker: Any) -> tuple[Tracker, int]:
    """The tracker as it was after the last stored window (``make_tracker()``: a fresh one), and
    how many stored estimates were replayed to get there."""
    seq, tracker = store.checkpoint(make_tracker)
    if tracker is None:
        seq, tracker = 0, make_tracker()
    replay = store.estimates_after(seq)
    for _, est in replay:
        tracker.add(est)  # rows already stored with their estimate
    return tracker, len(replay)
