"""Each hidden effect changes the true modal properties by its documented amount (docs/simulator.md)
and never shows up in the nominal structure file."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from shm_ros.core.simulate import EffectRequest, named_scenario, simulate_campaign
from shm_ros.core.simulate.effects import EFFECTS


def _campaign(name, effects=(), n_windows=1, window_s=10.0, seed=7, **kw):
    kw.setdefault("t_daily_c", 0.0)
    kw.setdefault("t_drift_c", 0.0)
    sc = named_scenario(name, n_windows=n_windows, window_s=window_s, seed=seed, **kw)
    sc.effects = [EffectRequest(k, dict(p)) for k, p in effects]
    return simulate_campaign(sc)


def _truth(c, i=0):
    return c.window(i).truth


def _in_plane(t, key="frequencies_hz", n=6):
    """The in-plane modes of a truth entry (the out-of-plane ones come in between)."""
    fam = t["mode_families"]
    inplane = "vertical" if "vertical" in fam else "x"
    return np.array([v for v, f in zip(t[key], fam, strict=True) if f == inplane][:n])


def _ratios(a, b, n=3):
    return _in_plane(a, n=n) / _in_plane(b, n=n)


def _energy_share(c, group, i=0):
    """First-order (Rayleigh quotient) share of each mode's strain energy in a parameter group."""
    tm = c.truth_model
    theta = tm.theta(c.factors(i))
    sol = tm.model.modes(theta, n_modes=3)
    K = tm.model.stiffness(theta)
    Kg = sum(theta[j] * tm.model.K_terms[j] for j in tm.groups[group])
    phi = sol.shapes
    return np.einsum("ij,ik,kj->j", phi, Kg, phi) / np.einsum("ij,ik,kj->j", phi, K, phi)


def _assert_hidden(c_effect, c_plain, key):
    """The nominal structure file is byte-for-byte the same and does not name the effect."""
    a = yaml.safe_dump(c_effect.nominal_structure, sort_keys=True)
    b = yaml.safe_dump(c_plain.nominal_structure, sort_keys=True)
    assert a == b
    name = EFFECTS[key][0]
    assert key not in a and name not in a


@pytest.mark.parametrize("name,key,params,t_mean", [
    ("girder", "temperature_linear", {}, 25.0),
    ("girder", "temperature_bilinear", {}, -4.0),
    ("girder", "damage", {"at": 0}, 10.0),
    ("girder", "repair", {"at": 0}, 10.0),
    ("building", "temperature_linear", {}, 30.0),
    ("building", "damage", {"at": 0, "where": "story2"}, 15.0),
])
def test_stiffness_effects_follow_the_first_order_energy_share(name, key, params, t_mean):
    """Documented amount: r_j^2 - 1 = s_j (F - 1) to first order, s_j = share of mode j's strain
    energy in the scaled part, F = stiffness factor (exactly sqrt(F) for a uniformly scaled building).
    The shares are those of the in-plane model, so the amounts are checked on the planar truth (model
    form off); on the richer truth the in-plane modes move the same way (a deck's vertical modes
    hybridise with its torsion modes, which the same effect moves too)."""
    rich = _ratios(_truth(_campaign(name, [(key, params)], t_mean_c=t_mean)), _truth(_campaign(name, t_mean_c=t_mean)))
    F_rich = _campaign(name, [(key, params)], t_mean_c=t_mean).factors(0)
    assert np.all(np.sign(rich - 1) == np.sign(list(F_rich.values())[0] - 1)), rich
    plain = _campaign(name, t_mean_c=t_mean, model_form=False)
    eff = _campaign(name, [(key, params)], t_mean_c=t_mean, model_form=False)
    _assert_hidden(eff, plain, key)
    te, tp = _truth(eff), _truth(plain)
    (group, F), = te["effect_factors"].items()
    # the factor is the documented formula of the window's true temperature / time
    p = eff.effects[0].params
    if key.startswith("temperature"):
        expect = 1 + p["alpha_per_c"] * (te["temperature_c"] - p["t_ref_c"])
        if key == "temperature_bilinear":
            expect += p["below_per_c"] * min(te["temperature_c"] - p["knee_c"], 0.0)
        assert F == pytest.approx(expect, rel=1e-12)
    else:
        assert F == p["factor"]
    r = _ratios(te, tp)
    assert np.max(np.abs(r - 1)) > 0.003  # visible
    s = _energy_share(plain, group)
    predicted = 1 + s * (F - 1)
    assert np.all(np.abs(r**2 - predicted) <= 0.12 * abs(F - 1) + 1e-9), (r**2, predicted)
    if name == "building" and group == "EI":
        assert np.allclose(r, np.sqrt(F), rtol=1e-9)


