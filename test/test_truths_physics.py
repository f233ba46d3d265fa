"""The truth generator of test/truths/ against hand-computed physics (OpenSeesPy models)."""

from __future__ import annotations

import numpy as np
import pytest
from truths import assemble
from truths.apparent import transfer_peak
from truths.building import Building, draw_building
from truths.drivers import ar1
from truths.ground_motion import GroundMotion
from truths.opensees import eigen_hz, eigen_shapes, fresh, ops
from truths.story_state import Soil, Spring, StoryState
from truths.transient import run_event


def _symmetric(k1: float, k2: float, m1: float, m2: float) -> Building:
    """Two stories, four equal column lines, centre of mass at the plan centre; y twice as stiff."""
    share = np.full(4, 0.25)
    return Building(masses=np.array([m1, m2]), k_x=np.array([k1, k2]), k_y=2 * np.array([k1, k2]),
                    heights=np.array([3.5, 3.5]), plan=(20.0, 16.0), share_x=share, share_y=share,
                    cm_offset=(0.0, 0.0), zeta=(0.02, 0.02), damper_c=np.zeros(2), sensor_xy=(10.0, 8.0),
                    instrumented=[1, 2])


def test_one_dof_eigen_is_the_closed_form():
    m, k = 3.2e5, 7.9e7
    fresh(1, 1)
    ops.node(1, 0.0)
    ops.node(2, 0.0)
    ops.fix(1, 1)
    ops.mass(2, m)
    ops.uniaxialMaterial("Elastic", 1, k)
    ops.element("zeroLength", 1, 1, 2, "-mat", 1, "-dir", 1)
    f = eigen_hz(1)[0]
    assert f == pytest.approx(np.sqrt(k / m) / (2 * np.pi), rel=1e-10)


def test_two_story_shear_building_matches_the_hand_2x2_eigenproblem():
    k1, k2, m1, m2 = 2.4e8, 1.6e8, 4.0e5, 3.0e5
    assemble.build(_symmetric(k1, k2, m1, m2), StoryState.clean(2))
    f = eigen_hz(6)
    # det(K - w^2 M) = 0 with K = [[k1 + k2, -k2], [-k2, k2]], M = diag(m1, m2), by hand
    a, b, d = (k1 + k2) / m1, -k2 / m1, k2 / m2
    c = -k2 / m2
    disc = np.sqrt((a - d) ** 2 + 4 * b * c)
    hand = np.sqrt(np.array([(a + d - disc) / 2, (a + d + disc) / 2])) / (2 * np.pi)
    for fh in hand:
        assert np.min(np.abs(f / fh - 1)) < 1e-9, (f, hand)


def _torsion_share(b: Building) -> np.ndarray:
    """Per mode, the torsional part of the roof motion: r_g theta / |(u, v, r_g theta)|."""
    h = assemble.build(b, StoryState.clean(b.n))
    roof = h.masters[-1]
    _, phi = eigen_shapes(3, [(roof, 1), (roof, 2), (roof, 6)])
    r_g = np.sqrt((b.plan[0] ** 2 + b.plan[1] ** 2) / 12)
    phi[2] *= r_g
    return np.abs(phi[2]) / np.linalg.norm(phi, axis=0)


def test_eccentric_building_has_coupled_torsional_modes():
    sym = _torsion_share(_symmetric(2.4e8, 1.6e8, 4.0e5, 3.0e5))
    assert np.sort(sym)[:2].max() < 1e-8           # translational modes of the symmetric plan are pure
    for seed in range(5):
        share = _torsion_share(draw_building(np.random.default_rng(seed), 3))
        assert np.all((share > 1e-3) & (share < 1 - 1e-3)), (seed, share)  # no mode is pure
        assert np.sort(share)[1] > 0.03, (seed, share)  # a translational mode carries visible torsion


@pytest.mark.parametrize("seed", [11, 12])
def test_hysteretic_springs_soften_in_a_strong_event_and_recover(seed):
    rng = np.random.default_rng(seed)
    b = draw_building(rng, 1, f1_hz=3.0)
    rate, seg = 50.0, 24.0
    motions = [GroundMotion(fg=3.0, zg=0.6, duration_s=seg, t1_frac=0.05, t2_frac=0.5, decay=0.5)] * 3
    pga = (0.08, 1.6, 0.08)                       # a factor 20 between the weak and the strong part
    ax = np.concatenate([m.record(rng, rate, p) for m, p in zip(motions, pga, strict=True)])
    ay = 0.5 * np.concatenate([m.record(rng, rate, p) for m, p in zip(motions, pga, strict=True)])
    linear = run_event(b, StoryState.clean(1), ax, ay, rate)
    state = StoryState(k_factor=np.ones(1), spring=Spring.STEEL02, yield_drift=linear.peak_drift / 4,
                       nonlinear_share=0.6, nonlinear_stories=[0])
    r = run_event(b, state, ax, ay, rate)         # one continuous record: weak, strong, weak
    n = int(seg * rate)
    f = [transfer_peak(ax[i * n:(i + 1) * n], r.ax[i * n:(i + 1) * n, -1], rate, (1.0, 6.0)) for i in range(3)]
    assert f[1] < 0.93 * f[0], f                  # softer while strong
    assert abs(f[2] / f[0] - 1) < 0.04, f         # and back afterwards (no lasting loss; ~2 bins)
    assert np.min(np.abs(f[0] / linear.f0_hz - 1)) < 0.03, (f, linear.f0_hz)  # the x mode


def test_free_field_soil_lowers_the_first_frequency():
    for seed in range(3):
        rng = np.random.default_rng(seed)
        b = draw_building(rng, 3)
        assemble.build(b, StoryState.clean(3))
        fixed = eigen_hz(3)[0]
        soil = Soil(mass=float(b.masses[0]), k_sway=float(b.masses.sum()) * (2 * np.pi * fixed) ** 2 / 0.3,
                    yield_sway=0.01)
        assemble.build(b, StoryState(k_factor=np.ones(3), soil=soil))
        on_soil = eigen_hz(3)[0]
        # sway alone: 1/f^2 = 1/f_fix^2 + 1/f_sway^2 (f_sway^2 = f_fix^2 / 0.3) within the coupling
        assert on_soil < 0.93 * fixed
        assert on_soil == pytest.approx(fixed / np.sqrt(1.3), rel=0.05)


@pytest.mark.parametrize("rho", [0.9, 0.95, 0.99])
def test_ar1_driver_has_the_requested_rho(rho):
    n = 200_000
    x = ar1(np.random.default_rng(int(rho * 1000)), n, rho)
    r1 = np.corrcoef(x[:-1], x[1:])[0, 1]
    # sampling sd of the lag-1 estimate ~ sqrt((1 - rho^2) / n) <= 0.0022; 5 sd plus the O(1/n) bias
    assert abs(r1 - rho) < 5 * np.sqrt((1 - rho**2) / n) + 20 / n
