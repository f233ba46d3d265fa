"""The bands do not peek (docs/predict.md, "Bands that hold"): zeroing the measured outputs after
the strong-motion onset leaves every measured channel's band (and peak interval) unchanged, with the
cross-validated model error in force; unmeasured floors use the records only through the documented
shape expansion, and prediction.json says so per channel."""

from __future__ import annotations

import numpy as np
from predict_truth import Profile, truth_source

from shm_ros.core.models import build_model
from shm_ros.core.predict import PosteriorDraws, PredictConfig, event_from_window, event_json, predict_event
from shm_ros.core.predict.model_error import cross_validated_error
from shm_ros.core.structure import structure_from_dict


def test_measured_bands_do_not_use_the_records_after_the_onset():
    pc = truth_source()(5, Profile(n_calibration=2, n_predicted=1, duration_s=25.0, fs=25.0))
    model = build_model(structure_from_dict(pc.structure))
    cfg = PredictConfig(n_draws=20, seed=1)
    th = model.nominal_theta()
    theta = th * np.exp(0.05 * np.random.default_rng(0).standard_normal((20, th.size)))
    cal = [event_from_window(w, model) for w in pc.calibration]
    draws = PosteriorDraws(theta, th).with_model_error(cross_validated_error(model, cal, th, cfg))
    ev = event_from_window(pc.predicted[0], model)
    a = predict_event(model, ev, draws, cfg)
    ev.outputs[a.strong.start:] = 0.0  # the records after the strong-motion onset are gone
    b = predict_event(model, ev, draws, cfg)
    measured = [c for c in a.channels if c.measured]
    assert len(measured) == 4
    for ca in measured:
        cb = b.channel(ca.name)
        assert np.array_equal(ca.lower, cb.lower) and np.array_equal(ca.upper, cb.upper), ca.name
        assert ca.peak_ci == cb.peak_ci
        assert not np.array_equal(ca.values, cb.values)  # the records did change
    doc = {c["name"]: c for c in event_json(a)["channels"]}
    for c in a.channels:
        if c.measured:
            continue
        changed = not np.array_equal(c.mean, b.channel(c.name).mean)
        if c.name.startswith("floor"):  # the shape expansion uses the measured floors' residual
            assert changed and c.expanded and doc[c.name]["through"] == "shape expansion"
            assert doc[c.name]["uses_measured_records"]
        else:  # drifts: the model alone
            assert not changed and doc[c.name]["through"] == "model"
            assert not doc[c.name]["uses_measured_records"]
    assert event_json(a)["error_model"] == "cross-validated model error"
