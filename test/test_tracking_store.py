"""The history store (SQLite): every window with its row, resume after a crash at any window
without losing or repeating one, redelivered estimates skipped, export by time range, one writer,
retention; and the track command's export from a store."""

from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest
from test_tracking_core import _campaign

from shm_ros.core.tracking import Tracker, TrackingConfig, track
from shm_ros.io.store import SCHEMA_VERSION, StoreError, TrackStore, resume
from shm_ros.io.tables import read_tracked_modes, write_tracked_modes

CFG = TrackingConfig(reference_windows=12)
TRAIN = 40


def _fresh() -> Tracker:
    return Tracker(CFG, training_windows=TRAIN)


def _run(path, estimates, crash_at=(), redeliver=100, every=7):
    """Feed ``estimates`` to a store-backed tracker; at each index in ``crash_at`` the process
    "dies" (objects dropped without closing: an open transaction is lost, as with kill -9) and
    a new one resumes, first receiving again up to ``redeliver`` recent estimates."""
    store = TrackStore(path, checkpoint_every=every)
    tracker, _ = resume(store, _fresh)
    skipped = 0
    for i, e in enumerate(estimates):
        if i in crash_at:
            store.db.execute("BEGIN IMMEDIATE")  # a transaction in flight when the process dies
            store.db.execute("INSERT INTO estimates (window_id, start_ns, record) VALUES ('torn', 0, '{}')")
            store._lock.close()
            store.db.close()
            store = TrackStore(path, checkpoint_every=every)
            tracker, _ = resume(store, _fresh)
            for old in estimates[max(0, i - redeliver):i]:  # transient-local redelivery
                assert store.has(old.window_id)
                skipped += 1
        if store.has(e.window_id):
            continue
        store.record(e, tracker.add(e), tracker)
    return store, skipped


def test_store_resumes_after_crashes_without_loss_or_duplicates(tmp_path):
    est, _, _ = _campaign(7, n=240, damage_at=0.75, damage=0.02)
    calm, _ = _run(tmp_path / "calm.sqlite", est)
    rng = np.random.default_rng(3)
    crashes = set(rng.choice(np.arange(1, 240), 6, replace=False).tolist()) | {5, 12, 13}  # in the reference period too
    hit, skipped = _run(tmp_path / "hit.sqlite", est, crashes)
    assert skipped > 0
    for table in ("rows", "estimates", "alarms", "models"):
        assert hit.count(table) == calm.count(table), table
    assert hit.count("estimates") == 240 and not hit.has("torn")
    assert hit.rows() == calm.rows()
    assert hit.alarms() == calm.alarms() and len(calm.alarms()) > 10
    assert hit.models() == calm.models()
    write_tracked_modes(tmp_path / "calm.csv", calm.observations())
    write_tracked_modes(tmp_path / "hit.csv", hit.observations())
    assert (tmp_path / "calm.csv").read_bytes() == (tmp_path / "hit.csv").read_bytes()
    # the store's table is the batch tracker's table
    batch = track(est, TrackingConfig(reference_windows=12, training_fraction=TRAIN / 240))
    assert np.allclose(calm.observations().frequencies_hz, batch.observations.frequencies_hz, equal_nan=True)
    assert [a["window_id"] for a in calm.alarms()] == [w for w, a in zip(batch.window_ids, batch.novelty_alarm,
                                                                                  strict=True) if a]
    # the fitted models are kept: the reference set and, after training, the environmental fits
    models = calm.models()
    assert models[0]["reference"] and models[-1]["environment"] and models[-1]["threshold"] > 0
    assert calm.meta("schema_version") == str(SCHEMA_VERSION)
    assert calm.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    calm.close()
    hit.close()


def test_one_writer_readers_time_range_retention_and_schema(tmp_path):
    est, _, _ = _campaign(8, n=120, damage_at=2.0)
    store, _ = _run(tmp_path / "s.sqlite", est)
    with pytest.raises(StoreError, match="another process"):
        TrackStore(tmp_path / "s.sqlite")
    with TrackStore(tmp_path / "s.sqlite", writer=False) as reader:
        t = [r["start_ns"] for r in reader.rows()]
        part = reader.rows(t[20], t[50])
        assert [r["start_ns"] for r in part] == t[20:50]
        with pytest.raises(sqlite3.OperationalError):
            reader.db.execute("DELETE FROM rows")
    store.close()
    # retention: a store keeping one day holds the last day of windows (10-minute windows: 144)
    keep = TrackStore(tmp_path / "r.sqlite", retention_days=0.25, checkpoint_every=10)
    tracker = _fresh()
    for e in est:
        keep.record(e, tracker.add(e), tracker)
    assert 36 <= keep.count("rows") <= 36 + 10
    keep.close()
    db = sqlite3.connect(tmp_path / "s.sqlite")
    db.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION + 1),))
    db.commit()
    db.close()
    with pytest.raises(StoreError, match="newer"):
        TrackStore(tmp_path / "s.sqlite")


def test_track_command_exports_a_store_by_time_range(tmp_path, capsys):
    from datetime import datetime, timezone

    from shm_ros.cli import main

    est, _, _ = _campaign(9, n=150, damage_at=0.7, damage=0.03)
    store, _ = _run(tmp_path / "s.sqlite", est)
    store.close()
    t0 = datetime.fromtimestamp(est[30].start_ns / 1e9, tz=timezone.utc).isoformat()
    rc = main(["track", "--store", str(tmp_path / "s.sqlite"), "--out", str(tmp_path / "x"), "--from", t0])
    assert rc == 0, capsys.readouterr().err
    table = read_tracked_modes(tmp_path / "x" / "tracked_modes.csv")
    assert table.n_windows == 120 and table.mode_numbers == [1, 2, 3, 4, 5]
    norm = read_tracked_modes(tmp_path / "x" / "normalised_modes.csv")
    # normalised frequencies (windows 40-99: trained, before the change at 105) scatter less than
    # the raw ones: the temperature effect is removed; the training rows have none
    span = slice(TRAIN - 30, 100 - 30)
    assert np.nanstd(norm.frequencies_hz[span, 0]) < 0.5 * np.nanstd(table.frequencies_hz[span, 0])
    assert np.isnan(norm.frequencies_hz[: TRAIN - 30]).all()
    alarms = json.loads((tmp_path / "x" / "alarms.json").read_text())["alarms"]
    assert alarms and all(a["modes"] for a in alarms)
    rc = main(["track", "--store", str(tmp_path / "none.sqlite"), "--out", str(tmp_path / "y")])
    assert rc == 2 and "no such store" in capsys.readouterr().err