def test_bilinear_knee_makes_frequencies_jump_below_freezing():
    c = _campaign("girder", [("temperature_bilinear", {})], n_windows=24, window_s=5.0, t_mean_c=0.0,
                  t_daily_c=5.0, pause_s=3595.0)
    rows = [(c.conditions(i).temperature_c, c.truth_model.system(c.factors(i))[1].frequencies_hz[0])
            for i in range(c.n_windows)]
    T, f = np.array(rows).T
    assert T.min() < -2 and T.max() > 2
    warm, cold = T > 0.5, T < -0.5
    slope_warm = np.polyfit(T[warm], f[warm], 1)[0]
    slope_cold = np.polyfit(T[cold], f[cold], 1)[0]
    assert slope_warm < 0 and slope_cold < 10 * slope_warm  # much steeper below the knee


def test_frozen_bearings_stiffen_the_girder():
    plain = _campaign("girder", t_mean_c=-5.0)
    eff = _campaign("girder", [("temperature_bilinear", {"where": "bearings"})], t_mean_c=-5.0)
    _assert_hidden(eff, plain, "temperature_bilinear")
    te = _truth(eff)
    assert te["effect_factors"]["bearings"] > 50
    r = _ratios(te, _truth(plain))
    assert np.all(r > 1.03) and np.all(r < 1.25)


@pytest.mark.parametrize("name,fraction", [("girder", 0.06), ("building", 0.08)])
def test_added_mass_lowers_every_frequency_by_one_over_sqrt(name, fraction):
    plain = _campaign(name)
    eff = _campaign(name, [("added_mass", {"fraction": fraction, "when": "always"})])
    _assert_hidden(eff, plain, "added_mass")
    # |lambda| of complex (non-classically damped) modes is not exactly the undamped frequency: 1e-4
    assert np.allclose(_ratios(_truth(eff), _truth(plain), 6), 1 / np.sqrt(1 + fraction), rtol=1e-4)


def test_added_mass_of_rush_hour_traffic_only_in_rush_hours():
    c = _campaign("girder", [("added_mass", {})], n_windows=48, window_s=5.0, pause_s=1795.0)
    for i in range(c.n_windows):
        h = c.conditions(i).local_hour
        rush = (7.0 <= h < 9.5) or (17.0 <= h < 19.5)
        assert c.factors(i) == ({"mass": 1.06} if rush else {})


def test_girder_support_flexibility_is_a_series_soil_spring():
    plain = _campaign("girder")
    eff = _campaign("girder", [("support_flexibility", {"k_soil_n_m": 2.0e9})])
    _assert_hidden(eff, plain, "support_flexibility")
    kb = np.array([b.k_vertical for b in plain.truth_model.spec.girder.bearings])
    ke = np.array([b.k_vertical for b in eff.truth_model.spec.girder.bearings])
    assert np.allclose(ke, 1 / (1 / kb + 1 / 2.0e9), rtol=1e-12)
    r = _ratios(_truth(eff), _truth(plain))
    assert np.all(r < 0.99) and r[0] > 0.9


def test_building_foundation_sway_lowers_frequencies_and_moves_the_ground_sensor():
    plain = _campaign("building", window_s=120.0)
    eff = _campaign("building", [("support_flexibility", {})], window_s=120.0)
    _assert_hidden(eff, plain, "support_flexibility")
    assert eff.truth_model.model.n_dof == plain.truth_model.model.n_dof + 3  # x, y, twist of the foundation
    te, tp = _truth(eff), _truth(plain)
    r = _ratios(te, tp)
    assert np.all(r < 0.985) and np.all(r > 0.9)
    # the ground sensor now sits on a moving foundation: it has a mode-shape component
    assert abs(te["mode_shapes"]["g0"][0]) > 0.01 and tp["mode_shapes"]["g0"][0] == 0.0


