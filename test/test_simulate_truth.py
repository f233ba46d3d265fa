"""truth.json frequencies are the truth model's eigenvalues, and the recordings agree with them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import full_size
from scipy.linalg import eigh
from scipy.signal import welch

from shm_ros.core.models import build_model
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.campaign import write_campaign

SEEDS = [11, 12, 13, 14, 15, 16] if full_size() else [11, 12, 13]


@pytest.mark.parametrize("name", ["girder", "building"])
def test_truth_json_frequencies_are_eigenvalues_of_the_truth_model(tmp_path, name):
    sc = named_scenario(name, n_windows=3, window_s=20.0, seed=4, t_mean_c=0.0)
    from shm_ros.core.simulate import EffectRequest

    sc.effects = [EffectRequest("temperature_linear")]
    c = simulate_campaign(sc)
    files = write_campaign(c, tmp_path)
    truth = json.loads(files.truth.read_text())
    assert truth["seed"] == 4 and "provenance" in truth and truth["schema_version"]
    tm = c.truth_model
    for i, w in enumerate(truth["windows"]):
        theta = tm.theta(c.factors(i))
        f = _dense_frequencies(tm, theta)  # every family, ascending
        got = np.array(w["frequencies_hz"])
        # the entry lists the lowest six in-plane modes and every mode below the sixth
        # 1e-6: a stiff deck swaying on soft lateral bearings is an ill-conditioned eigenproblem
        # (subset and dense solvers agree to ~3e-7 on those modes)
        assert np.allclose(got, f[: got.size], rtol=1e-6), (got, f)
        assert w["mode_families"].count(tm.in_plane_family) == 6
        assert w["temperature_c"] == pytest.approx(c.conditions(i).temperature_c, abs=1e-3)
    # the windows differ because temperature differs, and truth follows
    fr = np.array([w["frequencies_hz"][0] for w in truth["windows"]])
    assert np.ptp(fr) > 0


def _dense_frequencies(tm, theta):
    """Independent: full dense eigenproblems of the truth model's matrices. Girder: vertical bending
    coupled to torsion by the eccentric mass, and lateral bending; building: the complex modes of
    the state space of M, K, C (non-classical damping: |lambda| is not the undamped frequency)."""
    from scipy.linalg import eig

    if tm.kind == "girder":
        Kv, Kt = tm.model.stiffness(theta), tm.torsion.stiffness(theta)
        Mv, Mt = tm.model.mass(theta), tm.torsion.mass(theta)
        Cvt = sum(t * c for t, c in zip(theta, tm.coupling, strict=True) if c is not None)
        K = np.block([[Kv, np.zeros((Kv.shape[0], Kt.shape[0]))], [np.zeros((Kt.shape[0], Kv.shape[0])), Kt]])
        M = np.block([[Mv, Cvt], [Cvt.T, Mt]])
        lam = np.concatenate([eigh(K, M, eigvals_only=True),
                              eigh(tm.lateral.stiffness(theta), tm.lateral.mass(theta), eigvals_only=True)])
        return np.sort(np.sqrt(lam)) / (2 * np.pi)
    m = tm.building_matrices(theta, {})
    n = m["M"].shape[0]
    Minv = np.linalg.inv(m["M"])
    lam = eig(np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ m["K"], -Minv @ m["C"]]]))[0]
    return np.sort(np.abs(lam[lam.imag > 0])) / (2 * np.pi)


def _in_plane(entry, key="frequencies_hz"):
    fam = entry["mode_families"]
    inplane = "vertical" if "vertical" in fam else "x"
    return [v for v, f in zip(entry[key], fam, strict=True) if f == inplane]


def _psd_peak(freqs, psd, f0, half_band=0.04, context=0.15):
    """Resonance frequency near f0 from a least-squares fit of one mode's acceleration PSD (plus a
    floor) to the Welch PSD within +-half_band, and the peak's height over the median PSD within
    +-context (a resonance stands out of its neighbourhood)."""
    from scipy.optimize import curve_fit

    near = (freqs > f0 * (1 - context)) & (freqs < f0 * (1 + context))
    band = (freqs > f0 * (1 - half_band)) & (freqs < f0 * (1 + half_band))
    fb, pb = freqs[band], psd[band]
    k = int(np.argmax(pb))

    def model(f, fn, z, a, b):
        r = f / fn
        return np.log(a * r**4 / ((1 - r * r) ** 2 + (2 * z * r) ** 2) + b)

    p0 = [fb[k], 0.02, pb[k] * (2 * 0.02) ** 2, np.min(pb)]
    popt, _ = curve_fit(model, fb, np.log(pb), p0=p0, bounds=([fb[0], 1e-4, 0, 0], [fb[-1], 0.2, np.inf, np.inf]))
    return popt[0], pb[k] / np.median(psd[near])


@pytest.mark.parametrize("name", ["girder", "building"])
def test_welch_peaks_of_long_windows_agree_with_truth_within_1pct(name):
    """Independent check on the recorded samples (offsets, noise, quantisation and all): each of the
    first three true frequencies is a clear PSD peak within 1 %, for every seed."""
    for seed in SEEDS:
        sc = named_scenario(name, n_windows=1, window_s=1800.0, seed=seed)
        c = simulate_campaign(sc)
        w = c.window(0)
        truth = w.truth
        x = w.recording.values - w.recording.values.mean(axis=0)
        out = [i for i, s in enumerate(w.sensor_ids) if s != truth.get("input_sensor")]
        freqs, P = welch(x[:, out], fs=sc.fs, nperseg=2 ** 14, axis=0)
        # normalise each channel so that one loud sensor does not hide a mode
        psd = (P / P.sum(axis=0)).sum(axis=1)
        for f_true in _in_plane(truth)[:3]:
            f_peak, prominence = _psd_peak(freqs, psd, f_true)
            assert abs(f_peak - f_true) / f_true < 0.01, (name, seed, f_true, f_peak)
            assert prominence > 5.0, (name, seed, f_true, prominence)


def test_nominal_model_is_not_the_truth_model():
    """No inverse crime: the nominal file's model and the truth model disagree like reality does."""
    for name in ("girder", "building"):
        c = simulate_campaign(named_scenario(name, n_windows=1, window_s=10.0, seed=3))
        nominal = build_model(structure_from_dict(c.nominal_structure))
        f_nom = nominal.modes(n_modes=3).frequencies_hz
        w = c.window(0)
        f_true = np.array(_in_plane(w.truth)[:3])
        rel = np.abs(f_true - f_nom) / f_nom
        assert rel.max() > 0.005 and rel.max() < 0.25, (name, f_nom, f_true)
        if name == "girder":
            tm = c.truth_model
            assert tm.spec.girder.elements_per_span == 4 * c.truth_model.nominal.girder.elements_per_span
            dx = [abs(tm.info["sensor_x"][s.id] - s.x) for s in tm.nominal.sensors]
            assert 0.0 < max(dx) < 1.0
            # damping is not the nominal Rayleigh 2 %/2 %
            assert not np.allclose(_in_plane(w.truth, "damping_ratios")[:2], 0.02, atol=2e-3)


