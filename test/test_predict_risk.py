"""Risk where it matters (docs/predict.md, "Risk"): per predicted event the probability that a
story's drift ratio exceeds the structure file's limits, and the warning when the event lies
outside what the calibration saw.

Truth: test/predict_truth.py (softening story springs that leave their elastic range in the strong
event). Calibrated on three events of PGA 0.4-0.8 m/s^2; predicted: an elastic event inside that
range and a strong one (3 m/s^2) that takes the truth beyond its elastic range. The structure file's
``drift_limits`` put the elastic range and a limit at the truth's elastic drift ratio.

- strong event: the truth exceeds the limit; P(exceedance) >= 0.5 at the story where it does most,
  and the out-of-calibration warning is raised (its PGA is above the calibration events');
- elastic event: P(exceeding twice the truth's peak drift) <= 0.05 at every story, no warning.
"""

from __future__ import annotations

import copy

import numpy as np
from predict_bands import predict_campaign
from predict_truth import Profile, truth_source

from shm_ros.core.predict import event_json, summary_json
from shm_ros.core.predict.risk import event_risk
from shm_ros.core.structure import structure_from_dict
from shm_ros.report.inputs import PredictionInputs, ReportInputs
from shm_ros.report.summary import _predicted

PROFILE = Profile(n_calibration=3, n_predicted=2, duration_s=30.0, fs=25.0,
                  earthquakes=((0.4, 6.0), (0.8, 6.0), (0.6, 6.0), (0.6, 6.0), (3.0, 6.0)))


def test_drift_exceedance_and_out_of_calibration_warning():
    pc = truth_source()(11, PROFILE)
    elastic_id, strong_id = (w.window_id for w in pc.predicted)
    assert pc.yields[strong_id] and not pc.yields[elastic_id]
    model, preds, draws = predict_campaign(pc, 11, n_draws=60, steps=60)
    st = copy.deepcopy(pc.structure)
    st["drift_limits"] = {"limits": [pc.elastic_drift_ratio], "elastic": pc.elastic_drift_ratio}
    limits = structure_from_dict(st).drift_limits
    elastic, strong = preds

    r = event_risk(strong, limits)
    truth = pc.truth[strong_id]
    k = max(range(1, 9), key=lambda j: np.max(np.abs(truth[f"drift_ratio{j}"])))
    peak = float(np.max(np.abs(truth[f"drift_ratio{k}"])))
    p = r["stories"][k - 1]["exceedance"][0]["probability"]
    print(f"\nstrong event: truth peak drift ratio {peak:.5f} at story {k} (limit {pc.elastic_drift_ratio:.5f}), "
          f"P(exceed) {p:.3f}; warnings {r['warnings']}")
    assert peak > pc.elastic_drift_ratio
    assert p >= 0.5
    assert r["outside_calibration"] and any("above the strongest calibration event" in w for w in r["warnings"])

    truth = pc.truth[elastic_id]
    probs = []
    for j in range(1, 9):
        twice = 2 * float(np.max(np.abs(truth[f"drift_ratio{j}"])))
        probs.append(event_risk(elastic, type(limits)((twice,), limits.elastic, {}, True))
                     ["stories"][j - 1]["exceedance"][0]["probability"])
    r = event_risk(elastic, limits)
    print(f"elastic event: P(exceed twice the truth's peak) at most {max(probs):.4f}; warnings {r['warnings']}")
    assert max(probs) <= 0.05
    assert not r["warnings"] and not r["outside_calibration"]

    # prediction.json and the report's summary say so
    strong.risk, elastic.risk = event_risk(strong, limits), r
    payload = {"events": [event_json(p) for p in preds], "summary": summary_json(preds)}
    assert payload["summary"]["events_outside_calibration"] == [strong_id]
    text = _predicted(ReportInputs(prediction=PredictionInputs(payload)))
    assert text is not None and "exceeded a limit" in text and strong_id in text
    assert "1 event(s) lay outside what the calibration saw" in text
