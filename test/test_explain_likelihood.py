"""explain's candidate likelihood: the model-form error of an effect's per-mode change.

A mode that barely feels an effect in the analysis model may feel it several times more in the
structure. Its error is then not a fraction of its own tiny change: with a purely relative error such
a mode, precise over hundreds of windows, pulls the fitted size of the effect far off.
"""

from __future__ import annotations

import numpy as np

from shm_ros.core.explain.likelihood import CandidateLikelihood, _Part


def _table(seed: int, w: int = 600):
    rng = np.random.default_rng(seed)
    x = np.sin(np.linspace(0.0, 12.0, w)) + 0.3 * rng.standard_normal(w)  # the effect's driver
    s_model = np.array([0.5, 0.45, 0.4, 0.03])
    s_true = np.array([0.48, 0.46, 0.41, 0.09])  # the last mode feels it three times more
    size = 0.04
    r = size * x[:, None] * s_true[None] + 0.003 * rng.standard_normal((w, 4))
    return r, x, s_model, size


def _map_size(lik: CandidateLikelihood, x: np.ndarray, s_model: np.ndarray) -> float:
    grid = np.linspace(0.02, 0.08, 601)
    d = grid[:, None, None] * x[None, :, None] * s_model[None, None, :]
    return float(grid[np.argmax(lik.gain(d))])


def test_a_mode_the_model_barely_moves_does_not_set_the_size():
    errs_rel, errs = [], []
    for seed in range(5):
        r, x, s_model, size = _table(seed)
        lik = CandidateLikelihood(r)
        errs.append(_map_size(lik, x, s_model) / size - 1.0)
        # the same table with the error a fraction of each mode's own change (spread off)
        part = lik.freq
        grid = np.linspace(0.02, 0.08, 601)
        d = grid[:, None, None] * x[None, :, None] * s_model[None, None, :]
        ll = part.loglik(d, lik.tau, spread=False).sum(axis=1)
        errs_rel.append(grid[np.argmax(ll)] / size - 1.0)
    assert max(abs(e) for e in errs) < 0.06, errs
    assert min(errs_rel) > 0.15, errs_rel  # the tiny mode drags the relative form's size up


def test_spread_keeps_the_relative_error_where_modes_move_alike():
    rng = np.random.default_rng(3)
    r = 0.003 * rng.standard_normal((300, 3))
    part = _Part.make(r, 1.0, 0.003)
    d = (0.01 * rng.standard_normal(300))[None, :, None] * np.ones((1, 1, 3))
    assert np.allclose(part.loglik(d, 0.1, spread=True), part.loglik(d, 0.1, spread=False))
    # no change at all: the null's value (the gain of a zero change is exactly zero)
    lik = CandidateLikelihood(r)
    assert abs(float(lik.gain(np.zeros((1, 300, 3)))[0])) < 1e-9
