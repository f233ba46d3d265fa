"""Stops and crashes of a running graph lose and duplicate nothing (real node processes, real DDS).

`shm-ros run` (ingest, identify, track with its store, recorder; restarts on) is fed by
`shm-ros replay` while deterministic faults (``SHM_FAULT``, :mod:`shm_ros.io.faults`) kill a node
at a point: the recorder in the middle of a bag write, identify after publishing a window's
estimate, track inside its store's commit. The first replay is stopped by SIGTERM; a second replay
of the same bag resumes. Then Ctrl-C reaches the whole process group (supervisor and nodes), as
from a terminal. The recorded bag must open without salvage and hold every window, modal estimate
and tracked row exactly once; the tracked rows must equal an undisturbed tracking of the same
estimates; the store must hold every window; no traceback; nothing left running; the graph's exit
code says whether something was lost (a killed node not running again at the stop) and the replay
that was stopped says so.

One run in CI, stopped once the three killed nodes are running again: exit code 0, every window
published before the stop recorded, estimated and stored once. ``SHM_FULL=1`` runs 20 with kill
points drawn from a fixed seed, every other one stopped as soon as the three faults fired.

Also: the recorder killed as it closes its bag at a Ctrl-C (``recorder:close``) keeps every window
for the next start; killing the supervisor with SIGKILL leaves no node running (and the recorder,
ended by its parent-death signal, closes its bag); a node with a bad configuration stops the graph
with its reason instead of being restarted in a loop. Those run only the nodes their point needs.
"""

from __future__ import annotations

import collections
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import full_size
from ros_helpers.graph import ids_written
from test_graph_faults import _signal
from test_supervisor import _children, _identity, _Lines, _still_running, _wait_for

FS = 100.0
T0 = 1_714_521_600_000_000_000
WINDOW_S = 5.0
N_WINDOWS = 6
RESULTS = ("/shm/windows", "/shm/modal_estimates", "/shm/tracked_modes")  # recorded once per window each
STRUCTURE = """
name: three-storey-test-frame
kind: shear_building
shear_building:
  floors:
    - {mass: 1.0e+5, stiffness: 2.0e+8}
    - {mass: 1.0e+5, stiffness: 2.0e+8}
    - {mass: 1.0e+5, stiffness: 2.0e+8}
sensors:
  - {id: f1, at: {floor: 1}, direction: x}
  - {id: f2, at: {floor: 2}, direction: x}
  - {id: f3, at: {floor: 3}, direction: x}
"""


def _bag(path: Path) -> None:
    """N_WINDOWS windows of a two-mode response, as 0.5 s blocks of three channels."""
    from shm_ros.io.bags import BagWriter

    n = int(N_WINDOWS * WINDOW_S * FS)
    x = _signal(np.random.default_rng(3), n)
    with BagWriter(path) as w:
        for k in range(0, n, 50):
            w.accel_block("/site/daq/accel_block", T0 + int(k * 1e9 / FS), FS, ["f1", "f2", "f3"], x[k:k + 50])


def _config(tmp_path: Path, only: tuple[str, ...] = (), **extra: dict) -> Path:
    """The graph: ingest, identify, track, recorder (``only`` those named), ``extra`` parameters by node."""
    structure = tmp_path / "structure.yaml"
    structure.write_text(STRUCTURE)
    # close_wait_s: a killed node's reader stays matched until DDS drops it, and ingest's stop would
    # wait the default 10 s for it in vain (what ingest publishes as it closes is not counted here)
    nodes = {"ingest": {"parameters": {"structure": str(structure), "window_s": WINDOW_S, "close_wait_s": 2.0}},
             "identify": {"parameters": {"structure": str(structure)}},
             "track": {"parameters": {"store": str(tmp_path / "track.sqlite"), "reference_windows": 3}},
             "recorder": {"parameters": {"output": str(tmp_path / "out")}}}
    for name, params in extra.items():
        nodes[name] = {"parameters": {**nodes.get(name, {}).get("parameters", {}), **params}}
    if only:
        nodes = {name: node for name, node in nodes.items() if name in only}
    config = tmp_path / "graph.yaml"
    config.write_text(yaml.safe_dump({"graph": {"mode": "processes", "restart": True}, "nodes": nodes}))
    return config


