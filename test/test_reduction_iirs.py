"""IIRS reduction to the measured floors and mode-shape expansion.

CI size: a few hundred parameter draws; ``SHM_FULL=1`` runs thousands.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import full_size
from scipy.optimize import least_squares

from shm_ros.core.models import build_model
from shm_ros.core.models.reduction import (
    expand_mode_shapes,
    expand_sensor_shapes,
    guyan,
    iirs,
    iirs_limit,
    reduce_model,
    reduced_modes_batch,
)
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.structure import load_structure

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MEASURED = ["f1", "f3", "f6", "f8"]  # four instrumented floors of the eight (plus the ground input)
N_MODES = 4


def _mac(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """MAC between matching columns along the DOF axis (-2)."""
    num = np.sum(a * b, axis=-2) ** 2
    return num / (np.sum(a * a, axis=-2) * np.sum(b * b, axis=-2))


@pytest.fixture(scope="module")
def building():
    spec = load_structure(EXAMPLES / "building.yaml")
    return spec, build_model(spec)


def _prior_draws(spec, n, rng):
    """Parameter vectors drawn from the structure file's priors (kept physical: > 0.4)."""
    cols = [np.clip(p.prior.frozen().rvs(size=n, random_state=rng), 0.4, None) for p in spec.parameters]
    return np.column_stack(cols)


def test_iirs_matches_full_model_over_prior_spread(building):
    """Acceptance: reduced modes within 0.1 % of the full model's lowest four, and expansion with the
    same transformation recovers the unmeasured floors' mode-shape components with MAC >= 0.99."""
    spec, model = building
    rng = np.random.default_rng(20240601)
    n = 5000 if full_size() else 400
    thetas = _prior_draws(spec, n, rng)
    masters = model.master_dofs(MEASURED)
    slaves = np.setdiff1d(np.arange(model.n_dof), masters)

    red = reduce_model(model, thetas, MEASURED)  # iterated, never sees the full eigenvectors
    assert red.converged
    sol = red.modes(N_MODES)
    full = model.modes_batch(thetas, N_MODES)
    err = np.abs(sol.frequencies_hz / full.frequencies_hz - 1)
    assert err.max() < 1e-3, err.max(axis=0)
    assert err.max() < 1e-6  # converged to the tolerance, far inside the acceptance bound

    # the "measured" shapes are the full model's at the sensors; expansion fills the other floors
    expanded = red.expand(full.shapes[:, masters, :])
    mac_slaves = _mac(expanded[:, slaves, :], full.shapes[:, slaves, :])
    assert mac_slaves.min() >= 0.99, mac_slaves.min(axis=0)
    # the reduced shapes themselves are the full shapes at the masters
    mac_masters = _mac(sol.shapes, full.shapes[:, masters, :])
    assert mac_masters.min() > 0.9999

    # Guyan (no iteration) is visibly worse: the improvement is the iteration's, not the test's
    g = guyan(model.stiffness_batch(thetas[:50]), model.mass_batch(thetas[:50]), masters)
    g_err = np.abs(g.modes(N_MODES).frequencies_hz / full.frequencies_hz[:50] - 1)
    assert g_err[:, 1:].max() > 1e-2


def test_expansion_of_a_messier_truth(building):
    """Shapes measured on a building whose stories deviate randomly (+-5 % stiffness, +-3 % mass) from
    the model; the model is first fitted to the measured frequencies (as updating would), then
    expands the four measured floors. Figures (SHM_FULL, 400 trials, median / 5th percentile of the
    unmeasured floors' MAC): mode 1 0.99995/0.9998, mode 2 0.9995/0.998, mode 3 0.998/0.985,
    mode 4 0.989/0.943 - model error, not the expansion, limits the higher modes."""
    spec, model = building
    rng = np.random.default_rng(7)
    n = 400 if full_size() else 60
    masters = model.master_dofs(MEASURED)
    slaves = np.setdiff1d(np.arange(model.n_dof), masters)
    groups = [0, 0, 1, 1, 1, 2, 2, 2]
    macs, macs_guyan = [], []
    for _ in range(n):
        d = spec.to_dict()
        theta_true = np.clip(rng.normal(1.0, 0.15, 3), 0.6, None)
        for i, f in enumerate(d["shear_building"]["floors"]):
            f["stiffness"] *= theta_true[groups[i]] * rng.normal(1.0, 0.05)
            f["mass"] *= rng.normal(1.0, 0.03)
        truth = build_model(structure_from_dict(d, "truth"), include_parameters=False).modes(n_modes=N_MODES)
        fit = least_squares(
            lambda th: model.modes(th, N_MODES).frequencies_hz / truth.frequencies_hz - 1, np.ones(3), bounds=(0.3, 3.0)
        )
        red = reduce_model(model, fit.x, MEASURED)
        measured = truth.shapes[masters, :]
        macs.append(_mac(red.expand(measured)[slaves], truth.shapes[slaves]))
        g = guyan(model.stiffness(fit.x), model.mass(fit.x), masters)
        macs_guyan.append(_mac(g.expand(measured)[slaves], truth.shapes[slaves]))
    macs, macs_guyan = np.array(macs), np.array(macs_guyan)
    assert np.percentile(macs[:, :2], 5, axis=0).min() >= 0.99, np.percentile(macs, 5, axis=0)
    assert np.median(macs[:, 2]) >= 0.99, np.median(macs, axis=0)
    assert np.median(macs[:, 3]) >= 0.95, np.median(macs, axis=0)
    assert np.all(np.median(macs, axis=0) >= np.median(macs_guyan, axis=0))


