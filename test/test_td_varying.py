"""Time-varying responses of the within-event candidates (shm_ros/core/explain/td_varying.py): the
interpolated steps against one exact discretisation per segment, and constant factors against the
time-invariant response code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from explain_td_cases import event_series

from shm_ros.core.explain.td_model import FactorModel, event_data
from shm_ros.core.explain.td_varying import interpolation_error, node_steps, varying_responses
from shm_ros.core.models import build_model
from shm_ros.core.response import sensor_outputs
from shm_ros.core.response.batch import batch_responses
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.structure import load_structure


@pytest.fixture(scope="module")
def setup():
    s = event_series(3, None, n_events=2, duration_s=30.0)
    fm = FactorModel.of(build_model(structure_from_dict(s.structure)))
    rec = event_data(s.events).records[1]
    return fm, rec, sensor_outputs(fm, rec.channel_ids)


@pytest.mark.parametrize(("ratio", "which"), [(r, w) for w in ("stiffness", "damping") for r in (1.2, 3.0, 10.0)]
                         + [(3.0, "added_damping"), (50.0, "added_damping")])
def test_interpolated_steps_match_exact(setup, ratio, which):
    fm, rec, outs = setup
    L = 10
    J = -(-rec.outputs.shape[0] // L)
    rng = np.random.default_rng(int(ratio * 10))
    # a slowly varying factor, as a softening during the strong motion gives, plus jumps
    t = np.arange(J) / J
    vals = np.exp(-np.log(ratio) * np.clip(np.sin(np.pi * t) + 0.1 * rng.standard_normal(J), 0, 1))
    col = fm.n_base + ("stiffness", "damping", "added_damping").index(which)
    if which == "added_damping":  # up to three times the first mode's inherent damping added
        vals = 3.0 * vals
    row = np.r_[fm.nominal_theta()[:fm.n_base], 1.0, 1.0, 0.0]
    err = interpolation_error(fm, row, col, vals, L, rec.inputs, rec.dt, outs)
    assert err < 1e-7, err


def test_constant_factor_is_the_invariant_response(setup):
    fm, rec, outs = setup
    L = 10
    J = -(-rec.outputs.shape[0] // L)
    rows = np.array([np.r_[fm.nominal_theta()[:fm.n_base], f, 1.0, 0.0] for f in (0.8, 1.1)])
    ref = np.concatenate([Y for _, Y in batch_responses(fm, rows, rec.inputs, rec.dt, outs)])
    steps = node_steps(fm, np.column_stack([rows[:, :fm.n_base], np.ones((2, 2)), np.zeros(2)]), fm.n_base,
                       np.array([0.7, 0.7]), np.array([1.2, 1.2]), rec.dt, outs)
    got = varying_responses(steps, np.repeat(rows[:, [fm.n_base]], J, axis=1), L, rec.inputs)
    assert got.shape == ref.shape
    assert np.max(np.abs(got - ref)) <= 1e-7 * np.max(np.abs(ref))


def test_batched_damping_equals_one_at_a_time(setup):
    """The batched inherent damping (numpy's stacked eigensolver, used to build a batch of state spaces)
    against the one-row route (scipy's generalised eigensolver) of the factor model: damping shape,
    damping factor and added damping varied, and of a model with modal damping."""
    fm, _, _ = setup
    rng = np.random.default_rng(5)
    th = np.tile(fm.nominal_theta(), (6, 1))
    th[:, :fm.n_base] *= rng.uniform(0.6, 1.5, (6, fm.n_base))
    th[:, fm.n_base:] = rng.uniform(0.5, 2.0, (6, 3))
    th[0, fm.n_base + 2] = 0.0  # no added damping in one row
    C = fm.inherent_damping_batch(th)
    for k in range(6):
        one = fm.inherent_damping(th[k])
        assert np.max(np.abs(C[k] - one)) < 1e-10 * np.max(np.abs(one))
    modal = build_model(load_structure(Path(__file__).parents[1] / "examples" / "matrices.yaml"))
    assert modal.damping_kind == "modal"
    one = modal.inherent_damping(None)
    batch = modal.inherent_damping_batch(modal.nominal_theta()[None])[0]
    assert np.max(np.abs(batch - one)) < 1e-12 * np.max(np.abs(one))
