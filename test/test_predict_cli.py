"""`shm-ros predict` on window files: prediction.json (docs/interfaces.md §7), the Table-3 text,
figures; with a posterior of a joint time-domain calibration it beats the nominal model."""

from __future__ import annotations

import json

import numpy as np
import yaml
from predict_synth import simulate_quakes

from shm_ros.cli import main
from shm_ros.core.bayes.records import RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.core.models import build_model
from shm_ros.core.predict import event_from_window
from shm_ros.core.predict.signals import baseline_correct, pre_event_end
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.posterior_files import write_posterior
from shm_ros.io.window_files import save_window


def test_predict_cli(tmp_path, capsys):
    q = simulate_quakes(4, 3, duration_s=40.0, fs=40.0, sensor_floors=(4, 7, 8))
    s_path = tmp_path / "s.yaml"
    s_path.write_text(yaml.safe_dump(q.structure))
    files = []
    for i, w in enumerate(q.windows):
        files.append(tmp_path / f"w{i}.npz")
        save_window(files[-1], w)
    spec = structure_from_dict(q.structure)
    model = build_model(spec)
    recs = []
    for w in q.windows[:2]:
        ev = event_from_window(w, model)
        k = pre_event_end(ev.inputs[0], ev.fs, 0.001, 1.0)
        recs.append(AccelerationRecord(1 / ev.fs, baseline_correct(ev.inputs.T, k, "mean").T,
                                       baseline_correct(ev.outputs, k, "mean"), ev.channel_ids))
    post = update(model, RecordSet(recs), UpdateConfig(likelihood="time", n_chains=8, n_steps=60, max_steps=60,
                                                        evidence=False, ess_target=10, rhat_target=2.0),
                  spec.parameters)
    write_posterior(tmp_path / "post", post, {})

    rc = main(["predict", "--structure", str(s_path), "--posterior", str(tmp_path / "post"), "--windows",
               str(files[2]), "--out", str(tmp_path / "out"), "--n-draws", "50"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "accel floor 4" in text and q.windows[2].window_id in text
    doc = json.loads((tmp_path / "out" / "prediction.json").read_text())
    assert doc["schema_version"] and doc["model"] == "updated"
    ev = doc["events"][0]
    by = {c["name"]: c for c in ev["channels"]}
    assert by["f4"]["measured"] and by["f4"]["nrms_pct"] < by["f4"]["nrms_pct_nominal"]
    assert 0.5 < by["f8"]["coverage_95"] <= 1.0
    assert not by["floor5"]["measured"] and by["floor5"]["peak_ci95"][0] <= by["floor5"]["peak"] \
        <= by["floor5"]["peak_ci95"][1]
    assert by["drift_ratio8"]["peak"] > 0
    row = doc["table3"][0]
    assert row["accel_floor4"] == by["f4"]["nrms_pct"]
    assert row["drift_top"] is not None and np.isfinite(row["drift_top"])  # floors 7 and 8 measured
    assert (tmp_path / "out" / f"prediction_{q.windows[2].window_id}.png").stat().st_size > 1000

    assert ev["risk"]["limits_from"] == "defaults" and len(ev["risk"]["stories"]) == 8
    p = ev["risk"]["stories"][7]["exceedance"]
    assert [x["limit"] for x in p] == [0.005, 0.01, 0.02] and p[0]["probability"] >= p[1]["probability"]

    # the model error learnt out of sample over the calibration events, named in the JSON
    rc = main(["predict", "--structure", str(s_path), "--posterior", str(tmp_path / "post"), "--windows",
               str(files[2]), "--calibration-windows", str(files[0]), str(files[1]), "--out",
               str(tmp_path / "cv"), "--n-draws", "50", "--no-plots"])
    assert rc == 0
    cv = json.loads((tmp_path / "cv" / "prediction.json").read_text())["events"][0]
    assert cv["error_model"] == "cross-validated model error" and len(cv["model_error"]["folds"]) == 2
    assert cv["risk"]["calibration_pga_max_m_s2"] > 0
    assert main(["predict", "--structure", str(s_path), "--posterior", str(tmp_path / "post"), "--windows",
                 str(files[2]), "--calibration-windows", str(files[0]), "--out", str(tmp_path / "x")]) == 2
    assert "two or more events" in capsys.readouterr().err

    rc = main(["predict", "--structure", str(s_path), "--windows", *map(str, files), "--out",
               str(tmp_path / "nom"), "--no-plots"])
    assert rc == 0
    nom = json.loads((tmp_path / "nom" / "prediction.json").read_text())
    assert nom["model"] == "nominal" and len(nom["events"]) == 3
    f4 = {c["name"]: c for c in nom["events"][2]["channels"]}["f4"]
    assert abs(f4["nrms_pct"] - by["f4"]["nrms_pct_nominal"]) < 1e-9  # the nominal model is the nominal