def test_batched_and_single_agree_and_warm_start(building):
    spec, model = building
    rng = np.random.default_rng(3)
    thetas = _prior_draws(spec, 20, rng)
    batch = reduce_model(model, thetas, MEASURED, tol=1e-10)
    for b in (0, 7, 19):
        one = reduce_model(model, thetas[b], MEASURED, tol=1e-10)
        np.testing.assert_allclose(one.modes(N_MODES).frequencies_hz, batch.modes(N_MODES).frequencies_hz[b], rtol=1e-8)
        np.testing.assert_allclose(one.T, batch.T[b], rtol=1e-5, atol=1e-8)
    # the plain iteration (no extrapolation) reaches the same fixed point, in more iterations
    plain = reduce_model(model, thetas, MEASURED, tol=1e-10)
    plain = iirs(model.stiffness_batch(thetas), model.mass_batch(thetas), plain.masters, tol=1e-10, accelerate=False)
    np.testing.assert_allclose(plain.modes(N_MODES).frequencies_hz, batch.modes(N_MODES).frequencies_hz, rtol=1e-8)
    assert plain.iterations > batch.iterations
    # warm start from the nominal transformation converges to the same reduced model
    nominal = reduce_model(model, None, MEASURED, tol=1e-10)
    warm = iirs(model.stiffness_batch(thetas), model.mass_batch(thetas), nominal.masters, tol=1e-10, t0=nominal.t)
    np.testing.assert_allclose(warm.modes(N_MODES).frequencies_hz, batch.modes(N_MODES).frequencies_hz, rtol=1e-8)
    # the convenience call returns sensor-ordered shapes, or expanded ones
    sol = reduced_modes_batch(model, thetas, MEASURED, n_modes=3)
    exp = reduced_modes_batch(model, thetas, MEASURED, n_modes=3, expand=True)
    assert sol.shapes.shape == (20, 4, 3) and exp.shapes.shape == (20, 8, 3)
    np.testing.assert_allclose(exp.shapes[:, model.master_dofs(MEASURED)], sol.shapes, atol=1e-12)
    np.testing.assert_allclose(expand_mode_shapes(batch.T, batch.modes(3).shapes), batch.expand(batch.modes(3).shapes))


def test_limit_equals_converged_iteration(building):
    """``method="limit"`` (lowest eigenvectors) is the fixed point the iteration converges to."""
    spec, model = building
    thetas = _prior_draws(spec, 200, np.random.default_rng(11))
    it = reduce_model(model, thetas, MEASURED, tol=1e-12)
    lim = reduce_model(model, thetas, MEASURED, method="limit")
    for a, b in ((it.K, lim.K), (it.M, lim.M)):
        rel = np.linalg.norm(a - b, axis=(1, 2)) / np.linalg.norm(b, axis=(1, 2))
        assert rel.max() < 1e-4, rel.max()
    np.testing.assert_allclose(it.modes(4).frequencies_hz, lim.modes(4).frequencies_hz, rtol=1e-8)
    single = iirs_limit(model.stiffness(thetas[0]), model.mass(thetas[0]), model.master_dofs(MEASURED))
    np.testing.assert_allclose(single.T, lim.T[0], atol=1e-10)
    with pytest.raises(ValueError, match="method"):
        reduce_model(model, None, MEASURED, method="serep")


def test_non_convergence_is_reported(building):
    _, model = building
    r = reduce_model(model, None, MEASURED, max_iter=3)
    assert not r.converged and r.iterations == 3 and list(r.not_converged) == [0]
    assert reduce_model(model, None, MEASURED).not_converged is None
    with pytest.raises(ValueError):
        iirs(model.stiffness(), model.mass(), [0, 0, 3])
    with pytest.raises(KeyError):
        model.master_dofs(["g0"])


def test_girder_reduction_to_deck_sensors():
    """Five vertical deck sensors of the 66-DOF girder: IIRS keeps its lowest five modes."""
    model = build_model(load_structure(EXAMPLES / "girder.yaml"))
    red = reduce_model(model)
    assert red.converged and len(red.masters) == 5
    full = model.modes(n_modes=5)
    np.testing.assert_allclose(red.modes().frequencies_hz, full.frequencies_hz, rtol=1e-6)
    expanded = red.expand(red.modes().shapes)
    assert _mac(expanded, full.shapes).min() > 0.9999


