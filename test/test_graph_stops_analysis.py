"""Crashes of the analysis nodes lose and duplicate nothing (real node processes, real DDS).

A small building campaign with a measured ground input (four 30-s windows, an earthquake in the
last) is replayed through `shm-ros run` (ingest, identify, track with its store, update, predict,
explain, recorder; restarts on) with the test hook (``SHM_FAULT``, :mod:`shm_ros.io.faults`)
killing update after it published its posterior, predict after it published its prediction and
explain after it published its verdict. Each killed node is restarted by the supervisor and takes
up what it had from its inputs' history (track's rows, ingest's windows). A probe on the result
topics keeps every publication: what each node published before it was killed is its undisturbed
result (its inputs were not disturbed: track and ingest ran on), and what its restart published
must equal it: the same verdict, the posterior within 0.1 posterior sd, the same prediction. The
recorded bag opens without salvage and holds every window, modal estimate, tracked row and
prediction once, and the posterior and verdict once each; the graph exits 0 (every killed node
came back and lost nothing: the exit code says that nothing was lost) and nothing is left running.
Samplers as short as the namespaces test's (150 steps).
With ``SHM_FULL=1`` the same bag is then replayed again into a fresh graph on the same store and
output bag: nothing recorded twice, the same results.
"""

from __future__ import annotations

import collections
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml
from conftest import full_size
from test_graph_stops import _announced_running, _clean, _Family, _replay
from test_supervisor import _Lines, _still_running, _wait_for

N_WINDOWS, WINDOW_S = 4, 30.0
SCENARIO = {"scenario": "building", "n_windows": N_WINDOWS, "window_s": WINDOW_S, "pause_s": 600.0, "seed": 7,
            "earthquakes": [{"window": 3, "pga_m_s2": 1.0, "onset_s": 10.0}]}
FAULTS = "update:published:1,predict:published:1,explain:published:1"


def _simulate(tmp_path: Path) -> Path:
    from shm_ros.cli import main

    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(yaml.safe_dump(SCENARIO))
    sim = tmp_path / "sim"
    assert main(["simulate", "--scenario-file", str(scenario), "--out", str(sim), "--quiet"]) == 0
    return sim


def _config(work: Path, structure: Path) -> Path:
    s = str(structure)
    every = {"min_windows": N_WINDOWS, "min_new_windows": N_WINDOWS}  # one run each, on every window
    nodes = {
        "ingest": {"structure": s, "window_s": WINDOW_S},
        "identify": {"structure": s, "uncertainty": False},
        "track": {"store": str(work / "track.sqlite"), "reference_windows": 3, "training_windows": 3},
        "update": {"structure": s, **every, "evidence": False, "n_steps": 150, "max_steps": 150,
                   "output_dir": str(work / "update")},
        "predict": {"structure": s, "n_draws": 10, "wait_for_posterior_s": 600.0, "posterior": str(work / "update"),
                    "output_dir": str(work / "prediction")},
        "explain": {"structure": s, **every, "events": "off", "nested_check": False, "prior_sensitivity": False,
                    "second_round": False, "n_importance": 200},
        "recorder": {"output": str(work / "out")},
    }
    config = work / "graph.yaml"
    config.write_text(yaml.safe_dump({"graph": {"mode": "processes", "restart": True},
                                      "nodes": {k: {"parameters": v} for k, v in nodes.items()}}))
    return config


RESULTS = {"shm/posterior": "latched", "shm/verdict": "latched", "shm/prediction": "stream"}
_PROBE = r"""
import json, sys
import rclpy
from rclpy.signals import SignalHandlerOptions
from shm_ros.ros import topics
from shm_ros.ros.node_main import StopSignals
from shm_ros.ros.qos import latched_qos, stream_qos
results = json.loads(sys.argv[1])
with StopSignals() as stop:
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("test_results_probe")
    for name, qos in results.items():
        kind = topics.TYPES[name]
        node.create_subscription(
            topics.message_class(kind), name,
            lambda data, name=name, kind=kind: print(json.dumps([name, kind, bytes(data).hex()]), flush=True),
            latched_qos() if qos == "latched" else stream_qos(), raw=True)
    ready = False
    while not stop.stopping:
        rclpy.spin_once(node, timeout_sec=0.1)
        if not ready and all(node.count_publishers(name) for name in results):
            print("ready", flush=True)
            ready = True
    node.destroy_node()
    rclpy.try_shutdown()
"""