class _Family:
    """Every process the supervisor started (and theirs), seen while it ran: pid -> start time."""

    def __init__(self, root: int) -> None:
        self.root = root
        self.seen: dict[int, int] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.is_set():
            todo = [self.root]
            while todo:
                kids = _children(todo.pop())
                self.seen.update(_identity(kids))
                todo += list(kids)
            time.sleep(0.3)

    def close(self) -> dict[int, int]:
        self._stop.set()
        self._thread.join(timeout=5)
        return self.seen


def _replay_args(bag: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "shm_ros.cli", "replay", str(bag), "--wait", "90", *extra]


def _replay(bag: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(_replay_args(bag, *extra), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _estimates_in_store(path: Path) -> int:
    from shm_ros.io.store import TrackStore

    if not path.exists():
        return 0
    with TrackStore(path, writer=False) as store:
        return store.count("estimates")


def _session(tmp_path: Path, bag: Path, env: dict[str, str], stop_when, stop_signal: int, *replay_args: str,
             only: tuple[str, ...] = ("ingest", "identify", "track", "recorder"), extra: dict | None = None):
    """Start the graph (the nodes ``only``), replay ``bag``, and once ``stop_when(output)`` holds send
    ``stop_signal`` to the graph's process group; returns (graph exit code, its output, replay exit
    code and output, every process seen, whether the replay still ran at the stop)."""
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(_config(tmp_path, only, **(extra or {})))],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                           start_new_session=True)  # its own process group, as a terminal's job
    out = _Lines(sup)
    family = _Family(sup.pid)
    try:
        up = _wait_for(lambda: all(out.count(f"[{n}]:") for n in only), timeout=120)
        assert up, out.text()
        replay = _replay(bag, *replay_args)
        assert _wait_for(lambda: stop_when(out), timeout=180), out.text()
        replaying = replay.poll() is None
        os.killpg(sup.pid, stop_signal)
        sup.wait(timeout=90)
        if replay.poll() is None:  # a replay at real time goes on without the graph: its user stops it too
            replay.send_signal(signal.SIGINT)
        replay_out, _ = replay.communicate(timeout=120)
    finally:
        if sup.poll() is None:
            os.killpg(sup.pid, signal.SIGKILL)
            sup.wait()
    seen = family.close()
    return sup.returncode, out.text(join_timeout=10), replay.returncode, replay_out, seen, replaying


def _settle(count, quiet_s: float = 5.0, timeout_s: float = 60.0, done=lambda: False,
            done_quiet_s: float = 1.0) -> None:
    """Wait until ``count()`` has not changed for ``quiet_s``, or for ``done_quiet_s`` once ``done()``
    holds (at most ``timeout_s``)."""
    end, last, since = time.monotonic() + timeout_s, count(), time.monotonic()
    while time.monotonic() < end and time.monotonic() - since < quiet_s:
        time.sleep(0.2)
        if (now := count()) != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since >= done_quiet_s and done():
            return


def _all_recorded(lines, out: Path) -> bool:
    """Every window ingest published so far has identify's estimate, and the recorder's bag holds each
    window, estimate and (once track has its three reference windows) tracked row."""
    n = lines.count("[ingest]: window")
    if lines.count("[identify]: window") < n:
        return False
    ids = ids_written(out, RESULTS)
    return all(len(ids[t]) >= (n if t != RESULTS[2] or n >= 3 else 0) for t in RESULTS)


def _announced_running(text: str) -> list[int]:
    """The pids the supervisor said it started ("started <node> (pid N)") that still run a node."""
    left = []
    for pid in (int(m) for m in re.findall(r"started \w+ \(pid (\d+)\)", text)):
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if b"shm_ros" in cmdline and state != "Z":
            left.append(pid)
    return left


def _named(text: str, heading: str) -> list[str]:
    """The nodes the supervisor's line starting with ``heading`` names ("may be lost: identify exited
    with -9; track ..." or "recovered from their inputs: identify, track"); [] without that line."""
    line = next((ln.split(heading, 1)[1] for ln in text.splitlines() if heading in ln), "")
    return [part.split()[0].rstrip(",") for part in line.replace(";", ",").split(",") if part.strip()]


def _clean(text: str) -> bool:
    return "Traceback" not in text and "KeyboardInterrupt" not in text and "terminate called" not in text