def test_expand_sensor_shapes_from_sensor_order(building):
    """Measured shapes given in any sensor order (max |.| = 1 as identification writes them), with
    a duplicated sensor, expand to every floor."""
    spec, model = building
    theta = np.array([0.9, 1.1, 1.05])
    full = model.modes(theta, n_modes=3).shapes
    ids = ["f8", "f3", "f1", "f6", "f6"]
    measured = model.sensor_matrix(ids) @ full
    measured = measured / np.abs(measured).max(axis=0)
    expanded = expand_sensor_shapes(model, ids, measured, theta)
    assert expanded.shape == (8, 3)
    assert _mac(expanded, full).min() > 0.99999
    one = expand_sensor_shapes(model, ids, measured[:, 0], theta)
    np.testing.assert_allclose(one, expanded[:, 0])
    with pytest.raises(KeyError):
        expand_sensor_shapes(model, ["g0", "f1", "f3", "f6"], measured[:4], theta)


def test_extreme_parameters_converged_members_are_accurate(building):
    """Far outside the priors (story groups 0.3-3x, adjacent groups up to 10x apart) IIRS can
    converge very slowly for some members; those are listed in ``not_converged`` and every other
    member is accurate. The extrapolation never leaves a member worse than the plain iteration."""
    _, model = building
    rng = np.random.default_rng(5)
    thetas = np.exp(rng.uniform(np.log(0.3), np.log(3.0), (3000 if full_size() else 600, 3)))
    K, M = model.stiffness_batch(thetas), model.mass_batch(thetas)
    masters = model.master_dofs(MEASURED)
    full = model.modes_batch(thetas, N_MODES).frequencies_hz
    acc = iirs(K, M, masters, tol=1e-8, max_iter=300)
    plain = iirs(K, M, masters, tol=1e-8, max_iter=300, accelerate=False)
    err_acc = np.abs(acc.modes(N_MODES).frequencies_hz / full - 1).max(axis=1)
    err_plain = np.abs(plain.modes(N_MODES).frequencies_hz / full - 1).max(axis=1)
    bad = np.zeros(len(thetas), bool)
    if acc.not_converged is not None:
        bad[acc.not_converged] = True
    assert err_acc[~bad].max() < 1e-6
    assert np.all(err_acc <= 1.5 * err_plain + 1e-7)
    assert bad.sum() < 0.1 * len(thetas)


@pytest.mark.parametrize("n_dof,n_masters", [(8, 4), (12, 5), (40, 6), (90, 6), (5, 1)])
def test_compiled_iteration_is_numpys_bit_for_bit(n_dof, n_masters):
    """The compiled IIRS loop gives the numpy loop's transformation, iteration count and verdict
    exactly: a sampler's chains follow every decision of the iteration (converged, jumped), so
    agreement to round-off would not be enough. Random pencils, warm and cold starts, with and
    without the extrapolation, some members stopped by max_iter; 384 slave-master entries (90, 6)
    take numpy's pairwise summation past one block."""
    from shm_ros.core.models.reduction import _iterate, _iterate_numpy, _split

    rng = np.random.default_rng(n_dof)
    for trial in range(40):
        B = int(rng.integers(1, 20))
        A = rng.standard_normal((n_dof, n_dof))
        K = (A @ A.T + n_dof * np.eye(n_dof))[None] * (1 + 0.1 * rng.standard_normal((B, 1, 1)))
        K = K + 0.05 * rng.standard_normal((B, n_dof, n_dof))
        K = 0.5 * (K + np.swapaxes(K, 1, 2)) + n_dof * np.eye(n_dof)
        M = np.broadcast_to(np.diag(rng.uniform(0.5, 2.0, n_dof)), (B, n_dof, n_dof)).copy()
        m, s = _split(n_dof, sorted(rng.choice(n_dof, n_masters, replace=False).tolist()))
        Kmm, Kms, Kss = K[:, m][:, :, m], K[:, m][:, :, s], K[:, s][:, :, s]
        Mmm, Mms, Mss = M[:, m][:, :, m], M[:, m][:, :, s], M[:, s][:, :, s]
        Kss_inv = np.linalg.inv(Kss)
        tG = -Kss_inv @ np.swapaxes(Kms, -1, -2)
        t0 = tG if trial % 2 else np.broadcast_to(tG[0] + 0.01 * rng.standard_normal(tG.shape[1:]), tG.shape)
        args = (Kmm, Kms, Kss, Mmm, Mms, Mss, tG, Kss_inv, np.array(t0), m.size,
                int(rng.choice([5, 200])), float(rng.choice([1e-4, 1e-9, 1e-12])), trial % 5 != 0)
        a, b = _iterate(*args), _iterate_numpy(*args)
        assert np.array_equal(a[0], b[0]) and a[1:4] == b[1:4], (trial, a[1:4], b[1:4])
        assert (a[4] is None and b[4] is None) or np.array_equal(a[4], b[4])