@pytest.mark.parametrize("name", ["girder", "building"])
def test_truth_mode_shapes_match_the_recorded_deflection_shapes(name):
    """Independent check of ``mode_shapes``: the first singular vector of the recorded cross-spectral
    matrix at each of the first three true frequencies (frequency-domain decomposition) has a MAC
    above 0.98 with the truth's shape, for every seed."""
    from scipy.signal import csd

    for seed in SEEDS:
        c = simulate_campaign(named_scenario(name, n_windows=1, window_s=1200.0, seed=seed))
        w = c.window(0)
        out = [i for i, s in enumerate(w.sensor_ids) if s != w.truth.get("input_sensor")]
        ids = [w.sensor_ids[i] for i in out]
        x = w.recording.values[:, out] - w.recording.values[:, out].mean(axis=0)
        n = len(out)
        spectra = {}
        for a in range(n):
            for b in range(a, n):
                f, spectra[a, b] = csd(x[:, a], x[:, b], fs=c.scenario.fs, nperseg=2 ** 13)
        inplane = [k for k, f in enumerate(w.truth["mode_families"]) if f == c.truth_model.in_plane_family]
        for k in inplane[:3]:
            f_true = w.truth["frequencies_hz"][k]
            j = int(np.argmin(np.abs(f - f_true)))
            G = np.empty((n, n), complex)
            for (a, b), s_ab in spectra.items():
                G[a, b], G[b, a] = s_ab[j], np.conj(s_ab[j])
            u = np.linalg.svd(G)[0][:, 0]
            phi = np.array([w.truth["mode_shapes"][s][k] for s in ids])
            mac = abs(np.vdot(phi, u)) ** 2 / (np.vdot(phi, phi).real * np.vdot(u, u).real)
            assert mac > 0.98, (name, seed, k, mac)
