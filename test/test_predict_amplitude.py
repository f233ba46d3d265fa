"""The amplitude-aware parts of the learnt model error (shm_ros/core/predict/model_error.py): the
equivalent-linear parameters of an event's PGA and the error growing with its distance from the
calibration events' PGAs. The acceptance on truths outside the model class is test_predict_bands.py."""

from __future__ import annotations

import numpy as np

from shm_ros.core.predict import PosteriorDraws
from shm_ros.core.predict.model_error import ModelError


def _error() -> ModelError:
    # a damping factor that doubles from 0.1 to 0.4 m/s^2, a stiffness factor that stays
    return ModelError({"a": 0.04, "b": 0.09}, [0.1, 0.4], [[1.0, 1.0], [1.0, 2.0]], {"a": 0.01, "b": 0.03},
                      unmeasured_rel2=0.2, log_spread=[0.0, 0.0])


def test_parameters_follow_the_amplitude_inside_the_calibration_range_and_hold_outside():
    me = _error()
    assert np.allclose(me.theta_at(0.2), [1.0, np.sqrt(2.0)])  # halfway in log PGA: halfway in log
    assert np.allclose(me.theta_at(0.01), [1.0, 1.0])  # below the weakest: the weakest's
    assert np.allclose(me.theta_at(4.0), [1.0, 2.0])  # above the strongest: the strongest's, no trend


def test_error_grows_with_the_log_pga_distance_to_the_nearest_calibration_event():
    me = _error()
    assert me.rel2_at("a", 0.1) == me.rel2_at("a", 0.4) == 0.04  # at a calibration PGA: the floor
    d = np.log(4.0 / 0.4)
    assert np.isclose(me.rel2_at("b", 4.0), 0.09 + 0.03 * d ** 2)
    assert me.rel2_at("b", 0.15) < me.rel2_at("b", 0.05) < me.rel2_at("b", 0.01)
    assert me.rel2_at(None, 0.1) == 0.2  # unmeasured outputs: at least the held-out error
    assert np.isclose(me.rel2_at(None, 40.0), 0.065 + 0.02 * np.log(100.0) ** 2)
    assert me.pga_max == 0.4


def test_draws_move_with_the_map_and_keep_their_spread():
    theta = np.array([[1.0, 1.0], [1.1, 0.9], [0.9, 1.2]])
    d = PosteriorDraws(theta, np.array([1.0, 1.0]), model_error=_error())
    at = d.at_amplitude(0.4, np.random.default_rng(0))
    assert np.allclose(at.theta_map, [1.0, 2.0])
    assert np.allclose(at.theta / at.theta_map, theta)  # the posterior's spread, relative
    spread = PosteriorDraws(theta, np.array([1.0, 1.0]), model_error=ModelError(
        {"a": 0.04}, [0.1, 0.4], [[1.0, 1.0], [1.0, 2.0]], log_spread=[0.5, 0.0]))
    moved = spread.at_amplitude(0.4, np.random.default_rng(0)).theta
    assert np.allclose(moved[:, 1], 2.0 * theta[:, 1]) and not np.allclose(moved[:, 0], theta[:, 0])
    assert PosteriorDraws(theta, np.array([1.0, 1.0])).at_amplitude(0.4, np.random.default_rng(0)).theta is theta


def test_error_grows_no_further_than_the_folds_were_held_out():
    # two calibration events 12 % apart: both folds at D_f = ln(0.92 / 0.82); an event 30 % stronger
    # than the strongest gets the held-out folds' error, not (D / D_f)^2 = 6 times their excess
    d_f = np.log(0.92 / 0.82)
    me = ModelError({"a": 0.1}, [0.82, 0.92], [[1.0, 1.0], [1.0, 1.0]], {"a": 0.05 / d_f ** 2},
                    distance_max=d_f)
    assert np.isclose(me.rel2_at("a", 0.92 * 1.3), 0.15)
    assert np.isclose(me.rel2_at("a", 0.92 * np.exp(d_f / 2)), 0.1 + 0.05 / 4)  # inside: the trend
    assert np.isclose(me.rel2_at(None, 10.0), 0.15)
    assert me.to_json()["distance_max"] == d_f and _error().to_json()["distance_max"] is None
