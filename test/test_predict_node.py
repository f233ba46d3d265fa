"""The predict node in the graph, over DDS: a simulated earthquake bag replayed through the real
ingest node into the predict node (given a posterior file) gives one ResponsePrediction per event
window, equal (same seed) to the numbers of ``shm-ros predict`` on the same bag and posterior
within 1e-9: the NRMS of ``prediction.json``, and the predictive mean and standard deviation of
``predict_windows`` (the function the command runs) sample by sample. The posterior is calibrated on
two events, whose window files the node and the command are given (``calibration_windows``,
``--calibration-windows``): both learn the model error out of sample (leave one event out), and the
node's ``prediction.json`` says so with the command's figures."""

from __future__ import annotations

import json

import numpy as np

from shm_ros.cli import main
from shm_ros.commands.predict import predict_windows
from shm_ros.core.bayes.records import RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.core.models import build_model
from shm_ros.core.predict import PredictConfig, event_from_window
from shm_ros.core.predict.signals import baseline_correct, pre_event_end
from shm_ros.io.posterior_files import write_posterior
from shm_ros.io.recording import windows_from_bag
from shm_ros.io.structure import load_structure
from shm_ros.io.window_files import save_window
from shm_ros.report.load import load_posterior
from shm_ros.ros.graph_run import replay_through_graph

WINDOW_S, N_DRAWS, SEED = 20.0, 20, 3


def _posterior(model, spec, windows, out):
    """A short time-domain calibration on some events: only that node and command read the same
    file matters here, not how well it is converged."""
    recs = []
    for window in windows:
        ev = event_from_window(window, model)
        k = pre_event_end(ev.inputs[0], ev.fs, 0.001, 1.0)
        recs.append(AccelerationRecord(1 / ev.fs, baseline_correct(ev.inputs.T, k, "mean").T,
                                       baseline_correct(ev.outputs, k, "mean"), ev.channel_ids))
    post = update(model, RecordSet(recs), UpdateConfig(likelihood="time", n_chains=8, n_steps=40, max_steps=40,
                                                       evidence=False, ess_target=10, rhat_target=2.0),
                  spec.parameters)
    write_posterior(out, post, {})
    return out


def test_predict_node_in_the_graph_matches_cli(tmp_path):
    d = tmp_path / "quake"
    assert main(["simulate", "building-earthquake", "--out", str(d), "--windows", "4", "--window-s",
                 str(WINDOW_S), "--quiet", "--seed", "3"]) == 0  # a seed whose windows ingest flags 3 of 4
    s_path, bag = d / "structure.yaml", d / "bag"
    spec = load_structure(s_path)
    model = build_model(spec)
    windows, _ = windows_from_bag(bag, spec, WINDOW_S)
    events = [w for w in windows if w.is_event]
    assert 2 <= len(events) < len(windows)  # quiet windows too: they must not be predicted
    post = _posterior(model, spec, events[:2], tmp_path / "post")
    cal = [str(tmp_path / f"cal{i}.npz") for i in range(2)]
    for p, w in zip(cal, events[:2], strict=True):
        save_window(p, w)

    assert main(["predict", "--structure", str(s_path), "--posterior", str(post), "--bag", str(bag), "--window",
                 str(WINDOW_S), "--out", str(tmp_path / "cli"), "--no-plots", "--n-draws", str(N_DRAWS),
                 "--seed", str(SEED), "--calibration-windows", *cal]) == 0
    cli = {e["window_id"]: e for e in json.loads((tmp_path / "cli" / "prediction.json").read_text())["events"]}
    assert sorted(cli) == sorted(w.window_id for w in events)
    preds, errors = predict_windows(model, events, load_posterior(post), PredictConfig(n_draws=N_DRAWS, seed=SEED),
                                    events[:2])
    assert not errors
    ref = {p.window_id: p for p in preds}

    run = replay_through_graph(bag, s_path, tmp_path / "graph", window_s=WINDOW_S, expected_windows=len(windows),
                               identify={"uncertainty": False},
                               predict={"posterior": str(post), "n_draws": N_DRAWS, "seed": SEED,
                                        "calibration_windows": cal, "output_dir": str(tmp_path / "node")},
                               expected_predictions=len(events), timeout_s=240.0)
    node = {e["window_id"]: e for e in json.loads((tmp_path / "node" / "prediction.json").read_text())["events"]}
    assert sorted(node) == sorted(cli)
    for wid, e in node.items():  # the node learnt the model error out of sample, as the command did
        me, want = e["model_error"], cli[wid]["model_error"]
        assert me is not None and me["method"] == "leave-one-event-out" and len(me["folds"]) == 2
        assert me["relative_error"] == want["relative_error"] and me["relative_error"] != {}
    got = run.predictions
    assert sorted(m["window_id"] for m in got) == sorted(cli), [m["window_id"] for m in got]  # one per event
    for m in got:
        ev, p = cli[m["window_id"]], ref[m["window_id"]]
        names = [c["name"] for c in ev["channels"]]
        assert m["channel_names"] == names and m["n_samples"] == p.channels[0].mean.size
        by = {c["name"]: c for c in ev["channels"]}
        for name, v in zip(names, m["nrms_pct"], strict=True):
            if by[name]["measured"]:
                assert np.isfinite(v) and abs(v - by[name]["nrms_pct"]) < 1e-9, (name, v, by[name]["nrms_pct"])
            else:
                assert np.isnan(v)
        for key, attr in (("predicted_mean", "mean"), ("predicted_std", "std")):
            want = np.column_stack([getattr(c, attr) for c in p.channels])
            have = np.asarray(m[key]).reshape(want.shape)
            assert np.max(np.abs(have - want)) <= 1e-9 * np.max(np.abs(want)), key


def test_bad_calibration_windows_name_the_parameter_and_the_file(tmp_path):
    """One event, or a file that is no window, stops the node at its start with the parameter's name."""
    import pytest

    from shm_ros.ros.params import ParameterError
    from shm_ros.ros.predict_node import _check_calibration

    with pytest.raises(ParameterError, match="'calibration_windows': give two or more"):
        _check_calibration("predict", (str(tmp_path / "a.npz"),))
    bad = tmp_path / "not_a_window.npz"
    bad.write_bytes(b"not a window")
    with pytest.raises(ParameterError, match=r"predict: parameter 'calibration_windows': .*not_a_window"):
        _check_calibration("predict", (str(bad), str(bad)))