def _fault_sets() -> list[tuple[str, bool]]:
    """The faults of each run and whether the stop waits until the killed nodes are back: in CI one
    fixed set, stopped once the three are running again (the exit code 0 path); with SHM_FULL=1, 20
    sets whose kill points are drawn from a fixed seed (the recorder's message, identify's and the
    store's window), every other one stopped as soon as the three faults fired (a killed node
    usually still down: exit code 1 naming it)."""
    if not full_size():
        return [pytest.param("bag:write:15,identify:published:1,store:commit:1", True, id="run00")]
    rng = np.random.default_rng(35)
    return [pytest.param(f"bag:write:{rng.integers(5, 40)},identify:published:{rng.integers(1, 3)},"
                         f"store:commit:{rng.integers(1, 3)}", k % 2 == 0, id=f"run{k:02d}") for k in range(20)]



def _up_again(text: str, node: str) -> bool:
    """``node`` was restarted and its latest process is set up and spinning: the up file it writes
    then (the supervisor removes it before each start) exists. The file is named in the process's
    environment (``SHM_EXIT_REASON_FILE``)."""
    from shm_ros.ros.node_main import REASON_FILE_ENV

    pids = re.findall(rf"started {node} \(pid (\d+)\)", text)
    if len(pids) < 2:
        return False
    try:
        env = Path(f"/proc/{pids[-1]}/environ").read_bytes().split(b"\0")
    except OSError:
        return False
    reason = next((e.split(b"=", 1)[1].decode() for e in env if e.startswith(REASON_FILE_ENV.encode() + b"=")), "")
    return bool(reason) and Path(reason + ".up").exists()


class _Recovered:
    """``stop_when`` of a session: the three faults fired, each killed node is running again (set up
    and spinning), and the graph is quiet: every window ingest published is in the track store,
    neither count changed for ``quiet_s``, and the recorder's bag holds each of those windows and its
    estimate (the restarted recorder has taken up what was published while it was down)."""

    def __init__(self, marks: Path, store: Path, out: Path, quiet_s: float = 1.0) -> None:
        self.marks, self.store, self.out, self.quiet_s = marks, store, out, quiet_s
        self.state, self.since = (-1, -1), time.monotonic()

    def __call__(self, lines) -> bool:
        if len(list(self.marks.iterdir())) < 3:
            return False
        text = lines.text()
        if not all(_up_again(text, node) for node in ("identify", "track", "recorder")):
            return False
        state = (lines.count("[ingest]: window"), _estimates_in_store(self.store))
        if state != self.state:
            self.state, self.since = state, time.monotonic()
        if not (1 <= state[0] == state[1] and time.monotonic() - self.since >= self.quiet_s):
            return False
        return all(len(ids) >= state[0] for ids in ids_written(self.out, RESULTS[:2]).values())


