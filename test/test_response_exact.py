"""The exact time-domain response (shm_ros.core.response) against an independent computation.

The reference is built here by hand from the structure file's numbers, by another route: the
building in ABSOLUTE coordinates with the ground as an ordinary node, every driven node's
displacement and velocity as states (integrated from its measured acceleration), Rayleigh damping
from a hand-solved eigenproblem acting on the motion relative to the supports' quasi-static motion,
dampers on the absolute motion of their ends; discretised by ``scipy.signal.cont2discrete``
(method "foh") and run by ``scipy.signal.dlsim``. The solver under test works in relative
coordinates (dynamic part of the free floors only) and discretises by its own matrix exponential.
Both are exact for inputs linear between samples, so they must agree to round-off; 1e-6 relative
leaves room for the conditioning of the absolute-coordinate reference.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from shm_ros.core.models import build_model
from shm_ros.core.response import (
    Output,
    Quantity,
    build_state_space,
    build_state_spaces,
    discretize_foh,
    drift_outputs,
    response,
    sensor_outputs,
    simulate,
)
from shm_ros.core.structure import structure_from_dict

MASSES = [3.0e5, 2.8e5, 2.8e5, 2.6e5, 2.6e5, 2.2e5]
STIFF = [6.0e8, 5.5e8, 5.0e8, 4.5e8, 4.0e8, 3.0e8]
HEIGHTS = [4.0, 3.2, 3.2, 3.2, 3.2, 3.0]
RATIOS = [0.02, 0.035]
THETA = np.array([0.92, 1.07])  # k_low (stories 1-3), m_top (floors 5-6)
DT, N = 0.01, 1200
N_FLOORS = len(MASSES)


def _spec_dict(inputs: list[dict], dampers: list[dict]) -> dict:
    sensors = [{"id": f"f{k}", "at": {"floor": k}, "direction": "x"} for k in range(N_FLOORS + 1)]
    sensors += [{"id": f"load{k}", "at": {"floor": k}, "direction": "x"} for k in range(1, N_FLOORS + 1)]
    return {
        "name": "six-story",
        "kind": "shear_building",
        "shear_building": {
            "floors": [{"mass": m, "stiffness": k, "height": h}
                       for m, k, h in zip(MASSES, STIFF, HEIGHTS, strict=True)],
            "dampers": dampers,
        },
        "damping": {"kind": "rayleigh", "ratios": RATIOS},
        "sensors": sensors,
        "inputs": inputs,
        "parameters": [
            {"name": "k_low", "applies_to": "shear_building.floors[0,1,2].stiffness",
             "prior": {"dist": "lognormal", "mu_ln": 0.0, "sigma_ln": 0.1}},
            {"name": "m_top", "applies_to": "shear_building.floors[4,5].mass",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.05}},
        ],
    }


def _records(n_inputs: int, seed: int) -> np.ndarray:
    """Band-limited, tapered records (they start and end near rest)."""
    rng = np.random.default_rng(seed)
    sos = signal.butter(4, [0.3, 15.0], btype="band", fs=1 / DT, output="sos")
    t = np.arange(N) * DT
    taper = np.sin(np.pi * t / t[-1]) ** 2
    return np.array([signal.sosfilt(sos, rng.standard_normal(N)) * taper for _ in range(n_inputs)])


# ---------------------------------------------------------------------------------------------
# the independent reference
# ---------------------------------------------------------------------------------------------


def _hand_model(theta: np.ndarray):
    """Absolute-coordinate stiffness (nodes 0..n, 0 = ground), masses and Rayleigh C of the floors."""
    k = np.array(STIFF, dtype=float)
    k[:3] *= theta[0]
    m = np.array(MASSES, dtype=float)
    m[4:] *= theta[1]
    n = N_FLOORS
    Kabs = np.zeros((n + 1, n + 1))
    for i in range(1, n + 1):  # story i joins nodes i - 1 and i
        Kabs[np.ix_([i - 1, i], [i - 1, i])] += k[i - 1] * np.array([[1, -1], [-1, 1]])
    Mabs = np.diag(np.concatenate([[0.0], m]))
    Kfix, Mfix = Kabs[1:, 1:], Mabs[1:, 1:]
    w = np.sort(np.sqrt(np.linalg.eigvals(np.linalg.solve(Mfix, Kfix)).real))[:2]
    # zeta_i = a0 / (2 w_i) + a1 w_i / 2
    a0, a1 = np.linalg.solve([[1 / (2 * w[0]), w[0] / 2], [1 / (2 * w[1]), w[1] / 2]], RATIOS)
    Cinh = np.zeros((n + 1, n + 1))
    Cinh[1:, 1:] = a0 * Mfix + a1 * Kfix
    return Kabs, Mabs, Cinh


def _reference(theta, inputs, dampers, free, prescribed, outputs, records):
    """Outputs (n_out, N). ``free``/``prescribed``: node lists (the ground is node 0, prescribed
    at rest when no input drives it); ``outputs``: (kind, node_row) with kind "a" or "d"."""
    Kabs, Mabs, Cinh = _hand_model(theta)
    F, P = list(free), list(prescribed)
    nf, npr = len(F), len(P)
    Mi = np.linalg.inv(Mabs[np.ix_(F, F)])
    R = -np.linalg.solve(Kabs[np.ix_(F, F)], Kabs[np.ix_(F, P)])  # quasi-static motion of the free nodes
    kv = [d for d in dampers if "k_maxwell" not in d]
    mx = [d for d in dampers if "k_maxwell" in d]
    n_nodes = N_FLOORS + 1

    def inc(d):
        b = np.zeros(n_nodes)
        b[d["between"][0]] += 1.0
        b[d["between"][1]] -= 1.0
        return b

    nm = len(mx)
    # states: x_F, v_F, f_maxwell, x_P, v_P ; inputs: the records
    ix, iv, im, ixp, ivp = 0, nf, 2 * nf, 2 * nf + nm, 2 * nf + nm + npr
    nz = 2 * nf + nm + 2 * npr
    ni = len(inputs)
    A = np.zeros((nz, nz))
    B = np.zeros((nz, ni))
    A[ix:ix + nf, iv:iv + nf] = np.eye(nf)
    A[ixp:ixp + npr, ivp:ivp + npr] = np.eye(npr)
    # node velocity = Sv z (absolute, every node)
    Sv = np.zeros((n_nodes, nz))
    Sv[F, iv:iv + nf] = np.eye(nf)
    Sv[P, ivp:ivp + npr] = np.eye(npr)
    force = np.zeros((nf, nz))  # forces on the free nodes, state part
    force -= Kabs[np.ix_(F, F)] @ np.eye(nf, nz, ix) + Kabs[np.ix_(F, P)] @ np.eye(npr, nz, ixp)
    rel_v = np.eye(nf, nz, iv) - R @ np.eye(npr, nz, ivp)
    force -= Cinh[np.ix_(F, F)] @ rel_v
    for d in kv:
        b = inc(d)
        force -= d["c"] * np.outer(b[F], b @ Sv)
    for j, d in enumerate(mx):
        b = inc(d)
        force[:, im + j] -= b[F]
        A[im + j] = d["k_maxwell"] * (b @ Sv)
        A[im + j, im + j] -= d["k_maxwell"] / d["c"]
    A[iv:iv + nf] = Mi @ force
    for c, inp in enumerate(inputs):
        node = inp["node"]
        if inp["kind"] == "force":
            B[iv + F.index(node), c] = Mi[F.index(node), F.index(node)] * inp.get("gain", 1.0)
        else:
            B[ivp + P.index(node), c] = inp.get("gain", 1.0)
    # outputs
    Cout = np.zeros((len(outputs), nz))
    Dout = np.zeros((len(outputs), ni))
    for r, (kind, row) in enumerate(outputs):
        if kind == "d":
            Cout[r, ix:ix + nf] = row[F]
            Cout[r, ixp:ixp + npr] = row[P]
        else:  # absolute acceleration
            Cout[r] = row[F] @ A[iv:iv + nf]
            Dout[r] = row[F] @ B[iv:iv + nf] + row[P] @ B[ivp:ivp + npr]
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, Cout, Dout), DT, method="foh")
    # cont2discrete's foh state is x - G2 u: at rest with u[0] it starts at -G2 u[0]
    G2 = (Dd - Dout) if not np.any(Cout) else np.linalg.lstsq(Cout, Dd - Dout, rcond=None)[0]
    x0 = -G2 @ records[:, 0]
    _, y, _ = signal.dlsim((Ad, Bd, Cd, Dd, DT), records.T, x0=x0)
    return np.atleast_2d(y.T)


# ---------------------------------------------------------------------------------------------
# cases
# ---------------------------------------------------------------------------------------------

KV = [{"between": [0, 1], "c": 4.0e6}, {"between": [2, 5], "c": 2.0e6}]
MAXWELL = [{"between": [1, 2], "c": 3.0e6, "k_maxwell": 6.0e7}, {"between": [4, 6], "c": 2.5e6, "k_maxwell": 9.0e7}]
ALL = KV + MAXWELL

# name: (inputs, dampers, free nodes, prescribed nodes); the ground is node 0
CASES: dict[str, tuple[list[dict], list[dict], list[int], list[int]]] = {
    "base_classical": ([{"sensor": "f0"}], [], [1, 2, 3, 4, 5, 6], [0]),
    "base_dampers": ([{"sensor": "f0"}], ALL, [1, 2, 3, 4, 5, 6], [0]),
    "floor_only": ([{"sensor": "f2", "kind": "floor"}], [KV[1], MAXWELL[1], {"between": [2, 3], "c": 1e6}],
                   [3, 4, 5, 6], [2]),
    "force_only": ([{"sensor": "load4", "kind": "force", "at": {"floor": 4}, "gain": 2.0e5}], ALL,
                   [1, 2, 3, 4, 5, 6], [0]),
    "base_and_force": ([{"sensor": "f0"}, {"sensor": "load6", "kind": "force", "at": {"floor": 6}, "gain": 1.0e5}],
                       ALL, [1, 2, 3, 4, 5, 6], [0]),
    "base_and_floor": ([{"sensor": "f0"}, {"sensor": "f3", "kind": "floor", "gain": 1.3}],
                       ALL + [{"between": [1, 5], "c": 1.5e6, "k_maxwell": 5.0e7}], [1, 2, 4, 5, 6], [0, 3]),
    "two_floors_and_force": ([{"sensor": "f1", "kind": "floor"}, {"sensor": "f4", "kind": "floor"},
                              {"sensor": "load5", "kind": "force", "at": {"floor": 5}, "gain": 5.0e4}],
                             [KV[1], MAXWELL[0], MAXWELL[1]], [2, 3, 5, 6], [1, 4]),
}


def _hand_inputs(inputs: list[dict]) -> list[dict]:
    out = []
    for i in inputs:
        kind = i.get("kind", "base" if i["sensor"] == "f0" else "floor")
        node = i["at"]["floor"] if "at" in i else int(i["sensor"].lstrip("fload"))
        out.append({"kind": kind, "node": node, "gain": i.get("gain", 1.0)})
    return out


def _rel_err(y: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.max(np.abs(y - ref), axis=1) / np.max(np.abs(ref), axis=1)


@pytest.mark.parametrize("batched", [False, True], ids=["one", "batch"])
@pytest.mark.parametrize("case", list(CASES))
def test_response_equals_independent_exact_computation(case, batched):
    """``batch``: THETA's state space taken from a batch of three parameter sets
    (:func:`build_state_spaces`, batched assembly), the others' equal to their own build bit for bit."""
    inputs, dampers, free, prescribed = CASES[case]
    spec = structure_from_dict(_spec_dict(inputs, dampers), f"{case}.yaml")
    model = build_model(spec)
    records = _records(len(inputs), seed=len(case))
    known = sorted(free + prescribed)
    sensors = [f"f{k}" for k in known]
    drifts = [d for k, d in enumerate(drift_outputs(model, ratio=True), start=1) if k in known and k - 1 in known]
    outputs = sensor_outputs(model, sensors) + drifts
    if batched:
        thetas = np.array([THETA * [0.8, 1.1], THETA, THETA * [1.3, 0.9]])
        systems = build_state_spaces(model, thetas, outputs)
        for k in (0, 2):
            one = build_state_space(model, thetas[k], outputs)
            assert all(np.array_equal(getattr(systems[k], m), getattr(one, m)) for m in "ABCD")
        y = simulate(discretize_foh(systems[1], DT), records)
    else:
        y = response(model, THETA, records, DT, outputs)

    hand_in = _hand_inputs(inputs)
    driven = [i["node"] for i in hand_in if i["kind"] != "force"]
    if 0 in prescribed and 0 not in driven:  # ground at rest: a support with a zero record
        hand_in = hand_in + [{"kind": "base", "node": 0}]
        records_ref = np.vstack([records, np.zeros(N)])
    else:
        records_ref = records
    rows = []
    for k in known:
        e = np.zeros(N_FLOORS + 1)
        e[k] = 1.0
        rows.append(("a", e))
    for k in range(1, N_FLOORS + 1):
        if k in known and k - 1 in known:
            e = np.zeros(N_FLOORS + 1)
            e[k], e[k - 1] = 1.0 / HEIGHTS[k - 1], -1.0 / HEIGHTS[k - 1]
            rows.append(("d", e))
    ref = _reference(THETA, hand_in, dampers, free, prescribed, rows, records_ref)
    assert y.shape == ref.shape == (len(outputs), N)
    at_rest = [r for r, o in enumerate(outputs) if o.name == "f0" and 0 not in driven]  # ground at rest
    assert np.all(y[at_rest] == 0.0) and np.all(ref[at_rest] == 0.0)
    moving = [r for r in range(len(outputs)) if r not in at_rest]
    err = _rel_err(y[moving], ref[moving])
    assert np.all(err < 1e-6), dict(zip([outputs[r].name for r in moving], err, strict=True))
    # the records drive the structure (a zero response would agree trivially)
    assert np.all(np.max(np.abs(ref[moving]), axis=1) > 1e-6)  # drift ratios ~1e-3, accelerations ~1 m/s^2


