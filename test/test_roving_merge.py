"""Merging setups through the references (shm_ros/core/roving/merge_post.py, merge_pre.py) and the
clock offset of a roving sensor (clock.py)."""

from __future__ import annotations

import numpy as np
import pytest
import synthetic_oma as so

from shm_ros.core.delay import shift
from shm_ros.core.identify import IdentifyConfig, identify_array
from shm_ros.core.modal import mac
from shm_ros.core.preprocess import PreprocessConfig, preprocess
from shm_ros.core.roving.clock import estimate_clock_offset
from shm_ros.core.roving.merge_post import drop_unconfirmed, merge_post, pair_modes
from shm_ros.core.roving.merge_pre import merge_pre
from shm_ros.core.roving.offline import merge_arrays
from shm_ros.core.types import ModalEstimate, Mode

REFS = ["r1", "r2"]
# three modes over two references and four roving points (p1, p2 in setup 1; p3, p4 in setup 2)
TRUTH = np.array([[0.4, 0.9, 0.2, 0.5, 0.7, 1.0],
                  [1.0, -0.3, 0.8, -0.6, 0.1, -0.4],
                  [0.5, 0.5, -0.9, 0.3, -0.2, 0.6]])
KEYS = ["r1", "r2", "p1", "p2", "p3", "p4"]
FREQ = [1.0, 2.0, 2.05]  # modes 2 and 3 closer than any frequency rule would separate safely


def _estimate(cols: list[int], scale: float, order: list[int], df: float = 0.0) -> ModalEstimate:
    modes = [Mode(FREQ[m] * (1 + df * (-1) ** m), 0.02, scale * TRUTH[m, [0, 1, *cols]]) for m in order]
    return ModalEstimate("s", 0, 0, ["r1", "r2"] + [KEYS[c] for c in cols], modes)


def test_references_ten_times_larger_give_roving_divided_by_ten():
    one = _estimate([2, 3], 1.0, [0, 1, 2])
    two = _estimate([4, 5], 10.0, [0, 1, 2])
    merged = merge_post([one, two], REFS)
    assert [g.setups_found for g in merged] == [2, 2, 2]
    for g, truth in zip(merged, TRUTH, strict=True):
        want = truth / truth[np.argmax(np.abs(truth))]
        got = g.vector(KEYS)
        assert np.max(np.abs(got - want) / np.abs(want)) < 1e-12
        # the second setup's roving components relative to the first's: exactly the truth's ratio,
        # i.e. the raw x10 divided by 10 (the opposite of multiplying by <ref_2, ref_1> / <ref_1, ref_1>)
        raw = two.modes[list(FREQ).index(FREQ[merged.index(g)])].mode_shape[2:]
        np.testing.assert_allclose(got[4:] / got[2], raw / 10.0 / truth[2], rtol=1e-12)
        # exact references: the scale's standard error is zero
        assert max(g.shape_std.values()) < 1e-12


def test_modes_in_another_order_are_paired_by_the_references():
    one = _estimate([2, 3], 1.0, [0, 1, 2])
    # setup 2 lists the modes as 3, 1, 2 and its close pair's frequencies are nudged towards each
    # other's: frequency alone would pair them wrongly
    two = _estimate([4, 5], -3.0, [2, 0, 1], df=0.012)
    groups = pair_modes([one, two], REFS)
    assert groups == [{0: 0, 1: 1}, {0: 1, 1: 2}, {0: 2, 1: 0}]
    merged = merge_post([one, two], REFS)
    for g, truth in zip(merged, TRUTH, strict=True):
        assert mac(g.vector(KEYS), truth) > 1 - 1e-12


def test_mode_missing_in_one_setup_and_scale_uncertainty():
    rng = np.random.default_rng(3)
    one = _estimate([2, 3], 1.0, [0, 1, 2])
    two = _estimate([4, 5], 2.0, [0, 1])  # mode 3 not found in setup 2
    for m in two.modes:
        m.mode_shape = m.mode_shape + 0.01 * rng.standard_normal(m.mode_shape.size)
    merged = merge_post([one, two], REFS)
    third = merged[2]
    assert third.setups_found == 1 and third.missing_setups == [2]
    assert "not found in setup(s) [2]" in third.notes[0] and "p3" not in third.shape
    # noisy references in setup 2: its roving components carry the scale's uncertainty, setup 1's less
    first = merged[0]
    assert first.shape_std["p3"] > 1e-4 and first.shape_std["p3"] > first.shape_std["p1"]


def _setups(seed: int, duration: float = 1800.0):
    """Four setups cut from one ambient record of a 12-floor building (10 sensors): references at two
    floors, two roving floors per setup, each setup at its own excitation level."""
    data, fs, truth, names = so.ambient_record(seed, duration=duration, fs=40.0, noise=0.02, n_sensors=10)
    refs = [names[-1], names[4]]
    roving = [n for n in names if n not in refs]
    n = data.shape[0] // 4
    sets, chans = [], []
    for k in range(4):
        mov = roving[2 * k: 2 * k + 2]
        cols = [names.index(c) for c in refs + mov]
        sets.append(data[k * n:(k + 1) * n, cols] * (1.0, 3.0, 0.5, 8.0)[k])
        chans.append(refs + mov)
    return sets, chans, refs, fs, truth, names


