"""The tracker's checkpoint in the history store is data, never code: a store whose checkpoint row
holds a pickle (an older program's, or a crafted one with a payload) is opened without unpickling
it - the checkpoint is discarded with a notice and the tracker rebuilt from the stored estimates -
and a typed checkpoint naming a type outside the allow-list is refused the same way."""

from __future__ import annotations

import base64
import json
import pickle

import numpy as np
import pytest
from test_tracking_core import _campaign

from shm_ros.core.tracking import Tracker, TrackingConfig
from shm_ros.io.checkpoint import CheckpointError, Codec
from shm_ros.io.store import CHECKPOINT_MAGIC, TrackStore, checkpoint_bytes, resume, tracker_from_checkpoint

CFG = TrackingConfig(reference_windows=12)


def _fresh() -> Tracker:
    return Tracker(CFG, training_windows=30)


class _Payload:
    """Unpickling this creates the marker file (what ``os.system`` in a crafted store would do)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def _store_with(path, estimates, state: bytes | None):
    store = TrackStore(path, checkpoint_every=10**6)
    tracker = _fresh()
    for e in estimates:
        store.record(e, tracker.add(e), tracker)
    if state is not None:
        store.db.execute("INSERT OR REPLACE INTO checkpoint VALUES (1, ?, ?)", (len(estimates), state))
    store.close()
    return tracker


def _rows(tracker, estimates) -> str:
    """The rows the tracker makes of ``estimates``, as text (NaN compares equal)."""
    return repr([(r.window_id, r.frequencies_hz.tolist(), r.novelty_score, r.novelty_alarm)
                 for e in estimates for r in tracker.add(e)])


def test_a_pickled_checkpoint_never_runs(tmp_path):
    est, _, _ = _campaign(5, n=60)
    marker = tmp_path / "owned"
    _store_with(tmp_path / "s.sqlite", est[:40], pickle.dumps(_Payload(marker)))
    store = TrackStore(tmp_path / "s.sqlite")
    tracker, replayed = resume(store, _fresh)
    assert not marker.exists()  # the payload did not run
    assert replayed == 40 and len(store.notices) == 1 and "discarded" in store.notices[0]
    reference = _fresh()
    for e in est[:40]:
        reference.add(e)
    assert _rows(tracker, est[40:]) == _rows(reference, est[40:])  # rebuilt by replay: the same tracker
    store.close()


def test_typed_checkpoint_resumes_and_refuses_foreign_types(tmp_path):
    est, _, _ = _campaign(6, n=70)
    tracker = _store_with(tmp_path / "ok.sqlite", est[:50], None)
    data = checkpoint_bytes(tracker)
    assert data.startswith(CHECKPOINT_MAGIC) and b"pickle" not in data
    again = tracker_from_checkpoint(data, _fresh())
    assert _rows(again, est[50:]) == _rows(tracker, est[50:])
    # a crafted typed checkpoint: an object of a class outside the allow-list
    doc = json.loads(data[len(CHECKPOINT_MAGIC):])
    doc["d"][1][1]["d"][0][1] = {"o": "os:system", "s": {}}  # the state's first field
    crafted = CHECKPOINT_MAGIC + json.dumps(doc).encode()
    with pytest.raises(CheckpointError, match="not allowed"):
        tracker_from_checkpoint(crafted, _fresh())
    _store_with(tmp_path / "bad.sqlite", est[:20], crafted)
    store = TrackStore(tmp_path / "bad.sqlite")
    _, replayed = resume(store, _fresh)
    assert replayed == 20 and "not allowed" in store.notices[0]
    store.close()


@pytest.mark.parametrize("record", [
    {"a": "|O", "s": [1], "b": ""},  # object arrays are refused
    {"a": "<f8", "s": [10**6], "b": base64.b64encode(b"\0" * 8).decode()},  # data does not fill the shape
    {"q": [], "n": -1}, {"d": [[{"l": []}, 1]]}, {"e": "os:path", "v": 1}, [1, 2], {"x": 1},
])
def test_codec_refuses_malformed_records(record):
    with pytest.raises(CheckpointError):
        Codec([]).decode(record)


def test_codec_round_trip_keeps_types():
    from collections import deque

    value = {"a": np.arange(6, dtype=np.int32).reshape(2, 3), (1, "k"): [float("nan"), float("inf"), True, None],
             "q": deque([1, 2], maxlen=5), "b": np.array([True, False])}
    back = Codec([]).loads(Codec([]).dumps(value))
    assert back.keys() == value.keys() and back["a"].dtype == np.int32 and np.array_equal(back["a"], value["a"])
    assert np.isnan(back[(1, "k")][0]) and back[(1, "k")][1:] == [float("inf"), True, None]
    assert back["q"] == value["q"] and back["q"].maxlen == 5 and back["b"].dtype == bool
