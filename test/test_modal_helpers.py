"""The shared science helpers: MAC, real mode shapes, Rayleigh damping, JSON with numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shm_ros.core.modal import mac, mac_matrix, real_shape, unit_max
from shm_ros.core.models.damping import rayleigh_coefficients, rayleigh_ratios
from shm_ros.io import jsonio

RNG = np.random.default_rng(7)


# -- MAC ------------------------------------------------------------------------------------------
def test_mac_is_one_for_scaled_copies_zero_for_orthogonal_and_symmetric():
    a = RNG.standard_normal(8)
    b = RNG.standard_normal(8)
    assert mac(a, -3.5 * a) == pytest.approx(1.0)
    assert mac(a, (2 - 1j) * a) == pytest.approx(1.0)  # complex scale too
    assert mac(np.array([1.0, 0.0]), np.array([0.0, 2.0])) == 0.0
    assert mac(a, b) == pytest.approx(mac(b, a))
    assert 0.0 <= mac(a, b) <= 1.0
    assert mac(a, np.zeros(8)) == 0.0  # a zero shape: 0, not NaN


def test_mac_leaves_out_missing_components_and_counts_common_ones():
    a = np.array([1.0, 2.0, np.nan, 4.0])
    b = np.array([2.0, 4.0, 5.0, 8.0])
    assert mac(a, b) == pytest.approx(1.0)
    one = np.array([1.0, np.nan, np.nan])
    assert mac(one, np.array([3.0, 1.0, 1.0])) == pytest.approx(1.0)
    assert mac(one, np.array([3.0, 1.0, 1.0]), min_common=2) == 0.0


def test_mac_broadcasts_and_matrix_agrees_with_pairwise():
    A = RNG.standard_normal((3, 6)) + 1j * RNG.standard_normal((3, 6))
    B = RNG.standard_normal((4, 6))
    M = mac_matrix(A, B)
    assert M.shape == (3, 4)
    np.testing.assert_allclose(M, mac(A[:, None, :], B[None, :, :]), rtol=1e-12)
    batch = RNG.standard_normal((5, 4, 6))  # observed (3, n) against a batch of model shape sets
    Mb = mac_matrix(B[:3], batch)
    assert Mb.shape == (5, 3, 4)
    np.testing.assert_allclose(Mb[2], mac_matrix(B[:3], batch[2]), rtol=1e-12)
    np.testing.assert_allclose(np.diag(mac_matrix(B, B)), 1.0)


# -- real shapes ----------------------------------------------------------------------------------
def test_real_shape_is_invariant_to_complex_scaling():
    phi = np.array([0.2, -0.7, 1.3, 0.9])
    noisy = phi + 0.05j * RNG.standard_normal(4)
    ref = real_shape(noisy)
    for c in (1.0, -1.0, 1j, 3 * np.exp(0.7j), -0.01 * np.exp(-2.1j)):
        np.testing.assert_allclose(real_shape(c * noisy), ref, atol=1e-12)
    np.testing.assert_allclose(real_shape(np.exp(0.4j) * phi), phi / phi[2], atol=1e-12)
    assert np.max(np.abs(ref)) == pytest.approx(1.0) and ref[np.argmax(np.abs(ref))] == 1.0


def test_real_shape_and_unit_max_of_zeros_stay_zero():
    np.testing.assert_array_equal(real_shape(np.zeros(3, complex)), np.zeros(3))
    np.testing.assert_array_equal(unit_max(np.zeros(3)), np.zeros(3))
    np.testing.assert_allclose(unit_max(np.array([0.5, -2.0])), [-0.25, 1.0])


# -- Rayleigh -------------------------------------------------------------------------------------
def test_rayleigh_meets_both_ratios():
    w1, w2, z1, z2 = 2.0, 9.0, 0.02, 0.05
    a0, a1 = rayleigh_coefficients(w1, w2, z1, z2)
    assert isinstance(a0, float)
    np.testing.assert_allclose(rayleigh_ratios(np.array([w1, w2]), a0, a1), [z1, z2], rtol=1e-12)


def test_rayleigh_coincident_frequencies_fall_back_to_mass_proportional_scalar_and_batched():
    a0, a1 = rayleigh_coefficients(5.0, 5.0, 0.03, 0.04)
    assert (a0, a1) == (pytest.approx(2 * 0.03 * 5.0), 0.0)
    assert rayleigh_ratios(5.0, a0, a1) == pytest.approx(0.03)
    # batched: one row coincident, one not; no division by zero, no NaN
    w1 = np.array([[5.0], [2.0]])
    w2 = np.array([[5.0], [9.0]])
    z = np.array([[0.03], [0.02]])
    with np.errstate(all="raise"):
        A0, A1 = rayleigh_coefficients(w1, w2, z, z)
    assert np.all(np.isfinite(A0)) and np.all(np.isfinite(A1))
    assert A1[0, 0] == 0.0 and A0[0, 0] == pytest.approx(0.3)
    np.testing.assert_allclose(rayleigh_ratios(np.array([2.0, 9.0]), A0[1, 0], A1[1, 0]), 0.02, rtol=1e-12)


def test_model_batch_damping_has_the_guard_too():
    from shm_ros.core.models.base import AffineModel

    K = np.diag([4.0, 4.0])  # two equal frequencies
    m = AffineModel(name="twin", parameter_names=[], K0=K, M0=np.eye(2), K_terms=[], M_terms=[],
                    dof_labels=["a", "b"], damping_ratios=(0.02, 0.05))
    f = m.modes(n_modes=2).frequencies_hz
    with np.errstate(all="raise"):
        z = m.modal_damping_ratios_batch(np.zeros((1, 0)), f[None])
    np.testing.assert_allclose(z, [[0.02, 0.02]])
    np.testing.assert_allclose(m.modal_damping_ratios(), [0.02, 0.02])


# -- JSON -----------------------------------------------------------------------------------------
def test_json_round_trip_of_numpy_values(tmp_path):
    doc = {
        "f": np.float32(1.5), "i": np.int64(7), "b": np.bool_(True), "arr": np.arange(3.0),
        "nan": float("nan"), "inf": np.inf, "nested": [np.array([[1, 2], [3, 4]]), (np.nan, 2.0)],
        3: "int key", "path": tmp_path / "x",
    }
    path = jsonio.dump(doc, tmp_path / "sub" / "doc.json")
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    back = jsonio.load(path)
    assert back["f"] == 1.5 and back["i"] == 7 and back["b"] is True
    assert back["arr"] == [0.0, 1.0, 2.0] and back["nested"] == [[[1, 2], [3, 4]], [None, 2.0]]
    assert back["nan"] is None and back["inf"] is None and back["3"] == "int key"
    assert back["path"] == str(tmp_path / "x")
    assert isinstance(back["i"], int) and not math.isnan(back["f"])


def test_json_arrays_keep_strict_nulls_and_types_on_the_fast_path():
    doc = {"f": np.array([[1.0, np.nan], [-np.inf, 2.5]]), "f32": np.array([0.5], dtype=np.float32),
           "u": np.array([3], dtype=np.uint8), "b": np.array([True, False]), "empty": np.zeros((0, 2))}
    back = jsonio.loads(jsonio.dumps(doc, indent=None))
    assert back == {"f": [[1.0, None], [None, 2.5]], "f32": [0.5], "u": [3], "b": [True, False], "empty": []}
    assert isinstance(back["u"][0], int) and isinstance(back["b"][0], bool)
    with pytest.raises(TypeError, match="complex"):
        jsonio.dumps({"c": np.array([1j])})


def test_json_refuses_unknown_objects():
    with pytest.raises(TypeError, match="object"):
        jsonio.dumps({"x": object()})


def test_sign_aligned_uses_common_components_and_batches():
    from shm_ros.core.modal import sign_aligned

    ref = np.array([1.0, 2.0, np.nan])
    assert np.array_equal(sign_aligned(np.array([-1.0, -1.0, 5.0]), ref), [1.0, 1.0, -5.0])
    assert np.array_equal(sign_aligned(np.array([np.nan, np.nan, 3.0]), ref)[2:], [3.0])  # nothing shared
    batch = np.array([[1.0, 1.0, 0.0], [-2.0, -1.0, 0.0]])
    np.testing.assert_array_equal(sign_aligned(batch, ref), [[1.0, 1.0, 0.0], [2.0, 1.0, -0.0]])


def test_temperatures_fill_gaps_from_neighbours_for_every_candidate():
    """One helper gives every candidate the temperature covariate: a missing window takes the value
    between its neighbours (a cold night stays cold), the reference is the median of measured ones."""
    from shm_ros.core.explain.candidates._common import temperatures
    from shm_ros.core.explain.candidates.base import Context

    t_in = np.array([10.0, np.nan, -6.0, -4.0, np.nan, 20.0])
    ctx = Context(times_s=np.arange(6.0), covariates={"temperature_c": t_in}, hints={})
    t, ref = temperatures(ctx)
    assert np.allclose(t, [10.0, 2.0, -6.0, -4.0, 8.0, 20.0])
    assert ref == float(np.median([10.0, -6.0, -4.0, 20.0]))
    none = Context(times_s=np.arange(3.0), covariates={}, hints={})
    t0, ref0 = temperatures(none)
    assert ref0 == 0.0 and np.all(t0 == 0.0)
