"""Column decisions of the automatic picking (``stabilization.pick_modes_reported``) against a
direct loop over each column's model orders: the two-A / MPC pass fraction counts an order once
when any of its poles passes (a split pair must not outvote the column), and a picked mode keeps
one pole per order, the one nearest the column's median frequency (the lowest index among equals).

The diagram is synthetic (three columns over 30 orders, split pairs with identical frequencies at
some orders, random per-pole check results), so every branch of those rules is exercised; the
reference is computed independently of the picking code's vectorised form."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.ssi import PoleSet
from shm_ros.core.stabilization import PickingConfig, PoleFlags, _cluster, pick_modes_reported

N_ORDERS = 30


def _diagram(seed: int) -> tuple[PoleSet, PoleFlags]:
    rng = np.random.default_rng(seed)
    shapes = {2.0: np.array([1.0, 0.6, 0.3, 0.1]), 5.0: np.array([-0.5, 0.2, 1.0, 0.7]),
              9.0: np.array([0.3, -1.0, 0.4, -0.2])}
    pass_rate = {2.0: 0.9, 5.0: 0.5, 9.0: 0.1}
    order, freq, shape, two_a = [], [], [], []
    for o in range(1, N_ORDERS + 1):
        for f0, phi in shapes.items():
            if o < 3:
                continue
            n_here = 2 if rng.random() < 0.3 else 1  # a split pair at some orders
            f = f0 * (1 + 1e-3 * rng.standard_normal())
            for _ in range(n_here):
                order.append(o)
                freq.append(f)  # the pair has identical frequencies: a tie for the nearest pole
                shape.append((phi + 1e-3 * rng.standard_normal(4)).astype(complex))
                two_a.append(rng.random() < pass_rate[f0])
    n = len(order)
    poles = PoleSet(np.array(order), np.array(freq), np.full(n, 0.02), np.array(shape),
                    np.array(freq), np.full(n, 0.02), np.ones(n), np.arange(1, N_ORDERS + 1))
    ones = np.ones(n, bool)
    flags = PoleFlags(np.ones(n), ones, ones.copy(), np.array(two_a), ones.copy(), ones.copy())
    return poles, flags


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_column_pass_fractions_and_one_pole_per_order_match_a_loop_over_orders(seed):
    poles, flags = _diagram(seed)
    cfg = PickingConfig()
    picked, report = pick_modes_reported(poles, flags, cfg)
    cand = np.flatnonzero(flags.stable & flags.physical_ok)
    labels = _cluster(poles.frequency_hz[cand], poles.shape[cand], cfg.distance_cutoff)
    columns = {round(c["frequency_hz"], 9): c for c in report.columns if c["check"] == "two-A"}
    assert len(columns) == 3  # every column reaches enough orders to be judged
    kept = same_order = 0
    for lab in np.unique(labels):
        members = cand[labels == lab]
        fmed = float(np.median(poles.frequency_hz[members]))
        orders = np.unique(poles.order[members])
        passed = [bool(np.any(flags.two_a_ok[members[poles.order[members] == o]])) for o in orders]
        assert columns[round(fmed, 9)]["pass_fraction"] == round(float(np.mean(passed)), 3)
        mode = [p for p in picked if abs(p.frequency_hz - fmed) < 0.05 * fmed]
        if np.mean(passed) < cfg.column_pass_fraction:
            assert not mode  # removed by the two-A filter
            continue
        kept += 1
        same_order += members.size - orders.size
        expected = []
        for o in orders:
            at = members[poles.order[members] == o]
            expected.append(at[np.argmin(np.abs(poles.frequency_hz[at] - fmed))])
        assert len(mode) == 1 and np.array_equal(mode[0].pole_index, expected)
    assert kept == len(picked) >= 1
    assert report.removed["same order"] == same_order > 0


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_columns_checked_until_settled_keep_every_verdict(seed):
    """``two_a_by_column`` asks for the two-A verdict of each column's poles only until the
    column's verdict is settled, and picking then keeps and removes the same columns as with
    every pole's verdict; the report's pass fraction is that of the orders checked."""
    from shm_ros.core.stabilization import passes_needed, stable_columns, two_a_by_column

    poles, flags = _diagram(seed)
    truth = flags.two_a_ok.copy()
    cfg = PickingConfig()
    asked: list[np.ndarray] = []

    def validate(idx):
        assert np.unique(poles.order[idx]).size == 1  # one model order at a time
        asked.append(idx)
        return truth[idx]

    ok, checked = two_a_by_column(poles, flags, cfg, validate)
    assert np.array_equal(ok, truth & checked) and 0 < checked.sum() < truth.size
    columns, need = stable_columns(poles, flags, cfg)
    for members in columns:
        orders = np.unique(poles.order[members])
        seen = np.unique(poles.order[members[checked[members]]])
        passed = sum(bool(truth[members[poles.order[members] == o]].any()) for o in seen)
        required = passes_needed(orders.size, need, cfg.column_pass_fraction)
        # settled: reached, or out of reach ...
        assert passed >= required or passed + orders.size - seen.size < required
        # ... and not before its last order checked
        sequence = [int(poles.order[idx[0]]) for idx in asked if np.isin(idx, members).any()]
        assert sorted(sequence) == list(seen)
        n_pass = 0
        for k, o in enumerate(sequence[:-1]):
            n_pass += bool(truth[members[poles.order[members] == o]].any())
            assert n_pass < required and n_pass + orders.size - (k + 1) >= required
    full = pick_modes_reported(poles, flags, cfg)
    lazy_flags = PoleFlags(flags.mpc, flags.stable_freq, flags.stable, ok, flags.mpc_ok,
                           flags.physical_ok, two_a_checked=checked)
    lazy = pick_modes_reported(poles, lazy_flags, cfg)
    assert [p.frequency_hz for p in lazy[0]] == [p.frequency_hz for p in full[0]]
    assert lazy[1].removed == full[1].removed
    for c in lazy[1].columns:
        assert c["orders_checked"] <= c["orders"]
    assert sum(c["orders_checked"] < c["orders"] for c in lazy[1].columns if c["check"] == "two-A") >= 1


@pytest.mark.parametrize("n_orders", [10, 30, 48, 50, 99, 100])
def test_passes_needed_is_the_picking_rule(n_orders):
    from shm_ros.core.stabilization import passes_needed

    need, fraction = 10, 0.2
    keep = [k for k in range(n_orders + 1) if not (k / n_orders < fraction or k < need)]
    assert passes_needed(n_orders, need, fraction) == keep[0]