def test_one_setup_far_off_does_not_move_the_common_reference_shape():
    # five setups agree on mode 1's reference ratio; a sixth (a pick blended with a neighbour) is far off
    setups = [_estimate([2, 3], 1.0 + 0.1 * k, [0, 1, 2]) for k in range(5)]
    bad = _estimate([4, 5], 1.0, [0, 1, 2])
    bad.modes[0].mode_shape = bad.modes[0].mode_shape * np.array([3.0, 1.0, 1.0, 1.0])
    g = merge_post(setups + [bad], REFS)[0]
    assert g.shape["r1"] / g.shape["r2"] == pytest.approx(TRUTH[0, 0] / TRUTH[0, 1], rel=1e-9)


def test_modes_the_setups_do_not_confirm_are_left_out():
    setups = [_estimate([2, 3], 1.0, [0, 1, 2]) for _ in range(8)]
    # one setup offers a fourth mode of its own; another a second estimate of mode 1 (0.5 % above,
    # the same reference shape), and a third the same second estimate
    extra = Mode(3.0, 0.02, TRUTH[2, [0, 1, 2, 3]] * np.array([1.0, -1.0, 1.0, 1.0]))
    setups[0].modes.append(extra)
    for k in (1, 2):
        setups[k].modes.append(Mode(1.005, 0.02, TRUTH[0, [0, 1, 2, 3]]))
        setups[k].modes.sort(key=lambda m: m.frequency_hz)
    merged = merge_post(setups, REFS)
    assert [g.setups_found for g in merged] == [8, 2, 8, 8, 1]
    kept, notes = drop_unconfirmed(merged, len(setups), REFS)
    assert [g.frequency_hz for g in kept] == pytest.approx([1.0, 2.0, 2.05])
    assert notes == ["a mode at 3 Hz found in one setup of 8 only: left out"]
    assert any("second estimate at 1.005 Hz from 2 setup(s)" in n for n in kept[0].notes)
    # the members of every kept mode are the setups' modes it was merged from
    assert kept[0].members == {k: 0 for k in range(8)}
    # three setups are too few to tell: nothing is left out
    assert len(drop_unconfirmed(merge_post(setups[:3], REFS), 3, REFS)[0]) == 5


@pytest.fixture(scope="module")
def building_setups():
    with so.single_blas_thread():
        return _setups(11)


CFG = IdentifyConfig(method="ssi-cov", block_rows=30, max_order=40, uncertainty=False, band="off")


def _check_against_truth(modes, names, truth, n_modes: int = 3):
    for k in range(n_modes):
        f = np.array([g.frequency_hz for g in modes])
        j = int(np.argmin(np.abs(f - truth.frequency_hz[k])))
        assert abs(f[j] / truth.frequency_hz[k] - 1) < 0.01, (k, f, truth.frequency_hz[:n_modes])
        got = modes[j].vector(names)
        assert np.isfinite(got).all()
        assert so.mac_real(truth.shapes[k], got) > 0.995, (k, so.mac_real(truth.shapes[k], got))


def test_post_merge_of_real_setups_matches_the_truth(building_setups):
    sets, chans, refs, fs, truth, names = building_setups
    ests = []
    with so.single_blas_thread():
        for y, ch in zip(sets, chans, strict=True):
            prep = preprocess(y, fs, ch, PreprocessConfig())
            ests.append(identify_array(prep, IdentifyConfig(**{**CFG.__dict__, "reference_channels": refs})
                                       ).estimate)
    merged = merge_post(ests, refs)
    _check_against_truth(merged, names, truth)


def test_merge_from_arrays_takes_the_roving_components_from_the_transmissibility(building_setups):
    """The offline merge from arrays runs the tf pipeline's transmissibility step: roving channels
    given before the references, components on the merged reference shape with the fit's std."""
    sets, chans, refs, fs, truth, names = building_setups
    sets = [y[:, ::-1] for y in sets]  # the roving channels first, as a recording may list them
    chans = [ch[::-1] for ch in chans]
    with so.single_blas_thread():
        modes, notes = merge_arrays(sets, chans, refs, fs, CFG)
        plain, _ = merge_arrays(sets, chans, refs, fs, CFG, transmissibility=False)
    assert any("transmissibility" in n for n in notes)
    _check_against_truth(modes, names, truth)
    roving = [n for n in names if n not in refs]
    for g, h in zip(modes[:3], plain[:3], strict=True):
        std = np.array([g.shape_std[n] for n in roving])
        assert np.isfinite(std).all() and (std > 0).all() and (std < 0.05).all(), std
        assert not np.allclose(g.vector(roving), h.vector(roving), rtol=0, atol=1e-9)


def test_pre_merge_of_real_setups_matches_the_truth(building_setups):
    sets, chans, refs, fs, truth, names = building_setups
    with so.single_blas_thread():
        preps = [preprocess(y, fs, ch, PreprocessConfig()) for y, ch in zip(sets, chans, strict=True)]
        modes, notes = merge_pre([p.data for p in preps], [p.channel_names for p in preps], refs, fs, CFG)
    _check_against_truth(modes, names, truth)
    assert "4 setups" in notes[0]


@pytest.mark.parametrize("offset_ms", [5.0, 12.5, 20.0])
def test_clock_offset_from_the_references(offset_ms):
    data, fs, truth, names = so.ambient_record(5, duration=600.0, fs=50.0, noise=0.02, n_sensors=6)
    roving = shift(data[:, 1], fs, -offset_ms / 1000.0)  # stamped late by the offset
    est = estimate_clock_offset(roving, data[:, [0, 5]], fs)
    assert abs(est.offset_s * 1000.0 - offset_ms) < 1.0, est
    back = estimate_clock_offset(shift(roving, fs, est.offset_s), data[:, [0, 5]], fs)
    assert abs(back.offset_s) < 1e-3