def test_kelvin_voigt_dampers_scale_frequencies_and_add_damping_exactly():
    """Closed-form amounts hold for the planar shear building (model form off: classical damping,
    no flexural part the braces do not stiffen); the richer truth follows them to a few per cent."""
    k_rel, c_rel = 0.3, 0.02
    plain = _campaign("building", model_form=False)
    eff = _campaign("building", [("damper", {"k_rel": k_rel, "c_rel_s": c_rel, "fail_at": "1h"})],
                    n_windows=2, pause_s=3600.0, model_form=False)
    _assert_hidden(eff, plain, "damper")
    t0, t1, tp = _truth(eff, 0), _truth(eff, 1), _truth(plain)
    assert np.allclose(_ratios(t0, tp, 6), np.sqrt(1 + k_rel), rtol=1e-9)
    a0, a1 = plain.truth_model.rayleigh
    w = 2 * np.pi * np.array(t0["frequencies_hz"])
    zeta = a0 / (2 * w) + (a1 + c_rel * k_rel) / (1 + k_rel) * w / 2
    assert np.allclose(t0["damping_ratios"], zeta, rtol=1e-8)
    # damper failure (fail_factor 0) at 1 h: back to the bare frame, ~12 % lower as in the paper
    assert np.allclose(t1["frequencies_hz"], tp["frequencies_hz"], rtol=1e-9)
    assert 1 - t1["frequencies_hz"][0] / t0["frequencies_hz"][0] == pytest.approx(1 - 1 / np.sqrt(1.3), rel=1e-6)
    rich = _ratios(_truth(_campaign("building", [("damper", {"k_rel": k_rel, "c_rel_s": c_rel})])),
                   _truth(_campaign("building")), 6)
    assert np.allclose(rich, np.sqrt(1 + k_rel), rtol=0.03), rich


def test_maxwell_dampers_stiffen_less_than_kelvin_voigt_and_add_damping():
    plain = _truth(_campaign("building"))
    kv = _truth(_campaign("building", [("damper", {})]))
    mx = _truth(_campaign("building", [("damper", {"model": "maxwell"})]))
    r_mx, r_kv = _ratios(mx, plain), _ratios(kv, plain)
    assert np.all(r_mx > 1.0) and np.all(r_mx < r_kv + 1e-12)
    assert np.all(_in_plane(mx, "damping_ratios", 3) > 1.5 * _in_plane(plain, "damping_ratios", 3))


def test_amplitude_dependent_stiffness_and_damping_follow_the_equivalent_linear_model():
    """Exact eigenvalues are assembled here for the planar building (model form off); the richer
    truth is checked for the same direction of change."""
    rich = _campaign("building-earthquake", [("amplitude_stiffness", {"drift_ref_m": 0.005}),
                                             ("amplitude_damping", {"velocity_ref_m_s": 0.01})], window_s=60.0, seed=3)
    tr, trp = _truth(rich), _truth(_campaign("building-earthquake", window_s=60.0, seed=3))
    assert np.all(_ratios(tr, trp) < 0.995)
    assert _in_plane(tr, "damping_ratios")[0] > 1.05 * _in_plane(trp, "damping_ratios")[0]
    kw = dict(window_s=60.0, seed=3, model_form=False)
    plain = _campaign("building-earthquake", **kw)
    eff = _campaign("building-earthquake", [("amplitude_stiffness", {"drift_ref_m": 0.005}),
                                            ("amplitude_damping", {"velocity_ref_m_s": 0.01})], **kw)
    _assert_hidden(eff, plain, "amplitude_stiffness")
    _assert_hidden(eff, plain, "amplitude_damping")
    te, tp = _truth(eff), _truth(plain)
    eq = te["equivalent_linear"]
    from shm_ros.core.simulate.newmark import equivalent_damping_factor, equivalent_stiffness_factor

    assert np.allclose(eq["stiffness_factor"], equivalent_stiffness_factor(np.array(eq["story_drift_rms_m"]), 0.005))
    assert np.allclose(eq["damping_factor"], equivalent_damping_factor(np.array(eq["story_velocity_rms_m_s"]), 0.01))
    # frequencies and damping: complex eigenvalues of the equivalent-linear model, assembled here
    # from the stored story factors (story springs k_i, story dashpots a1 k_i, mass-proportional a0)
    from scipy.linalg import eig

    tm = eff.truth_model
    k0 = tm.info["k_story"]
    k = k0 * np.array(eq["stiffness_factor"])
    c = tm.rayleigh[1] * k0 * np.array(eq["damping_factor"])
    n = k.size
    E = np.eye(n) - np.eye(n, k=-1)
    K, M = E.T @ np.diag(k) @ E, tm.model.mass(tm.theta({}))
    C = tm.rayleigh[0] * M + E.T @ np.diag(c) @ E
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = eig(A)[0]
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))][:3]
    assert np.allclose(te["frequencies_hz"][:3], np.abs(lam) / (2 * np.pi), rtol=1e-9)
    assert np.allclose(te["damping_ratios"][:3], -lam.real / np.abs(lam), rtol=1e-7)
    r = _ratios(te, tp)
    assert np.all(r < 0.995)  # visibly softer under the earthquake
    assert te["damping_ratios"][0] > 1.05 * tp["damping_ratios"][0]