def _published(lines: list[str], work: Path):
    """Every result the probe received, in order, decoded as the recorded bag is."""
    import json

    from shm_ros.io.bags import BagWriter
    from shm_ros.ros.graph_run import read_pipeline_bag

    with BagWriter(work / "published") as w:
        for t, line in enumerate(ln for ln in lines if ln.startswith("[")):
            topic, kind, data = json.loads(line)
            w.write_cdr("/" + topic, kind, t + 1, bytes.fromhex(data))
    return read_pipeline_bag(work / "published")


def _graph(sim: Path, work: Path, env: dict[str, str]) -> tuple[int, str, str, dict[int, int], list[str]]:
    """Run the graph on the recording until update, predict and explain are done with it (their
    restarted processes, when killed), then Ctrl-C to the supervisor; (exit code, its output, the
    replay's output, every process seen, the probe's lines: every result published)."""
    work.mkdir(exist_ok=True)  # a rerun: the same store and output bag
    (work / "prediction" / "prediction.json").unlink(missing_ok=True)
    config = _config(work, sim / "structure.yaml")
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config)], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, env=env)
    out = _Lines(sup)
    family = _Family(sup.pid)
    probe = subprocess.Popen([sys.executable, "-c", _PROBE, json.dumps(RESULTS)], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    probed = _Lines(probe)
    replay = None
    try:
        up = _wait_for(lambda: all(out.count(f"[{n}]:") for n in ("ingest", "identify", "track", "recorder"))
                       and probed.count("ready"), timeout=180)  # the probe sees update, predict, explain
        assert up, out.text() + probed.text()
        replay = _replay(sim / "bag")
        # each logs after its publication (a node killed there does not): the last process of each is done
        done = _wait_for(lambda: out.count(f"[update]: posterior from {N_WINDOWS} windows")
                         and out.count(f"[explain]: verdict from {N_WINDOWS} windows")
                         and (work / "prediction" / "prediction.json").exists(), timeout=600)
        assert done, out.text()
        time.sleep(2.0)  # the recorder and the probe take the last messages
        sup.send_signal(signal.SIGINT)
        sup.wait(timeout=90)
        replay_out, _ = replay.communicate(timeout=120)
        probe.send_signal(signal.SIGINT)
        probe.wait(timeout=30)
    finally:
        for proc in (sup, replay, probe):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return sup.returncode, out.text(join_timeout=10), replay_out, family.close(), probed.lines


def _bag(work: Path):
    from shm_ros.io.sources import open_source
    from shm_ros.ros.graph_run import read_pipeline_bag

    assert open_source(work / "out").note == "", "the bag must open without salvage"
    return read_pipeline_bag(work / "out")


def test_update_predict_and_explain_killed_after_publishing_come_back_with_the_same_results(tmp_path):
    sim = _simulate(tmp_path)
    marks = tmp_path / "marks"
    marks.mkdir()
    env = {**os.environ, "SHM_FAULT": FAULTS, "SHM_FAULT_MARK": str(marks)}
    work = tmp_path / "faulted"
    code, text, replay_out, seen, probed = _graph(sim, work, env)
    print(text[-4000:], replay_out[-500:])
    # every fault fired, each node was restarted once and nothing else died
    assert sorted(p.name for p in marks.iterdir()) == ["explain.published", "predict.published",
                                                       "update.published"]
    for node in ("update", "predict", "explain"):
        assert f"{node} exited with -9; restarting" in text, text
    assert text.count("restarting in") == 3, text
    # nothing was lost (each came back and took up its inputs' history): exit code 0, said so
    assert code == 0 and "exit code 0" in text and "may be lost" not in text, text
    recovered = text.split("recovered from their inputs: ")[-1].splitlines()[0]
    assert sorted(recovered.split(", ")) == ["explain", "predict", "update"], text
    assert _clean(text), text
    assert len(seen) >= 10 and _still_running(seen) == [] and _announced_running(text) == [], text

    # what each killed node published before its kill (undisturbed) and what its restart published
    published = _published(probed, tmp_path)
    recorded = _bag(work)
    _once(recorded)
    _restart_repeats(published, recorded)
    if full_size():  # a rerun of the same bag on the same store and output bag changes nothing
        code, text, replay_out, seen, again = _graph(sim, work, dict(os.environ))
        print(text[-3000:], replay_out[-500:])
        assert code == 0 and _clean(text) and _still_running(seen) == [], text
        skipped = re.search(r"\[recorder\]: recorded \d+ messages \((\d+) duplicates skipped\)", text)
        assert skipped and int(skipped.group(1)) >= 3 * N_WINDOWS, text  # windows, estimates, rows again
        rerun = _bag(work)
        _once(rerun)
        _same_results(recorded, rerun)


def _close(a, b) -> bool:
    """Equal, numbers to 1e-9 relative (NaN equal to NaN)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) or (math.isnan(a) and math.isnan(b))
    return a == b


def _once(rec) -> None:
    """Every window's outputs once in the bag; the posterior and the verdict once each (a node
    publishing the same result again is recorded once)."""
    for name, ids in (("windows", [w.window_id for w in rec.windows]),
                      ("estimates", [e.window_id for e in rec.estimates]),
                      ("tracked rows", [r["window_id"] for r in rec.tracked]),
                      ("predictions", [p["window_id"] for p in rec.predictions])):
        assert max(collections.Counter(ids).values(), default=0) == 1, (name, ids)
    assert len(rec.windows) == len(rec.estimates) == len(rec.tracked) == N_WINDOWS
    assert {w.window_id for w in rec.windows} == {e.window_id for e in rec.estimates} == {
        r["window_id"] for r in rec.tracked}
    assert len(rec.predictions) == 1 and len(rec.posteriors) == 1, (rec.predictions, rec.posteriors)
    assert len([v for v in rec.verdicts if v["kind"] == "modes"]) == 1, rec.verdicts


def _restart_repeats(published, recorded) -> None:
    """Each result was published by the killed process and again by its restart (at least twice),
    and every publication equals the first, the killed process's: the verdict in every field, the
    prediction to 1e-9, the posterior means within 0.1 posterior sd; the bag holds that result."""
    verdicts = [v for v in published.verdicts if v["kind"] == "modes"]
    for name, results in (("posteriors", published.posteriors), ("predictions", published.predictions),
                          ("verdicts", verdicts)):
        assert len(results) >= 2, f"{name}: {len(results)} published, the killed process's and its restart's expected"
    for post in published.posteriors[1:]:
        _same_posterior(published.posteriors[0], post)
    for pred in published.predictions[1:]:
        _same_prediction(published.predictions[0], pred)
    for verdict in verdicts[1:]:
        assert _close(verdict, verdicts[0]), (verdict, verdicts[0])
    _same_results(published, recorded)


def _same_posterior(p: dict, q: dict) -> None:
    """``q``'s means within 0.1 of ``p``'s posterior sd."""
    assert p["n_windows"] == q["n_windows"] == N_WINDOWS and set(p["parameters"]) == set(q["parameters"])
    for name, est in p["parameters"].items():
        assert abs(q["parameters"][name]["mean"] - est["mean"]) <= 0.1 * est["std"], (name, est, q["parameters"][name])


def _same_prediction(p: dict, q: dict) -> None:
    assert q["window_id"] == p["window_id"] and q["channel_names"] == p["channel_names"]
    np.testing.assert_allclose(q["predicted_mean"], p["predicted_mean"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(q["predicted_std"], p["predicted_std"], rtol=1e-9, atol=1e-12)


def _same_results(ref, got) -> None:
    """``got``'s posterior, prediction and modal verdict equal ``ref``'s (the posterior within 0.1
    posterior sd)."""
    _same_posterior(ref.posteriors[0], got.posteriors[0])
    _same_prediction(ref.predictions[0], got.predictions[0])
    modes = [[v for v in rec.verdicts if v["kind"] == "modes"][0] for rec in (ref, got)]
    assert _close(modes[1], modes[0]), (modes[1], modes[0])
