"""Crashes of the analysis nodes lose and duplicate nothing (real node processes, real DDS).

A small building campaign with a measured ground input (four 30-s windows, an earthquake in the
last) is replayed through `shm-ros run` (ingest, identify, track with its store, update, predict,
explain, recorder; restarts on) twice: once undisturbed, once with the test hook
(``SHM_FAULT``, :mod:`shm_ros.io.faults`) killing update after it published its posterior,
predict after it published its prediction and explain after it published its verdict. Each killed
node is restarted by the supervisor and takes up what it had from its inputs' history (track's
rows, ingest's windows). The faulted run must end as the undisturbed one: the same verdict, the
posterior within 0.1 posterior sd, the same prediction (the undisturbed run has every node in one
process: less start-up, and the results do not depend on the layout); the recorded bag opens
without salvage and holds every window, modal estimate, tracked row and prediction once, and the
posterior and verdict once each; the graph exits 0 (every killed node came back and lost nothing:
the exit code says that nothing was lost) and nothing is left running. Samplers as short as the
namespaces test's (150 steps).
With ``SHM_FULL=1`` the same bag is then replayed again into a fresh graph on the same store and
output bag: nothing recorded twice, the same results.
"""

from __future__ import annotations

import collections
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


def _config(work: Path, structure: Path, mode: str) -> Path:
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
    config.write_text(yaml.safe_dump({"graph": {"mode": mode, "restart": True},
                                      "nodes": {k: {"parameters": v} for k, v in nodes.items()}}))
    return config


def _graph(sim: Path, work: Path, env: dict[str, str],
           mode: str = "processes") -> tuple[int, str, str, dict[int, int]]:
    """Run the graph on the recording until update, predict and explain are done with it (their
    restarted processes, when killed), then Ctrl-C to the supervisor; (exit code, its output, the
    replay's output, every process seen)."""
    work.mkdir(exist_ok=True)  # a rerun: the same store and output bag
    (work / "prediction" / "prediction.json").unlink(missing_ok=True)
    config = _config(work, sim / "structure.yaml", mode)
    sup = subprocess.Popen([sys.executable, "-m", "shm_ros.cli", "run", str(config)], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, env=env)
    out = _Lines(sup)
    family = _Family(sup.pid)
    replay = None
    try:
        up = _wait_for(lambda: all(out.count(f"[{n}]:") for n in ("ingest", "identify", "track", "recorder")),
                       timeout=180)
        assert up, out.text()
        replay = _replay(sim / "bag")
        # each logs after its publication (a node killed there does not): the last process of each is done
        done = _wait_for(lambda: out.count(f"[update]: posterior from {N_WINDOWS} windows")
                         and out.count(f"[explain]: verdict from {N_WINDOWS} windows")
                         and (work / "prediction" / "prediction.json").exists(), timeout=600)
        assert done, out.text()
        time.sleep(2.0)  # the recorder takes the last messages
        sup.send_signal(signal.SIGINT)
        sup.wait(timeout=90)
        replay_out, _ = replay.communicate(timeout=120)
    finally:
        for proc in (sup, replay):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return sup.returncode, out.text(join_timeout=10), replay_out, family.close()


def _bag(work: Path):
    from shm_ros.io.sources import open_source
    from shm_ros.ros.graph_run import read_pipeline_bag

    assert open_source(work / "out").note == "", "the bag must open without salvage"
    return read_pipeline_bag(work / "out")


def test_update_predict_and_explain_killed_after_publishing_come_back_with_the_same_results(tmp_path):
    sim = _simulate(tmp_path)
    # the reference: every node in one process (less start-up; results do not depend on the layout)
    ref_code, ref_text, ref_replay, ref_seen = _graph(sim, tmp_path / "reference", dict(os.environ), "single")
    print(ref_text[-2000:], ref_replay[-500:])
    assert ref_code == 0 and _clean(ref_text), ref_text
    assert _still_running(ref_seen) == [] and _announced_running(ref_text) == []
    marks = tmp_path / "marks"
    marks.mkdir()
    env = {**os.environ, "SHM_FAULT": FAULTS, "SHM_FAULT_MARK": str(marks)}
    code, text, replay_out, seen = _graph(sim, tmp_path / "faulted", env)
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

    ref = _bag(tmp_path / "reference")
    _same_results(ref, _bag(tmp_path / "faulted"))
    if full_size():  # a rerun of the same bag on the same store and output bag changes nothing
        code, text, replay_out, seen = _graph(sim, tmp_path / "faulted", dict(os.environ))
        print(text[-3000:], replay_out[-500:])
        assert code == 0 and _clean(text) and _still_running(seen) == [], text
        skipped = re.search(r"\[recorder\]: recorded \d+ messages \((\d+) duplicates skipped\)", text)
        assert skipped and int(skipped.group(1)) >= 3 * N_WINDOWS, text  # windows, estimates, rows again
        _same_results(ref, _bag(tmp_path / "faulted"))


def _close(a, b) -> bool:
    """Equal, numbers to 1e-9 relative (NaN equal to NaN)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12) or (math.isnan(a) and math.isnan(b))
    return a == b


def _same_results(ref, got) -> None:
    """Every window's outputs once in both bags; the posterior and the verdict once each (a node
    publishing the same result again is recorded once); ``got``'s results equal ``ref``'s."""
    for rec in (ref, got):
        for name, ids in (("windows", [w.window_id for w in rec.windows]),
                          ("estimates", [e.window_id for e in rec.estimates]),
                          ("tracked rows", [r["window_id"] for r in rec.tracked]),
                          ("predictions", [p["window_id"] for p in rec.predictions])):
            assert max(collections.Counter(ids).values(), default=0) == 1, (name, ids)
        assert len(rec.windows) == len(rec.estimates) == len(rec.tracked) == N_WINDOWS
        assert len(rec.predictions) == 1 and len(rec.posteriors) == 1, (rec.predictions, rec.posteriors)
        assert len([v for v in rec.verdicts if v["kind"] == "modes"]) == 1, rec.verdicts
    assert [w.window_id for w in got.windows] == [w.window_id for w in ref.windows]
    # the tracked modes, the verdict and the prediction equal the undisturbed run's
    for x, y in zip(ref.tracked, got.tracked, strict=True):
        assert x["mode_numbers"] == y["mode_numbers"]
        np.testing.assert_allclose(y["frequencies_hz"], x["frequencies_hz"], rtol=1e-12, equal_nan=True)
    assert _close(got.verdicts, ref.verdicts), (got.verdicts, ref.verdicts)
    assert got.predictions[0]["window_id"] == ref.predictions[0]["window_id"]
    np.testing.assert_allclose(got.predictions[0]["predicted_mean"], ref.predictions[0]["predicted_mean"],
                               rtol=1e-9, atol=1e-12)
    # the posterior of the restarted update within 0.1 posterior sd of the undisturbed one
    p, q = ref.posteriors[0], got.posteriors[0]
    assert p["n_windows"] == q["n_windows"] == N_WINDOWS and set(p["parameters"]) == set(q["parameters"])
    for name, est in p["parameters"].items():
        assert abs(q["parameters"][name]["mean"] - est["mean"]) <= 0.1 * est["std"], (name, est, q["parameters"][name])