def test_unknown_or_misplaced_effects_fail_clearly():
    from shm_ros.core.simulate import EffectError

    with pytest.raises(EffectError, match="unknown effect"):
        _campaign("girder", [("snow", {})])
    with pytest.raises(EffectError, match="not available for girder"):
        _campaign("girder", [("damper", {})])
    with pytest.raises(EffectError, match="unknown parameter"):
        _campaign("building", [("added_mass", {"fractoin": 0.1})])


def test_story_damage_on_a_building_with_foundation_sway_hits_the_named_story():
    soil = _campaign("building", [("support_flexibility", {})])
    both = _campaign("building", [("support_flexibility", {}), ("damage", {"at": 0, "where": "story1"})])
    tm = both.truth_model
    theta = tm.theta(both.factors(0))
    k = tm.building_matrices(theta, both.factors(0))["k_story"]
    k0 = soil.truth_model.building_matrices(soil.truth_model.theta({}), {})["k_story"]
    # foundation springs (x, y, twist) untouched, story 1 (its x, y and twist rows) at 0.85
    assert np.allclose(k / k0, [1.0] * 3 + [0.85] * 3 + [1.0] * (k.size - 6))
    assert np.all(_ratios(_truth(both), _truth(soil)) < 1.0)


def test_girder_amplitude_effects_follow_the_window_rms_acceleration():
    """Girder (equivalent linear per window): deck stiffness x 1/(1 + a/a_ref), modal damping
    x (1 + a/a_ref), a = the window's RMS acceleration; windows with more traffic are softer."""
    kw = dict(n_windows=4, window_s=120.0, seed=3, pause_s=3 * 3600.0)
    plain = _campaign("girder", **kw)
    eff = _campaign("girder", [("amplitude_stiffness", {"accel_ref_m_s2": 1.0}),
                               ("amplitude_damping", {"accel_ref_m_s2": 0.2})], **kw)
    _assert_hidden(eff, plain, "amplitude_stiffness")
    rows = []
    for i in range(4):
        te, tp = _truth(eff, i), _truth(plain, i)
        eq = te["equivalent_linear"]
        a = eq["rms_accel_m_s2"]
        assert abs(a - eq["rms_accel_response_m_s2"]) < 0.02 * a  # the fixed point converged
        assert eq["stiffness_factor"] == pytest.approx(1 / (1 + a / 1.0), rel=1e-12)
        assert np.allclose(_in_plane(te, "damping_ratios") / _in_plane(tp, "damping_ratios"), 1 + a / 0.2, rtol=1e-9)
        r = _ratios(te, tp)
        s = _energy_share(plain, "EI", i)
        F = eq["stiffness_factor"]
        assert np.all(np.abs(r**2 - (1 + s * (F - 1))) <= 0.12 * abs(F - 1))
        rows.append((a, r[0]))
    a, r = np.array(rows).T
    assert np.ptp(a) > 0.2 * a.mean() and np.corrcoef(a, r)[0, 1] < -0.9