@pytest.mark.parametrize(("fault", "recovered"), _fault_sets())
def test_faults_sigterm_during_a_replay_and_ctrl_c_of_the_group_lose_and_duplicate_nothing(tmp_path, fault, recovered):
    from shm_ros.core.tracking import Tracker, TrackingConfig
    from shm_ros.io.sources import open_source
    from shm_ros.ros.graph_run import read_pipeline_bag

    bag = tmp_path / "recording"
    _bag(bag)
    marks = tmp_path / "marks"
    marks.mkdir()
    store = tmp_path / "track.sqlite"
    # 1: faults while a replay runs; SIGTERM to the graph (every process) once all three fired
    faults = {**os.environ, "SHM_FAULT_MARK": str(marks), "SHM_FAULT": fault}
    # stopped once the three faults fired, or once the killed nodes are back (a slower replay, so
    # that it still runs then: the stop cuts it short, it adds no time)
    stop_when = _Recovered(marks, store, tmp_path / "out") if recovered else lambda out: len(list(marks.iterdir())) == 3
    code, text, replay_code, replay_out, seen, replaying = _session(
        tmp_path, bag, faults, stop_when, signal.SIGTERM, "--rate", "0.5" if recovered else "1")
    print(text[-3000:], replay_out[-1000:])
    assert replaying and replay_code != 0, "the graph stopped during the replay: the replay must say so"
    assert re.search(r"stopped by a signal|left the graph|lost [1-9]", replay_out), replay_out
    assert sorted(p.name for p in marks.iterdir()) == ["bag.write", "identify.published", "store.commit"]
    # the exit code follows what was lost: 1 exactly when a killed node was not running again at the
    # stop (the recorder in its back-off, a restart still starting), 0 when the three came back
    # (each node named once, whichever way it died: a restart still starting that the SIGTERM to the
    # group ended is not a second death)
    lost, back = _named(text, "may be lost: "), _named(text, "recovered from their inputs: ")
    assert sorted(lost + back) == ["identify", "recorder", "track"], text
    assert code == (1 if lost else 0) and "all nodes stopped" in text, text
    if text.count("[recorder]: recording to") < 2:
        assert "recorder" in lost, text
    if recovered:  # each back and spinning at the stop: nothing lost, the exit code 0
        assert code == 0 and lost == [] and sorted(back) == ["identify", "recorder", "track"], text
    assert _clean(text), text
    # the four, and the recorder again when its restart came before the stop (its back-off is 2 s);
    # a restart just before the stop may live shorter than the watcher's poll: the announced pids count
    assert len(seen) >= 4 and _still_running(seen) == [] and _announced_running(text) == [], text
    # the recorder ran again and opened the bag before the stop: it closed the bag. A restart stopped
    # while it still started (before "recording to") leaves the split cut short for the next start
    if text.count("[recorder]: recording to") >= 2:
        assert open_source(tmp_path / "out").note == "", "the bag must be complete after the stop"
        first = read_pipeline_bag(tmp_path / "out")
        for ids in ([w.window_id for w in first.windows], [e.window_id for e in first.estimates],
                    [r["window_id"] for r in first.tracked]):
            assert max(collections.Counter(ids).values(), default=0) <= 1, ids
        if recovered:  # every window published before the stop: recorded, estimated and stored (ingest
            # publishes what it still holds as it closes: those may come after the others stopped)
            before = sorted(w.window_id for w in first.windows)[:stop_when.state[0]]  # ids sort in time
            assert len(before) == stop_when.state[0] >= 1, (stop_when.state, text)
            assert set(before) <= {e.window_id for e in first.estimates}, first.estimates
            assert {r["window_id"] for r in first.tracked} <= {w.window_id for w in first.windows}
            assert _estimates_in_store(store) >= len(before)
    else:  # stopped while the recorder waited for its restart: its split cut short waits for the next
        assert list((tmp_path / "out").glob("out_*/out_*.mcap")), "the split cut short must be kept"
    # 2: rerun (no faults): the same bag again resumes; then Ctrl-C to the whole process group
    # stopped once the store holds every window and the recorder's bag every window, estimate and
    # tracked row (it writes each message through to its file): what comes after is a duplicate at most
    code2, text2, replay_code2, replay_out2, seen2, _ = _session(
        tmp_path, bag, dict(os.environ), lambda out: _estimates_in_store(store) == N_WINDOWS and all(
            len(ids) >= N_WINDOWS for ids in ids_written(tmp_path / "out", RESULTS).values()), signal.SIGINT)
    print(text2[-3000:], replay_out2[-1000:])
    assert code2 == 0 and "exit code 0" in text2, text2  # nothing died, nothing lost
    assert replay_code2 == 0 and "lost 0" in replay_out2, replay_out2
    assert _clean(text2) and _still_running(seen2) == [], text2
    source = open_source(tmp_path / "out")
    assert source.note == "", source.note
    assert len(list((tmp_path / "out").glob("*.mcap"))) >= 2  # splits: the killed one, (its restart,) the rerun
    rec = read_pipeline_bag(tmp_path / "out")
    windows = [w.window_id for w in rec.windows]
    estimates = [e.window_id for e in rec.estimates]
    tracked = [r["window_id"] for r in rec.tracked]
    for name, ids in (("windows", windows), ("estimates", estimates), ("tracked rows", tracked)):
        dup = [k for k, c in collections.Counter(ids).items() if c > 1]
        assert not dup, f"{name} recorded twice: {dup}"
        assert len(ids) == N_WINDOWS, f"{name}: {len(ids)} of {N_WINDOWS}"
    assert set(windows) == set(estimates) == set(tracked)
    assert _estimates_in_store(store) == N_WINDOWS
    # the tracked rows equal those of an undisturbed tracking of the same estimates, in order
    tracker = Tracker(TrackingConfig(reference_windows=3))
    truth = {}
    for est in sorted(rec.estimates, key=lambda e: e.start_ns):
        for row in tracker.add(est):
            truth[row.window_id] = row
    assert set(truth) == set(tracked)
    for r in rec.tracked:
        want = truth[r["window_id"]]
        assert r["mode_numbers"] == [int(k) for k in want.mode_numbers], r["window_id"]
        np.testing.assert_allclose(r["frequencies_hz"], want.frequencies_hz, rtol=1e-12, equal_nan=True)


