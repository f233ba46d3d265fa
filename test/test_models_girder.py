"""Girder model vs closed-form / exact beam solutions, with mesh convergence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from shm_ros.core.models import build_model
from shm_ros.core.models.beam import deck_observation
from shm_ros.core.structure import structure_from_dict

E, I, A, RHO = 3.4e10, 2.1, 5.2, 2500.0
STIFF = 1.0e14  # N/m: bearings ~1e6 times stiffer than the spans (pinned supports)


def girder_dict(spans, sections=None, bearings=None, eps=10, sensors=None, k=STIFF):
    ends = np.concatenate([[0.0], np.cumsum(spans)])
    return {
        "name": "test-girder",
        "kind": "girder",
        "girder": {
            "spans": list(map(float, spans)),
            "elements_per_span": eps,
            "section": sections or {"E": E, "I": I, "A": A, "rho": RHO},
            "bearings": bearings or [{"x": float(x), "k_vertical": k, "k_rotation": 0.0} for x in ends],
        },
        "sensors": sensors or [{"id": "s1", "at": {"x": float(spans[0]) / 3}, "direction": "vertical"}],
    }


def exact_pinned_beam_frequencies(spans, EIs, mAs, n_modes, f_max):
    """Exact natural frequencies of a continuous Euler-Bernoulli beam on rigid pinned supports.

    Independent of the FE model: per span w = a sin(bx) + b cos(bx) + c sinh(bx) + d cosh(bx) with
    b^4 = omega^2 m / EI; zero deflection at every support, zero moment at the two ends, continuity
    of slope and moment over interior supports; roots of the determinant in omega.
    """
    n = len(spans)

    def matrix(w):
        Mx = np.zeros((4 * n, 4 * n))
        r = 0
        beta = [(w * w * mAs[k] / EIs[k]) ** 0.25 for k in range(n)]

        def funcs(k, x, deriv):
            b = beta[k]
            s, c, sh, ch = np.sin(b * x), np.cos(b * x), np.sinh(b * x), np.cosh(b * x)
            table = {
                0: [s, c, sh, ch],
                1: [b * c, -b * s, b * ch, b * sh],
                2: [-b * b * s, -b * b * c, b * b * sh, b * b * ch],
            }
            return np.array(table[deriv])

        for k in range(n):
            Mx[r, 4 * k : 4 * k + 4] = funcs(k, 0.0, 0)
            r += 1
            Mx[r, 4 * k : 4 * k + 4] = funcs(k, spans[k], 0)
            r += 1
        Mx[r, 0:4] = funcs(0, 0.0, 2)
        r += 1
        Mx[r, 4 * (n - 1) : 4 * n] = funcs(n - 1, spans[-1], 2)
        r += 1
        for k in range(n - 1):
            Mx[r, 4 * k : 4 * k + 4] = funcs(k, spans[k], 1)
            Mx[r, 4 * k + 4 : 4 * k + 8] = -funcs(k + 1, 0.0, 1)
            r += 1
            Mx[r, 4 * k : 4 * k + 4] = EIs[k] * funcs(k, spans[k], 2)
            Mx[r, 4 * k + 4 : 4 * k + 8] = -EIs[k + 1] * funcs(k + 1, 0.0, 2)
            r += 1
        return Mx / np.abs(Mx).max(axis=1, keepdims=True)

    def det(f):
        return np.linalg.det(matrix(2 * np.pi * f))

    grid = np.linspace(0.05, f_max, 6000)
    vals = np.array([det(f) for f in grid])
    roots = [brentq(det, grid[i], grid[i + 1], xtol=1e-13) for i in range(len(grid) - 1) if vals[i] * vals[i + 1] < 0]
    assert len(roots) >= n_modes, roots
    return np.array(roots[:n_modes])


def test_simply_supported_span_closed_form_and_convergence():
    L = 30.0
    exact = np.array([(j * np.pi / L) ** 2 * np.sqrt(E * I / (RHO * A)) / (2 * np.pi) for j in (1, 2, 3, 4)])
    errors = {}
    for eps in (2, 4, 8, 16):
        m = build_model(structure_from_dict(girder_dict([L], eps=eps), "ss.yaml"))
        f = m.modes(n_modes=4).frequencies_hz
        errors[eps] = np.abs(f / exact - 1)
    # mesh convergence: monotone and fast (cubic Hermite elements converge ~h^4 in frequency)
    for a, b in ((2, 4), (4, 8), (8, 16)):
        assert np.all(errors[b][:3] < errors[a][:3])
    assert errors[4][0] / errors[8][0] > 8
    assert np.all(errors[8] < 0.005), errors[8]
    assert np.all(errors[16] < 5e-4), errors[16]


@pytest.mark.parametrize(
    "spans,per_span_sections",
    [([14.0, 30.0, 14.0], False), ([20.0, 20.0, 20.0], False), ([18.0, 26.0], True)],
)
def test_continuous_girder_matches_exact_solution(spans, per_span_sections):
    if per_span_sections:
        sections = [{"E": E, "I": I, "A": A, "rho": RHO}, {"E": 0.8 * E, "I": 1.5 * I, "A": 1.2 * A, "rho": RHO}]
        EIs = [E * I, 0.8 * E * 1.5 * I]
        mAs = [RHO * A, RHO * 1.2 * A]
    else:
        sections = None
        EIs = [E * I] * len(spans)
        mAs = [RHO * A] * len(spans)
    n_modes = 5
    ref = None
    prev_err = None
    for eps in (5, 10, 20):
        spec = structure_from_dict(girder_dict(spans, sections=sections, eps=eps), "cont.yaml")
        f = build_model(spec).modes(n_modes=n_modes).frequencies_hz
        if ref is None:
            ref = exact_pinned_beam_frequencies(spans, EIs, mAs, n_modes, 1.3 * f[-1])
        err = np.abs(f / ref - 1)
        if eps == 10:
            assert np.all(err < 0.005), (eps, err)  # acceptance: within 0.5 % at the nominal mesh
        if prev_err is not None:
            assert err.max() < prev_err.max()
        prev_err = err
    assert prev_err.max() < 5e-4


def test_rigid_beam_on_springs_bounce_and_pitch():
    """A very stiff span on two soft end springs: bounce and pitch of a rigid bar (checks the
    bearing terms independently of the bending terms)."""
    L, k = 20.0, 2.0e7
    d = girder_dict([L], sections={"E": E * 1e6, "I": I, "A": A, "rho": RHO}, k=k, eps=4)
    m = build_model(structure_from_dict(d, "rigid.yaml"))
    f = m.modes(n_modes=2).frequencies_hz
    mass = RHO * A * L
    bounce = np.sqrt(2 * k / mass) / (2 * np.pi)
    pitch = np.sqrt(k * L**2 / 2 / (mass * L**2 / 12)) / (2 * np.pi)
    np.testing.assert_allclose(f, [bounce, pitch], rtol=1e-4)


def test_sensors_between_nodes_read_by_shape_functions():
    spans = [14.0, 30.0, 14.0]
    xs = [3.3, 21.7, 29.0, 51.1]
    sensors = [{"id": f"s{i}", "at": {"x": x}, "direction": "vertical"} for i, x in enumerate(xs)]
    spec = structure_from_dict(girder_dict(spans, sensors=sensors, eps=10), "obs.yaml")
    inserted = build_model(spec)  # a node at every sensor
    shapes = build_model(spec, sensor_nodes=False)  # sensors read through Hermite shape functions
    assert set(inserted.sensor_dofs) == set(f"s{i}" for i in range(4))
    assert "s0" not in shapes.sensor_dofs and "s2" in shapes.sensor_dofs  # 29.0 is a mesh node
    # a cubic field is interpolated exactly by Hermite functions
    x = shapes.node_x
    w = 1e-3 * (x**3 - 40 * x**2 + 7 * x + 2)
    r = 1e-3 * (3 * x**2 - 80 * x + 7)
    u = np.empty(2 * len(x))
    u[0::2], u[1::2] = w, r
    xq = np.array(xs)
    np.testing.assert_allclose(shapes.sensor_matrix([f"s{i}" for i in range(4)]) @ u, 1e-3 * (xq**3 - 40 * xq**2 + 7 * xq + 2))
    # the mode shapes read at the sensors agree between the two meshes
    fi, fs = inserted.modes(n_modes=4), shapes.modes(n_modes=4)
    np.testing.assert_allclose(fi.frequencies_hz, fs.frequencies_hz, rtol=2e-3)
    ids = [f"s{i}" for i in range(4)]
    a = inserted.sensor_matrix(ids) @ fi.shapes
    b = shapes.sensor_matrix(ids) @ fs.shapes
    for j in range(4):
        mac = (a[:, j] @ b[:, j]) ** 2 / ((a[:, j] @ a[:, j]) * (b[:, j] @ b[:, j]))
        assert mac > 0.9999
    # observation anywhere along the deck, also for a fine truth mesh
    fine = build_model(spec, elements_per_span=40)
    rows = fine.deck_observation(np.linspace(0, 58, 7))
    assert rows.shape == (7, fine.n_dof)
    np.testing.assert_allclose(rows.sum(axis=1)[[0, -1]], 1.0)
    with pytest.raises(ValueError):
        deck_observation(fine.node_x, [60.0])


def test_elements_per_span_override_and_bearing_nodes():
    d = girder_dict([14.0, 30.0, 14.0], eps=10)
    d["girder"]["bearings"].append({"x": 30.0, "k_vertical": 1.0e8, "k_rotation": 0.0})  # mid-span prop
    spec = structure_from_dict(d, "prop.yaml")
    coarse, fine = build_model(spec), build_model(spec, elements_per_span=40)
    assert np.any(np.isclose(coarse.node_x, 30.0)) and np.any(np.isclose(fine.node_x, 30.0))
    assert fine.n_dof > 3 * coarse.n_dof
    fc, ff = coarse.modes(n_modes=3).frequencies_hz, fine.modes(n_modes=3).frequencies_hz
    assert np.all(np.abs(fc / ff - 1) < 0.005)


def test_sensor_near_a_mesh_node_moves_it_instead_of_a_sliver_element():
    spans = [14.0, 30.0, 14.0]
    xs = [7.05, 14.02, 29.9, 30.6]  # near interior nodes, one next to a bearing
    sensors = [{"id": f"s{i}", "at": {"x": x}, "direction": "vertical"} for i, x in enumerate(xs)]
    spec = structure_from_dict(girder_dict(spans, sensors=sensors, eps=10), "near.yaml")
    model = build_model(spec)
    for i, x in enumerate(xs):
        assert model.node_x[model.sensor_dofs[f"s{i}"] // 2] == pytest.approx(x)
    h = np.diff(model.node_x)
    # only the sensor 2 cm from the bearing at 14 m needs a short element; all others stay near h
    assert np.sum(h < 0.5 * 1.4) == 1 and h.min() == pytest.approx(0.02)
    for b in (0.0, 14.0, 44.0, 58.0):
        assert np.any(np.isclose(model.node_x, b, atol=1e-12))
    ref = build_model(structure_from_dict(girder_dict(spans, eps=10), "ref.yaml"))
    np.testing.assert_allclose(model.modes(n_modes=4).frequencies_hz, ref.modes(n_modes=4).frequencies_hz, rtol=2e-4)


def test_rotational_springs_clamp_the_ends():
    """Very stiff vertical and rotational bearings at both ends: a clamped-clamped beam,
    (beta L) = 4.7300, 7.8532, 10.9956."""
    L = 30.0
    k_rot = 1.0e6 * E * I / L
    bearings = [{"x": x, "k_vertical": STIFF, "k_rotation": k_rot} for x in (0.0, L)]
    m = build_model(structure_from_dict(girder_dict([L], bearings=bearings, eps=16), "cc.yaml"))
    bl = np.array([4.730040745, 7.853204624, 10.99560784])
    exact = (bl / L) ** 2 * np.sqrt(E * I / (RHO * A)) / (2 * np.pi)
    np.testing.assert_allclose(m.modes(n_modes=3).frequencies_hz, exact, rtol=5e-4)
