"""The simulator's integrators against independent references (scipy discretisation, eigensolvers)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eig
from scipy.signal import cont2discrete, dlsim

from shm_ros.core.modal import real_shape
from shm_ros.core.simulate import EffectRequest, named_scenario, simulate_campaign
from shm_ros.core.simulate.campaign import rng_for
from shm_ros.core.simulate.linear import from_real_modes, from_state_space


def _reference(A, B, C, D, u, dt):
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), dt, method="foh")
    _, y, _ = dlsim((Ad, Bd, Cd, Dd, dt), u)
    return y


@pytest.mark.parametrize("f_hz,zeta", [(0.7, 0.01), (3.0, 0.05), (19.0, 0.3)])
def test_modal_filters_match_scipy_first_order_hold(f_hz, zeta):
    rng = np.random.default_rng(3)
    dt = 0.01
    u = rng.standard_normal((4000, 2))
    w = 2 * np.pi * f_hz
    A = np.array([[0, 1], [-w * w, -2 * zeta * w]])
    P = np.array([[0.7, -1.3]])  # modal force per input
    B = np.vstack([np.zeros((1, 2)), P])
    C = np.array([[-w * w, -2 * zeta * w]]) * 2.5  # acceleration of a DOF with shape value 2.5
    D = 2.5 * P
    ref = _reference(A, B, C, D, u, dt)
    real = from_real_modes([f_hz], [zeta], P, np.array([[2.5]])).simulate(u, dt)
    ss = from_state_space(A, B, C, D).simulate(u, dt)
    scale = np.max(np.abs(ref))
    assert np.max(np.abs(real - ref)) < 1e-9 * scale
    assert np.max(np.abs(ss - ref)) < 1e-9 * scale


def test_state_space_with_maxwell_damper_matches_scipy():
    """Non-proportional damping and an internal damper state: complex modes, exact response."""
    rng = np.random.default_rng(5)
    n = 4
    M = np.diag(rng.uniform(1, 2, n))
    k = rng.uniform(50, 100, n)
    E = np.eye(n) - np.eye(n, k=-1)
    K = E.T @ (k[:, None] * E)
    C = 0.05 * M + E.T @ np.diag([0.5, 0, 0, 0]) @ E
    kd, cd = 30.0, 3.0
    e0 = E[0]
    ns = 2 * n + 1
    A = np.zeros((ns, ns))
    Mi = np.linalg.inv(M)
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -Mi @ K
    A[n:2 * n, n:2 * n] = -Mi @ C
    A[n:2 * n, 2 * n] = -Mi @ e0
    A[2 * n, n:2 * n] = kd * e0
    A[2 * n, 2 * n] = -kd / cd
    B = np.zeros((ns, 1))
    B[n:2 * n, 0] = Mi @ np.ones(n)
    Cy = A[n:2 * n, :]
    Dy = B[n:2 * n, :]
    u = rng.standard_normal((3000, 1))
    sys = from_state_space(A, B, Cy, Dy)
    y = sys.simulate(u, 0.02)
    ref = _reference(A, B, Cy, Dy, u, 0.02)
    assert np.max(np.abs(y - ref)) < 1e-8 * np.max(np.abs(ref))
    lam = eig(A)[0]
    osc = np.sort(np.abs(lam[lam.imag > 1e-9]))
    assert np.allclose(np.sort(np.abs(sys.poles[sys.conjugate])), osc, rtol=1e-10)
    assert np.count_nonzero(~sys.conjugate) == np.count_nonzero(np.abs(lam.imag) <= 1e-9)


def test_real_shape_rotates_and_normalises():
    v = np.array([0.3, -1.0, 0.5]) * np.exp(1j * 0.7)
    r = real_shape(v)
    assert np.allclose(r, np.array([0.3, -1.0, 0.5]) / -1.0)
    assert r[np.argmax(np.abs(r))] == 1.0


def test_newmark_reduces_to_the_exact_linear_response_at_small_amplitude():
    """The nonlinear integrator with huge reference amplitudes is the linear model: it must agree
    with the exact modal integration (Newmark's period error is O(dt^2): 0.1 % at 10 Hz and 500 Hz)."""
    sc = named_scenario("building", n_windows=1, window_s=30.0, fs=500.0)
    sc.effects = [EffectRequest("amplitude_stiffness", {"drift_ref_m": 1e6}),
                  EffectRequest("amplitude_damping", {"velocity_ref_m_s": 1e6})]
    c = simulate_campaign(sc)
    sys, _ = c.truth_model.system({})
    u, _ = c._inputs(rng_for(1, 3, 0), 15000, c.conditions(0), 0)
    y_lin = sys.simulate(u, 1 / 500.0)
    # x, y, theta per floor with eccentric mass: Newmark runs in coordinates where the ground's x
    # acceleration moves every coordinate alike (BuildingTruth.nonlinear_response)
    y_nl, eq = c.truth_model.nonlinear_response({}, c.effects, u, 1 / 500.0, 5000)
    err = np.sqrt(np.mean((y_nl[5000:] - y_lin[5000:]) ** 2, axis=0))
    rms = np.sqrt(np.mean(y_lin[5000:] ** 2, axis=0))
    rows = np.array([r for r in range(3, y_lin.shape[1]) if r % 3 < 2])  # x and y of the floor sensors
    assert np.all(err[rows] < 0.02 * rms[rows]), (err, rms)
    assert np.allclose(y_nl[:, 0], u[:, 0]) and np.allclose(y_nl[:, 1], u[:, 1])  # the ground sensor
    assert np.allclose(eq["k_scale"], 1.0, atol=1e-6) and np.allclose(eq["c_scale"], 1.0, atol=1e-6)


def test_equivalent_factors_match_monte_carlo():
    from shm_ros.core.simulate.newmark import equivalent_damping_factor, equivalent_stiffness_factor

    rng = np.random.default_rng(0)
    d = 0.004 * rng.standard_normal(400_000)
    mc = np.mean(1.0 / (1.0 + np.abs(d) / 0.01) ** 2)
    assert abs(equivalent_stiffness_factor(np.array([0.004]), 0.01)[0] - mc) < 2e-3
    mc_c = np.mean(1.0 + 2.0 * np.abs(d) / 0.02)
    assert abs(equivalent_damping_factor(np.array([0.004]), 0.02) - mc_c) < 2e-3


def test_projected_loads_equal_the_dense_load_history_projected():
    from shm_ros.core.simulate import excitation as ex

    x = np.linspace(1.0, 29.0, 25)
    proj = np.random.default_rng(0).standard_normal((25, 4))
    for fn, kw in ((ex.traffic_loads, dict(point_x=x, length=30.0, vehicles_per_hour=3000.0,
                                           support_x=np.array([0.0, 15.0, 30.0]))),
                   (ex.wind_loads, dict(n_points=25, rms_n=100.0))):
        dense = fn(np.random.default_rng(4), 3000, 100.0, **kw)
        proj_out = fn(np.random.default_rng(4), 3000, 100.0, projection=proj, **kw)
        if isinstance(dense, tuple):
            assert dense[1] == proj_out[1] and dense[1] > 10
            dense, proj_out = dense[0], proj_out[0]
        assert np.abs(dense).max() > 0
        assert np.allclose(dense @ proj, proj_out, rtol=1e-10, atol=1e-9 * np.abs(proj_out).max())