class _Recorded:
    """``stop_when`` of a session: every window published by ingest, and each in the recorder's bag
    (it writes each message through to its file; recording the windows only)."""

    def __init__(self, out: Path) -> None:
        self.out = out

    def __call__(self, lines) -> bool:
        return lines.count("[ingest]: window") >= N_WINDOWS and len(
            ids_written(self.out, RESULTS[:1])[RESULTS[0]]) >= N_WINDOWS


def test_the_recorder_killed_as_it_closes_its_bag_at_a_ctrl_c_keeps_every_window_for_the_next_start(tmp_path):
    """``recorder:close``: Ctrl-C to the process group after a replay, and the recorder dies
    (SIGKILL) before it closes its bag: its split has no footer and the bag's ``metadata.yaml`` does
    not list it. The graph exits 1 naming the recorder only; no traceback; nothing left running.
    Every window it received is on disk: the next writer on the bag (the first thing a restarted
    recorder does) takes the split up, and the bag opens without salvage with every window once.
    (Ingest and the recorder only: the other nodes add nothing to this point.)"""
    from shm_ros.io.bag_splits import SplitBagWriter
    from shm_ros.io.sources import open_source
    from shm_ros.ros.graph_run import read_pipeline_bag

    bag = tmp_path / "recording"
    _bag(bag)
    marks = tmp_path / "marks"
    marks.mkdir()
    env = {**os.environ, "SHM_FAULT_MARK": str(marks), "SHM_FAULT": "recorder:close"}
    code, text, replay_code, replay_out, seen, _ = _session(
        tmp_path, bag, env, _Recorded(tmp_path / "out"), signal.SIGINT, only=("ingest", "recorder"),
        extra={"recorder": {"topics": ["shm/windows"]}})
    print(text[-3000:], replay_out[-1000:])
    assert replay_code == 0 and "lost 0" in replay_out, replay_out
    assert sorted(p.name for p in marks.iterdir()) == ["recorder.close"]
    assert code == 1 and _named(text, "may be lost: ") == ["recorder"], text
    # (dead in its stop, or just before the supervisor's own stop saw it: both a Ctrl-C to the group)
    assert re.search(r"may be lost: recorder (stopped with exit code|exited with) -9", text), text
    assert _clean(text) and len(seen) >= 2 and _still_running(seen) == [] and _announced_running(text) == [], text
    cut = list((tmp_path / "out").glob("out_*/out_*.mcap"))
    assert cut and cut[0].stat().st_size > 0, "the recorder died before it closed: its split cut short is kept"
    writer = SplitBagWriter(tmp_path / "out").open()  # what the next recorder on the bag does first
    assert writer.recovered, "the split cut short must be taken up"
    writer.close()
    assert open_source(tmp_path / "out").note == ""
    windows = [w.window_id for w in read_pipeline_bag(tmp_path / "out").windows]
    assert len(windows) == len(set(windows)) == N_WINDOWS, windows


def test_killing_the_supervisor_leaves_no_node_running(tmp_path):
    from shm_ros.io.sources import open_source

    config = _config(tmp_path, only=("ingest", "recorder"))  # each node asks for the same signal
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = _Lines(sup)
    try:
        up = _wait_for(lambda: out.count("[recorder]:") and out.count("[ingest]:"), timeout=120)
        assert up, out.text()
        kids = _identity(_children(sup.pid))
        assert len(kids) == 2
        sup.kill()
        sup.wait()
        gone = _wait_for(lambda: _still_running(kids) == [], timeout=30)
    finally:
        if sup.poll() is None:
            sup.kill()
    assert gone, f"left running after the supervisor was killed: {_still_running(kids)}"
    # the recorder was ended by its parent-death signal (SIGTERM): it closed its bag
    assert open_source(tmp_path / "out").note == ""