def test_floor_input_drives_the_floors_above_it():
    """An input recorded at floor 1 prescribes floor 1: floors 2..6 respond to it as to a support
    motion. Applying the same record as ground acceleration under floor 1 (what an input at floor 1
    used to mean) gives a clearly different response."""
    records = _records(1, seed=11)
    spec = structure_from_dict(_spec_dict([{"sensor": "f1"}], KV), "floor1.yaml")
    assert spec.inputs[0].kind == "floor"
    model = build_model(spec)
    sensors = [f"f{k}" for k in range(1, N_FLOORS + 1)]
    y = response(model, THETA, records, DT, sensor_outputs(model, sensors))
    rows = []
    for k in range(1, N_FLOORS + 1):
        e = np.zeros(N_FLOORS + 1)
        e[k] = 1.0
        rows.append(("a", e))
    ref = _reference(THETA, [{"kind": "floor", "node": 1}], KV, [2, 3, 4, 5, 6], [1], rows, records)
    assert np.all(_rel_err(y, ref) < 1e-6), _rel_err(y, ref)
    np.testing.assert_allclose(y[0], records[0], rtol=1e-12)  # floor 1 moves as recorded

    old = structure_from_dict(_spec_dict([{"sensor": "f0"}], KV), "old.yaml")
    y_old = response(build_model(old), THETA, records, DT, sensor_outputs(build_model(old), sensors))
    nrms = np.linalg.norm(y_old - y, axis=1) / np.linalg.norm(y, axis=1)
    assert np.all(nrms[1:] > 0.1), nrms
    # and the old treatment is not the hand-built floor-driven model either
    assert np.all(_rel_err(y_old, ref)[1:] > 0.1)


