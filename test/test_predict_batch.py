"""The batched solver of the prediction (``core.response.batch``) equals the exact time-domain
solver draw by draw: :func:`shm_ros.core.response.simulate` on the matrix-exponential step of
:func:`shm_ros.core.response.discretize_foh`, an independent route (expm and a per-system
recursion, against a batched eigen-decomposition of A and closed-form modal steps)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from predict_synth import simulate_quakes
from scipy.integrate import quad

import shm_ros.core.response.batch as batch
from shm_ros.core.models import build_model
from shm_ros.core.predict import event_from_window, prediction_outputs
from shm_ros.core.response import build_state_space, discretize_foh, simulate
from shm_ros.core.structure import structure_from_dict


@pytest.fixture(scope="module")
def case():
    q = simulate_quakes(3, 1, duration_s=12.0, fs=50.0)
    st = copy.deepcopy(q.structure)
    for d in st["shear_building"]["dampers"][::2]:  # half the dampers Maxwell: real poles, extra states
        d["k_maxwell"] = 50.0 * d["c"]
    model = build_model(structure_from_dict(st))
    ev = event_from_window(q.windows[0], model)
    outs = [o for o, _ in prediction_outputs(model, ev.channel_ids)]
    rng = np.random.default_rng(1)
    th = model.nominal_theta() * (1 + 0.05 * rng.standard_normal((7, model.n_parameters)))
    u = ev.inputs - ev.inputs[:, :1]
    ref = np.stack([simulate(discretize_foh(build_state_space(model, t, outs), 1.0 / ev.fs), u) for t in th])
    return model, th, u, 1.0 / ev.fs, outs, ref


def _run(case, **kw):
    model, th, u, dt, outs, _ = case
    parts = list(batch.batch_responses(model, th, u, dt, outs, **kw))
    assert [a for a, _ in parts] == sorted(a for a, _ in parts)
    return np.concatenate([Y for _, Y in parts])


def _rel(Y, ref):
    return float(np.max(np.abs(Y - ref) / np.max(np.abs(ref), axis=2, keepdims=True)))


def test_batched_equals_exact_solver(case):
    ref = case[-1]
    assert ref.shape[0] == 7 and np.all(np.max(np.abs(ref), axis=2) > 0)
    Y = _run(case, chunk=3)
    assert _rel(Y, ref) < 1e-9
    # chunking and threads change nothing, bit for bit
    assert np.array_equal(Y, _run(case, chunk=7)) and np.array_equal(Y, _run(case, chunk=2, threads=2))


def test_fallback_draws_mixed_with_modal(case, monkeypatch):
    """Draws past the condition limit take the matrix-exponential route; the rest stay modal."""
    model, th, u, dt, outs, ref = case
    conds = [np.linalg.cond(np.linalg.eig(build_state_space(model, t, outs).A)[1]) for t in th]
    monkeypatch.setattr(batch, "_MAX_COND", float(np.median(conds)))
    assert _rel(_run(case, chunk=7), ref) < 1e-9
    monkeypatch.setattr(batch, "_MAX_COND", 0.0)
    assert _rel(_run(case, chunk=4), ref) < 1e-9


def test_phi_series_meets_closed_form():
    z = np.array([0.0, 1e-6, -3e-3 + 2e-3j, 0.00999, 0.0100001, -0.5 + 3j, -40.0])
    p1, p2 = batch.phi12(z)
    assert p1[0] == 1.0 and p2[0] == 0.5
    # the definitions as integrals over one step: phi1 = int_0^1 e^{z s} ds, phi2 = int_0^1 e^{z (1 - s)} s ds
    for k, zk in enumerate(z[1:], start=1):
        for f, p in ((lambda s, zk=zk: np.exp(zk * s), p1[k]), (lambda s, zk=zk: np.exp(zk * (1 - s)) * s, p2[k])):
            ref = quad(lambda s, f=f: f(s).real, 0, 1, epsabs=0, epsrel=1e-13)[0] \
                + 1j * quad(lambda s, f=f: f(s).imag, 0, 1, epsabs=0, epsrel=1e-13)[0]
            assert abs(p - ref) <= 1e-12 * abs(ref), (zk, p, ref)


def test_records_built_together_equal_each_record_alone(case):
    """:func:`record_responses` builds every record's state spaces in one batch (each distinct row
    once): the same responses, bit for bit, as :func:`batch_responses` record by record, with rows
    shared between records, rows of one record only, and records of other lengths and steps."""
    model, th, u, dt, outs, _ = case
    records = [(u, dt), (u[:, : u.shape[1] // 2], dt), (u[:, ::2], 2 * dt)]
    thetas = [th, th[[4, 0, 4, 2]], np.vstack([th[:2], th[:2] * 1.01])]
    got: list[list[tuple[int, np.ndarray]]] = [[] for _ in records]
    for k, a, Y in batch.record_responses(model, thetas, records, outs, chunk=3):
        got[k].append((a, Y))
    for (uk, dk), t, parts in zip(records, thetas, got, strict=True):
        want = list(batch.batch_responses(model, t, uk, dk, outs, chunk=3))
        assert [a for a, _ in parts] == [a for a, _ in want]
        assert all(np.array_equal(Y, W) for (_, Y), (_, W) in zip(parts, want, strict=True))