def test_a_node_with_a_bad_configuration_stops_the_graph_with_its_reason(tmp_path):
    config = _config(tmp_path, only=("identify", "recorder"), identify={"structure": str(tmp_path / "missing.yaml")})
    started = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                         capture_output=True, text=True, timeout=180)
    text = run.stdout + run.stderr
    assert run.returncode == 2, text
    assert "identify cannot go on" in text and "missing.yaml" in text, text
    assert text.count("started identify") == 1, "not restarted"
    assert "restarting" not in text
    assert time.monotonic() - started < 120


def test_a_full_disk_stops_the_recorder_and_the_graph_and_keeps_what_was_recorded(tmp_path):
    """``recorder:enospc:5``: the recorder's 5th write fails as on a full disk."""
    from shm_ros.io.bags import read_messages
    from shm_ros.io.sources import open_source

    config = _config(tmp_path, only=("ingest", "identify", "recorder"))  # their diagnostics are recorded
    env = {**os.environ, "SHM_FAULT": "recorder:enospc:5"}
    run = subprocess.run([sys.executable, "-m", "shm_ros.cli", "run", str(config)],
                         capture_output=True, text=True, timeout=180, env=env)
    text = run.stdout + run.stderr
    assert run.returncode == 2, text
    assert "recorder cannot go on" in text and "no space left on the device: recording stopped; the 4 " \
        "messages recorded before are kept" in text, text
    assert "restarting" not in text and _clean(text), text
    assert open_source(tmp_path / "out").note == ""
    assert len(list(read_messages(tmp_path / "out"))) == 4


def test_a_replay_goes_on_after_an_ingest_restart_and_counts_what_was_lost(tmp_path):
    """Ingest killed after its second window: the replay does not wait out its drain for
    acknowledgements that cannot come; it goes on with the restarted ingest, says that what the dead
    process held is lost, and exits 1."""
    from shm_ros.io.sources import open_source
    from shm_ros.ros.graph_run import read_pipeline_bag

    bag = tmp_path / "recording"
    _bag(bag)
    marks = tmp_path / "marks"
    marks.mkdir()
    env = {**os.environ, "SHM_FAULT_MARK": str(marks), "SHM_FAULT": "ingest:published:2"}
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(_config(tmp_path))],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    out = _Lines(sup)
    try:
        up = _wait_for(lambda: all(out.count(f"[{n}]:") for n in ("ingest", "identify", "track", "recorder")),
                       timeout=120)
        assert up, out.text()
        started = time.monotonic()
        replay = subprocess.run(_replay_args(bag, "--rate", "2"), capture_output=True, text=True, timeout=400)
        took = time.monotonic() - started
        # identify done with what reached it: quiet for 5 s, or sooner once every window ingest published
        # has its estimate and all are in the recorder's bag, tracked too once track has its reference
        _settle(lambda: out.count("[identify]: window"), done=lambda: _all_recorded(out, tmp_path / "out"))
        sup.send_signal(signal.SIGINT)
        sup.wait(timeout=90)
    finally:
        if sup.poll() is None:
            sup.kill()
            sup.wait()
    text = out.text(join_timeout=10)
    print(replay.stdout[-800:], text[-2000:])
    assert (marks / "ingest.published").exists()
    assert "the ingest node restarted 1 time(s) during the replay" in replay.stderr, replay.stdout + replay.stderr
    assert replay.returncode == 1, replay.stdout
    assert took < 200, f"the replay waited {took:.0f} s"
    assert sup.returncode == 1 and _clean(text), text
    assert open_source(tmp_path / "out").note == ""
    rec = read_pipeline_bag(tmp_path / "out")
    # every window and estimate once; tracked rows once too, and there are some when the three
    # reference windows reached track (a loaded machine may start the new ingest after the last block)
    for ids in ([w.window_id for w in rec.windows], [e.window_id for e in rec.estimates],
                [r["window_id"] for r in rec.tracked]):
        assert max(collections.Counter(ids).values(), default=1) == 1, ids
    assert rec.windows and rec.estimates and (rec.tracked or len(rec.estimates) < 3), rec.estimates