def test_floor_input_leaves_out_what_it_does_not_support():
    spec = structure_from_dict(_spec_dict([{"sensor": "f3", "kind": "floor"}], []), "f3.yaml")
    model = build_model(spec)
    with pytest.raises(ValueError, match="ground"):
        response(model, None, _records(1, 0)[:, :50], DT, sensor_outputs(model, ["f2"]))
    out = response(model, None, _records(1, 0)[:, :50], DT, sensor_outputs(model, ["f4"]))
    assert out.shape == (1, 50)


def test_classical_base_response_matches_modal_superposition():
    """Without dampers and with one base input the solver is the classical modal solution: each mode
    an exactly discretised SDOF (scipy.signal.cont2discrete per mode)."""
    spec = structure_from_dict(_spec_dict([{"sensor": "f0"}], []), "b.yaml")
    model = build_model(spec)
    rec = _records(1, 5)
    y = response(model, THETA, rec, DT, [Output("top", Quantity.ACCELERATION, np.eye(N_FLOORS + 1)[N_FLOORS - 1])])
    sol = model.modes(THETA, N_FLOORS)
    zeta = model.modal_damping_ratios(THETA, N_FLOORS)
    gam = sol.shapes.T @ model.mass(THETA) @ np.ones(N_FLOORS)
    acc = np.zeros(N)
    for r in range(N_FLOORS):
        w = 2 * np.pi * sol.frequencies_hz[r]
        A = np.array([[0, 1], [-w * w, -2 * zeta[r] * w]])
        sys = signal.cont2discrete((A, np.array([[0], [-gam[r]]]), A[1:], np.array([[-gam[r]]])), DT, method="foh")
        _, q, _ = signal.dlsim(sys, rec[0])
        acc += sol.shapes[-1, r] * q[:, 0]
    acc += rec[0]  # absolute = relative + ground
    assert np.max(np.abs(y[0] - acc)) < 1e-6 * np.max(np.abs(acc))
