"""A mode's frequency without the robot (shm_ros/core/roving/carrier_mass.py): the setups' frequencies
fall linearly with the squared component at the robot's point; the fit's intercept is the unloaded
frequency."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.roving.carrier_mass import carrier_mass, shifted_median, unloaded_frequency


def test_the_intercept_at_a_node_is_the_frequency_without_the_robot():
    # f0 = 6.25 Hz; a robot of 1 % of the modal mass: f = f0 (1 - 0.005 phi^2)
    phi2 = np.array([0.0, 0.1, 0.36, 0.64, 1.0, 0.25])
    f = 6.25 * (1 - 0.005 * phi2)
    f0, b = unloaded_frequency(f, phi2)
    assert f0 == pytest.approx(6.25, rel=1e-12) and b == pytest.approx(6.25 * 0.005, rel=1e-9)
    # the setups' mean would be 0.2 % low
    assert np.mean(f) / 6.25 - 1 < -0.0019


def test_a_rise_with_the_robot_or_too_little_spread_keeps_the_mean():
    phi2 = np.array([0.0, 0.3, 0.6, 1.0])
    assert unloaded_frequency(6.0 * (1 + 0.001 * phi2), phi2) is None  # a mass cannot raise it
    assert unloaded_frequency([6.0, 5.99, 5.98, 5.97], [0.8, 0.85, 0.9, 0.95]) is None  # span < 0.25
    assert unloaded_frequency([6.0, 5.99, 5.98], [0.0, 0.5, 1.0]) is None  # fewer than 4 setups
    # a fall lost in the setups' scatter, with a gate at two standard errors
    scattered = ([6.0, 5.99, 6.01, 5.99, 5.995, 6.0], [0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert unloaded_frequency(*scattered, min_t=2.0) is None and unloaded_frequency(*scattered) is not None


def test_one_mass_over_the_modes_of_interest_and_the_shifted_median():
    # three modes, one robot of 2,000 kg; u = phi^2 / M (1/kg) with modal masses 1.9e5, 2.9e5, 2.4e5 kg
    rng = np.random.default_rng(3)
    f0, masses = np.array([6.24, 16.6, 18.3]), np.array([1.9e5, 2.9e5, 2.4e5])
    phi2 = [rng.uniform(0, 1, 12) for _ in f0]
    u = [p / m for p, m in zip(phi2, masses, strict=True)]
    f = [f0[j] * (1 - 2000.0 * u[j] / 2) for j in range(3)]
    m = carrier_mass(f, u)
    # the linearised fit uses each mode's mean frequency for f0: exact to second order in the shift
    assert m == pytest.approx(2000.0, rel=5e-3)
    for j in range(3):
        assert shifted_median(f[j], u[j], m) == pytest.approx(f0[j], rel=2e-5)
    # one setup far off (a wrong pick) moves the median by less than the mean
    bad = f[1].copy()
    bad[0] *= 1.03
    assert abs(shifted_median(bad, u[1], m) / f0[1] - 1) < 0.2 * abs(np.mean(bad * (1 + m * u[1] / 2)) / f0[1] - 1)
    # a frequency that rises with the robot is scatter: the mass is clipped at 0, not negative
    rising = [f0[j] * (1 + 2000.0 * u[j] / 2) for j in range(3)]
    assert carrier_mass(rising, u) == 0.0
    assert carrier_mass([f[0][:3]], [u[0][:3]]) is None  # fewer than four setups
    assert np.isnan(shifted_median([np.nan], [1e-6], 2000.0))
