"""Unit checks of the identification core: factorisations, the two estimates of A, pre-processing,
mode-shape normalisation and configuration errors."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.signal as sig

from shm_ros.core import ssi
from shm_ros.core.identify import IdentifyConfig, identify_window
from shm_ros.core.modal import real_shape as real_mode_shape
from shm_ros.core.preprocess import PreprocessConfig, preprocess
from shm_ros.core.stabilization import mpc
from shm_ros.core.types import Window


def _two_mode_record(seed: int, n: int = 20000, fs: float = 50.0, noise: float = 0.3):
    """Two lightly damped modes driven by white noise, 3 channels, plus sensor noise."""
    rng = np.random.default_rng(seed)
    out = np.zeros((n, 3))
    shapes = np.array([[1.0, 0.6, 0.3], [-0.5, 0.4, 1.0]])
    for (f, z), phi in zip([(2.0, 0.02), (5.5, 0.015)], shapes):
        w = 2 * np.pi * f
        b, a = sig.cont2discrete(([1.0], [1.0, 2 * z * w, w * w]), 1 / fs, method="zoh")[:2]
        q = sig.lfilter(np.ravel(b), a, rng.standard_normal(n))
        out += q[:, None] * phi[None, :]
    out += noise * out.std(axis=0) * rng.standard_normal(out.shape)
    return out, fs


def test_correlations_and_gram_are_exact_sums():
    rng = np.random.default_rng(1)
    z = rng.standard_normal((700, 3))
    nb, j = 8, 700 - 8 + 1 - 3
    h = np.vstack([z[a:a + j].T for a in range(nb)])
    assert np.allclose(ssi.hankel_gram(z, nb, j), h @ h.T, atol=1e-9)
    lower = ssi.hankel_lq_streamed(z, np.arange(nb * 3), j, chunk=97)
    assert np.allclose(lower @ lower.T, h @ h.T, atol=1e-8)
    r = ssi.correlations(z, np.array([1]), 6)
    assert np.allclose(r[4, :, 0], z[4:].T @ z[:-4, 1] / (700 - 4))


def test_segmented_correlations_equal_the_direct_sums():
    """Blocks shorter than the record (several segments, a partial last one) give the exact
    finite sums divided by N - k, for every lag, channel and reference."""
    rng = np.random.default_rng(5)
    z = rng.standard_normal((1001, 4)).cumsum(axis=0)  # coloured, non-zero mean
    refs = np.array([3, 0])
    n_lags = 17
    direct = np.stack([z[k:].T @ z[:1001 - k, refs] / (1001 - k) for k in range(n_lags)])
    for segment in (64, 100, 4096):
        r = ssi.correlations(z, refs, n_lags, segment=segment)
        assert np.allclose(r, direct, rtol=1e-10, atol=1e-10 * np.abs(direct).max())


def test_ssi_data_gram_and_streamed_qr_give_the_same_poles():
    y, fs = _two_mode_record(2, n=6000)
    p = []
    for lq in ("gram", "qr"):
        model = ssi.ssi_data(y, fs, 12, 12, lq=lq)
        p.append(ssi.poles_all_orders(model, [4, 8, 12]))
    assert np.allclose(np.sort(p[0].frequency_hz), np.sort(p[1].frequency_hz), rtol=1e-7)


def test_ssi_data_weightings_are_the_textbook_products():
    """PC: the left singular space of the weighted projection is that of Y_f Y_p^T / j; CVA: that
    of (Y_f Y_f^T / j)^-1/2 L21 mapped back by (Y_f Y_f^T / j)^1/2; UPC: that of L21. Checked
    against explicitly formed Hankel matrices; all three find both modes."""
    y, fs = _two_mode_record(7, n=3000)
    n, l = y.shape
    i, order = 6, 4
    j = n - 2 * i + 1
    yp = np.vstack([y[a:a + j].T for a in range(i)]) / np.sqrt(j)
    yf = np.vstack([y[i + a:i + a + j].T for a in range(i)]) / np.sqrt(j)
    proj = yf @ yp.T @ np.linalg.solve(yp @ yp.T, yp)  # Y_f / Y_p
    gf = yf @ yf.T
    w, v = np.linalg.eigh(gf)
    half, inv_half = (v * np.sqrt(w)) @ v.T, (v / np.sqrt(w)) @ v.T
    expected = {
        "upc": np.linalg.svd(proj)[0][:, :order],
        "pc": np.linalg.svd(yf @ yp.T)[0][:, :order],
        "cva": half @ np.linalg.svd(inv_half @ proj)[0][:, :order],
    }
    for weighting, ref in expected.items():
        model = ssi.ssi_data(y, fs, i, order, weighting=weighting, lq="qr")
        angles = sla.subspace_angles(model.observability, ref)
        assert np.max(angles) < 1e-6, (weighting, angles)
        poles = ssi.poles_all_orders(model, [order])
        assert np.min(np.abs(poles.frequency_hz - 2.0)) < 0.04, weighting
        assert np.min(np.abs(poles.frequency_hz - 5.5)) < 0.11, weighting
    with pytest.raises(ValueError, match="weighting"):
        ssi.ssi_data(y, fs, i, order, weighting="pca")
    w = Window("w", 0, fs, ["a", "b", "c"], y)
    with pytest.raises(ValueError, match="identify.weighting"):
        identify_window(w, IdentifyConfig(method="ssi-data", weighting="PC"))


def test_all_orders_from_one_factorisation_match_per_order_least_squares():
    y, fs = _two_mode_record(3)
    model = ssi.ssi_cov(y, fs, 15, 20)
    poles = ssi.poles_all_orders(model, np.arange(2, 21))
    o, l = model.observability, model.n_outputs
    for n in (4, 9, 20):
        a_f, a_b = ssi.forward_backward_A(o, l, n)
        mu = sla.eigvals(a_f)
        f_ref = np.sort(np.abs(np.log(mu[mu.imag > 1e-12]) * fs) / (2 * np.pi))
        assert np.allclose(np.sort(poles.frequency_hz[poles.order == n]), f_ref, rtol=1e-8)
        mu_b = sla.eigvals(a_b)
        fb_ref = np.abs(np.log(mu_b[mu_b.imag > 1e-12]) * fs) / (2 * np.pi)
        assert np.all(np.isin(np.round(poles.frequency_b_hz[poles.order == n], 8),
                              np.round(fb_ref, 8)))


def test_two_estimates_of_A_differ_on_noisy_data_and_printed_eq13_inverts_the_poles():
    y, fs = _two_mode_record(4)
    model = ssi.ssi_cov(y, fs, 15, 20)
    o, l = model.observability, model.n_outputs
    n = 12
    a_f, a_b = ssi.forward_backward_A(o, l, n)
    # genuinely different on noisy data
    assert np.linalg.norm(a_f - a_b) / np.linalg.norm(a_f) > 1e-3
    # ... but they agree on the physical poles: both contain 2.0 Hz and 5.5 Hz within 1 %
    for a in (a_f, a_b):
        mu = sla.eigvals(a)
        f = np.abs(np.log(mu[mu.imag > 0]) * fs) / (2 * np.pi)
        assert np.min(np.abs(f - 2.0)) < 0.02 and np.min(np.abs(f - 5.5)) < 0.055
    # the printed eq. 13 is the inverse of the forward estimate: poles outside the unit circle
    a_13 = ssi.printed_eq13_estimate(o, l, n)
    assert np.allclose(a_13 @ a_f, np.eye(n), atol=1e-6)
    mu13 = sla.eigvals(a_13)
    assert np.allclose(np.sort_complex(mu13), np.sort_complex(1.0 / sla.eigvals(a_f)), atol=1e-6)
    # its poles at the physical frequencies grow instead of decaying (negative damping)
    lam = np.log(mu13[mu13.imag > 0]) * fs
    f13 = np.abs(lam) / (2 * np.pi)
    for f0 in (2.0, 5.5):
        k = np.argmin(np.abs(f13 - f0))
        assert abs(f13[k] - f0) < 0.02 * f0 and lam[k].real > 0


def test_noise_free_two_estimates_coincide():
    """On exact shift-invariant data both estimates of A are the same matrix."""
    rng = np.random.default_rng(5)
    a = np.diag([0.95, 0.9]) @ np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    c = rng.standard_normal((3, 2))
    o = np.vstack([c @ np.linalg.matrix_power(a, k) for k in range(8)])
    a_f, a_b = ssi.forward_backward_A(o, 3, 2)
    assert np.allclose(a_f, a) and np.allclose(a_b, a)


def test_real_mode_shape_rotation_and_scaling():
    phi = np.array([0.2, -1.0, 0.5]) * np.exp(1j * 0.7)
    out = real_mode_shape(phi)
    assert np.allclose(out, [-0.2, 1.0, -0.5])
    assert mpc(phi[None])[0] == pytest.approx(1.0)
    scattered = np.array([[1.0, 1j, -1.0, -1j]])
    assert mpc(scattered)[0] < 0.05


def test_preprocess_offsets_filter_decimation_and_selection():
    fs = 200.0
    t = np.arange(40000) / fs
    rng = np.random.default_rng(6)
    sig_ = np.sin(2 * np.pi * 3.0 * t)
    raw = np.column_stack([9.81 + sig_ + 0.001 * t, -0.2 + sig_, np.sin(2 * np.pi * 60 * t),
                           rng.standard_normal(t.size)])
    cfg = PreprocessConfig(channels=["a", "b", "c"], lowpass_hz=20.0, target_rate_hz=50.0)
    prep = preprocess(raw, fs, ["a", "b", "c", "d"], cfg)
    assert prep.channel_names == ["a", "b", "c"]
    assert prep.sample_rate_hz == 50.0 and prep.data.shape == (10000, 3)
    assert abs(prep.data[:, 0].mean()) < 1e-3  # gravity offset and drift removed
    assert np.std(prep.data[:, 2]) < 0.01  # 60 Hz removed by the 20 Hz low-pass
    assert np.std(prep.data[1000:-1000, 0]) == pytest.approx(1 / np.sqrt(2), rel=0.02)
    with pytest.raises(ValueError, match="preprocess.channels"):
        preprocess(raw, fs, ["a", "b", "c", "d"], PreprocessConfig(channels=["zz"]))


def test_bad_channels_are_dropped_with_a_note_and_all_bad_is_a_clear_error():
    y, fs = _two_mode_record(7, n=4000)
    y = np.column_stack([y, np.full(4000, 9.81)])
    y[10, 1] = np.nan
    prep = preprocess(y, fs, ["s1", "s2", "s3", "dead"])
    assert prep.channel_names == ["s1", "s3"]
    assert any("s2" in n and "NaN" in n for n in prep.notes)
    assert any("dead" in n for n in prep.notes)
    with pytest.raises(ValueError, match="no usable channel"):
        preprocess(np.full((100, 1), np.nan), fs, ["x"])


def test_identify_window_on_a_simple_record_and_config_errors():
    y, fs = _two_mode_record(8)
    w = Window("w1", 0, fs, ["s1", "s2", "s3"], y + 9.81)
    est = identify_window(w, IdentifyConfig(max_order=30))
    f = np.array([m.frequency_hz for m in est.modes])
    assert f.size == 2 and np.allclose(f, [2.0, 5.5], rtol=0.01)
    assert est.sensor_ids == ["s1", "s2", "s3"]
    for m in est.modes:
        assert np.max(np.abs(m.mode_shape)) == pytest.approx(1.0)
        assert m.mode_shape[np.argmax(np.abs(m.mode_shape))] == 1.0
        assert m.n_poles > 5 and np.isfinite(m.frequency_spread_hz)
        assert np.isfinite(m.frequency_std_hz) and m.frequency_std_hz < 0.02 * m.frequency_hz
    with pytest.raises(ValueError, match="method"):
        identify_window(w, IdentifyConfig(method="fdd"))
    with pytest.raises(ValueError, match="input channel"):
        identify_window(w, IdentifyConfig(method="ssi-io"))
    with pytest.raises(ValueError, match="reference_channels"):
        identify_window(w, IdentifyConfig(reference_channels=["nope"]))
    with pytest.raises(ValueError, match="unknown option"):
        IdentifyConfig.from_dict({"stability": {"freq_tol": 0.01, "bogus": 1}})


def test_example_configuration_loads():
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[1] / "examples" / "identify.yaml"
    cfg = IdentifyConfig.from_dict(yaml.safe_load(path.read_text()))
    assert cfg.preprocess.lowpass_hz == 20.0 and cfg.stability.two_a_mac_min == 0.9
