"""Within-event analysis (``shm_ros.core.event_analysis``, ``shm-ros event``) against the simulator's
time-resolved equivalent-linear truth.

The structure: the building of the ``building-earthquake`` scenario with softening story springs
(``amplitude_stiffness``, default ``drift_ref_m`` 0.01 m) under one event of PGA 1.5 m/s^2 (the top
of the scenario's range) in a 240 s record; its fundamental frequency falls 20-35 % in the strong
motion. The truth of each moving window is the linear model with every story's mean-square secant
stiffness over that window (``shm_ros.core.simulate.equivalent_linear``), which is the analysis
model's class only in being linear: the data come from the nonlinear Newmark integration.

The truth is the default (model-form) building: x, y and twist per floor, eccentric masses, sensors
off the stiffness centre with cross-axis sensitivity, so the x sensors also see the first y sway
mode (6-10 % below the first x mode) and the first torsion mode (15-20 % above). The analysis is
given the nominal planar model's frequencies and follows the x modes (``analyse_event``'s
``model_frequencies_hz``); the truth track is the x family's. The seed statistics quoted below were
derived with the planar truth; with this one, seeds 1-6: error at the minimum -2.4 to +2.3 % (5 of 6
drop >= 15 %), time within one step, pre/post modes 1-2 within 1.7 %.

CI runs 3 seeds, ``SHM_FULL=1`` 12.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from scipy import stats

from shm_ros.core.event_analysis import EventConfig, analyse_event, running_median, significant_interval
from shm_ros.core.models import build_model
from shm_ros.core.simulate.campaign import simulate_campaign
from shm_ros.core.simulate.equivalent_linear import secant_factors, simulate_event
from shm_ros.core.simulate.newmark import equivalent_stiffness_factor
from shm_ros.core.simulate.scenario import EffectRequest, named_scenario

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
SEEDS = list(range(1, 13)) if FULL else [1, 2, 3]
PGA = 1.5
RECORD_S = 240.0
NOMINAL_F1_HZ = 1.146  # the nominal eight-story building's first natural frequency


def _campaign(seed: int, window_s: float = RECORD_S):
    sc = named_scenario("building-earthquake", n_windows=1, window_s=window_s, seed=seed,
                        pga_range_m_s2=(PGA, PGA))
    sc.effects = [EffectRequest("amplitude_stiffness", {})]
    return simulate_campaign(sc)


@pytest.fixture(scope="module")
def events():
    out = []
    for seed in SEEDS:
        ev = simulate_event(_campaign(seed), 0)
        res = analyse_event(ev.window, EventConfig(), model_frequencies_hz=_model_frequencies(ev))
        assert res.lowest_frequency_hz == pytest.approx(NOMINAL_F1_HZ, rel=1e-3)
        out.append((seed, ev, res))
    return out


def _model_frequencies(ev) -> np.ndarray:
    """The analysis model's (the nominal planar building's) natural frequencies."""
    return build_model(ev.truth.nominal).modes(n_modes=4).frequencies_hz


def _truth_mode(ev, res, r: int) -> int:
    """Index of the truth mode that followed mode ``r`` (0-based) is: the nearest small-amplitude
    frequency to its reference, which must lie within 5 %."""
    f_ref = res.tracks[r].reference_frequency_hz
    j = int(np.argmin(np.abs(ev.small_amplitude_frequencies_hz - f_ref)))
    assert abs(ev.small_amplitude_frequencies_hz[j] / f_ref - 1) < 0.05, (f_ref, ev.small_amplitude_frequencies_hz)
    return j


def allowed_failures(n: int, p: float = 0.95, level: float = 0.99) -> int:
    """Fewest failures f such that a method passing each seed with probability ``p`` has at least
    ``n - f`` passes with probability >= ``level`` (binomial tail)."""
    return next(f for f in range(n + 1) if stats.binom.sf(n - f - 1, n, p) >= level)


def test_moving_window_minimum_follows_the_equivalent_linear_truth(events):
    """The moving-window minimum of mode 1 is within 3 % of the truth's equivalent-linear frequency
    of the same window and within 5 s of the truth's own minimum, on every seed whose truth drops by
    at least 15 % (the claim's domain; at PGA 1.5 m/s^2 11 of 12 seeds did, 13.9 % the least).

    Criterion: on 17 preliminary seeds (PGA 1.2 and 1.5) the error at the minimum had mean 0.0 %
    and standard deviation 1.45 % (largest 2.4 %), the time offset at most one step (0.9 s); a
    normal error with that spread passes 3 % with probability p >= 0.95 per seed. (SHM_FULL, 12
    seeds: 11 qualify, all pass, errors within 2.3 %, times within 3.5 s.) Allowed failures
    among n qualifying seeds: the fewest f with P(Binomial(n, 0.95) >= n - f) >= 0.99, i.e. 1 of 3
    (probability 0.993), 3 of 10-12."""
    passed, lines, n = 0, [], 0
    for seed, ev, res in events:
        m = res.tracks[0]
        j = _truth_mode(ev, res, 0)
        truth = ev.track(res.window_start_s, res.window_s)
        kt = int(np.argmin(truth.frequencies_hz[:, j]))
        drop = 1 - truth.frequencies_hz[kt, j] / ev.small_amplitude_frequencies_hz[j]
        # the track recovers: the last windows are back within 3 % of the reference
        assert np.nanmedian(m.frequency_hz[-20:]) / m.reference_frequency_hz > 0.97, seed
        if drop < 0.15:
            lines.append(f"seed {seed}: drop {100 * drop:.1f} %, outside the claim")
            continue
        n += 1
        k = m.min_index
        assert k is not None
        err = m.smoothed_frequency_hz[k] / truth.frequencies_hz[k, j] - 1
        dt = res.time_s[k] - res.time_s[kt]
        passed += abs(err) <= 0.03 and abs(dt) <= 5.0
        lines.append(f"seed {seed}: drop {100 * drop:.1f} %, error at the minimum {100 * err:+.2f} %, "
                     f"time {dt:+.1f} s")
    print("\n".join(lines))
    assert n >= (2 * len(SEEDS)) // 3, "the scenario no longer softens the structure enough:\n" + "\n".join(lines)
    assert passed >= n - allowed_failures(n), "\n".join(lines)


def test_pre_and_post_event_estimates_return_to_the_small_amplitude_truth(events):
    """Pre-event and post-event (after the response is back near the pre-event level) frequencies of
    modes 1 and 2 are within 2 % of the small-amplitude truth (12 seeds: largest 1.3 %, typical
    0.5 %, of which 0.3 % for mode 2 is the Newmark integrator's period elongation), and the
    strong-motion estimate of mode 1 is within 7 % of the equivalent-linear truth over the Arias
    5-95 % interval. The strong phase is one linear fit to a record whose stiffness changes within
    every cycle, compared with the secant stiffness averaged over the phase: 2.1 % at most over 12
    seeds of the earlier, planar truth, up to 6 % on the building with x, y and twist per floor (CI
    seeds 1-3: +3.6, -2.2, +6.0 %); the acceptance for motion within the event is the moving-window
    minimum (test above, 3 %). Every pre/post value must pass: over 12 seeds mode 1 had
    mean -0.19 % and standard deviation 0.51 %, mode 2 -0.50 % and 0.42 %, so a normal error leaves
    2 % with probability 2e-4 per value and any of CI's 12 values with 0.2 %."""
    lines, bad = [], 0
    for seed, ev, res in events:
        sm = res.strong_motion
        assert ev.event is not None
        onset = ev.event["onset_s"]
        # the envelope peaks 6 s after the onset and decays over some 45 s
        assert onset < sm.start_s < onset + 10.0 and sm.start_s + 5.0 < sm.end_s < onset + 45.0, (seed, onset, sm)
        for name in ("pre", "post"):
            ph = res.phase(name)
            assert ph is not None and ph.modes, f"seed {seed}: no {name}-event estimate ({ph})"
            for pm in ph.modes:
                if pm.mode > 2:
                    continue
                j = _truth_mode(ev, res, pm.mode - 1)
                err = pm.frequency_hz / ev.small_amplitude_frequencies_hz[j] - 1
                lines.append(f"seed {seed} {name} mode {pm.mode}: {100 * err:+.2f} %")
                bad += abs(err) > 0.02
            assert any(pm.mode == 1 for pm in ph.modes), f"seed {seed}: mode 1 missing {name}-event"
        strong = res.phase("strong")
        assert strong is not None
        m1 = [pm for pm in strong.modes if pm.mode == 1]
        if m1:  # a strong motion shorter than half a moving window has no estimate
            j = _truth_mode(ev, res, 0)
            tr = ev.track(np.array([strong.start_s]), strong.end_s - strong.start_s)
            err = m1[0].frequency_hz / tr.frequencies_hz[0, j] - 1
            lines.append(f"seed {seed} strong mode 1: {100 * err:+.2f} % of the equivalent-linear truth")
            bad += abs(err) > 0.07
    print("\n".join(lines))
    assert bad == 0, "\n".join(lines)


def test_io_ssi_damping_intervals_cover_the_truth(events):
    """Input-output SSI damping of mode 1 before and after the event against the truth's
    equivalent-linear damping of the same phase. Its standard deviation is the spread of the
    estimates of half-overlapping sub-windows scaled by sqrt(sub-window / phase); with n
    sub-windows the 95 % interval takes Student's t with n - 1 degrees of freedom. With 12 seeds
    23 of 23 intervals held the truth (one phase had too few sub-windows); the estimates themselves
    are loose (0.004-0.029 against 0.012: ambient response with an unmeasured wind load). A
    calibrated 95 % interval holds the truth in at least 4 of 6 (CI) with probability 0.998, in
    at least 19 of 24 (SHM_FULL) with 0.999."""
    covered, total, lines = 0, 0, []
    for seed, ev, res in events:
        j = _truth_mode(ev, res, 0)
        assert res.method == "ssi-io"
        for name in ("pre", "post"):
            ph = res.phase(name)
            assert ph is not None
            pm = next((p for p in ph.modes if p.mode == 1), None)
            if pm is None or not np.isfinite(pm.damping_std):
                lines.append(f"seed {seed} {name}: no interval")
                total += 1
                continue
            z_true = ev.track(np.array([ph.start_s]), ph.end_s - ph.start_s).damping_ratios[0, j]
            half = stats.t.ppf(0.975, pm.n_sub_windows - 1) * pm.damping_std
            ok = abs(pm.damping_ratio - z_true) <= half
            covered += ok
            total += 1
            lines.append(f"seed {seed} {name}: {pm.damping_ratio:.4f} +- {half:.4f} vs {z_true:.4f}")
    print("\n".join(lines))
    need = 19 if FULL else 4
    assert total == 2 * len(SEEDS)
    assert covered >= need, "\n".join(lines)


def test_simulate_event_records_what_the_campaign_records():
    """The rerun that keeps the drift histories is the campaign's own window, sample for sample."""
    camp = _campaign(5, window_s=60.0)
    ev = simulate_event(camp, 0)
    w = camp.window(0).to_window()
    assert ev.window.channel_names == w.channel_names
    np.testing.assert_array_equal(ev.window.samples, w.samples)
    assert ev.story_drift_m.shape == (w.n_samples, 3 * 8)  # x, y, twist of each of 8 stories
    assert ev.family == "x" and np.all(ev.stiffness_nonlinear)
    tr = ev.track(np.array([0.0, 30.0]), 20.0)
    assert tr.family == "x" and tr.frequencies_hz.shape == (2, ev.small_amplitude_frequencies_hz.size)


def test_mean_square_secant_equals_the_gaussian_factor_for_gaussian_drift():
    """For Gaussian drift the secant definition is the simulator's window factor E[g'(d)] (Stein's
    lemma); for a sinusoid it is not, and it is the least-squares slope of force against drift."""
    rng = np.random.default_rng(0)
    d_ref = 0.01
    for sigma in (0.002, 0.01, 0.03):
        d = sigma * rng.standard_normal((400_000, 1))
        got = secant_factors(d, d_ref, "stiffness")[0]
        assert got == pytest.approx(equivalent_stiffness_factor(np.array([sigma]), d_ref)[0], rel=0.01)
    d = 0.02 * np.sin(np.linspace(0, 40 * np.pi, 20_001))[:, None]
    force = d / (1 + np.abs(d) / d_ref)
    slope = float(np.linalg.lstsq(d, force, rcond=None)[0][0, 0])
    assert secant_factors(d, d_ref, "stiffness")[0] == pytest.approx(slope, rel=1e-12)
    assert secant_factors(d, None, "stiffness")[0] == 1.0


def test_arias_interval_and_running_median():
    fs = 100.0
    a = np.zeros(3000)
    a[1000:2000] = np.sin(np.arange(1000) * 0.3) * 2.0
    t5, t95, total = significant_interval(a, fs)
    assert t5 == pytest.approx(10.5, abs=0.05)
    assert t95 == pytest.approx(19.5, abs=0.05)
    assert total == pytest.approx(np.pi / (2 * 9.80665) * np.sum(a * a) / fs, rel=1e-3)
    with pytest.raises(ValueError):
        significant_interval(np.zeros(100), fs)
    x = np.array([1.0, 0.2, 1.0, 1.1, np.nan, np.nan, 0.9])
    med = running_median(x, 3)
    assert med[1] == 1.0  # the single low outlier is gone
    assert np.isnan(med[5])  # one finite value of three is not enough
    np.testing.assert_array_equal(running_median(x, 1), x)


def test_event_command_writes_json_and_a_figure(tmp_path):
    from shm_ros.cli import main

    out = tmp_path / "sim"
    assert main(["simulate", "building-earthquake", "--out", str(out), "--windows", "1", "--window-s", "150",
                 "--effects", "amplitude_stiffness", "--seed", "4"]) == 0
    doc_path = tmp_path / "event.json"
    assert main(["event", str(out / "bag"), "--structure", str(out / "structure.yaml"), "--out", str(doc_path),
                 "--plots", str(tmp_path / "plots"), "--window", "150", "--n-modes", "2"]) == 0
    doc = json.loads(doc_path.read_text())
    assert "provenance" in doc and len(doc["events"]) == 1
    rec = doc["events"][0]
    assert rec["method"] == "ssi-io" and rec["input_sensor"] == "g0"
    assert {"pre", "strong", "post"} == set(rec["phases"])
    n = len(rec["windows"]["time_s"])
    assert n > 50 and len(rec["modes"]) == 2
    for m in rec["modes"]:
        assert len(m["frequency_hz"]) == n and len(m["damping_ratio"]) == n
    m1 = rec["modes"][0]
    assert m1["minimum"]["drop"] > 0.1  # PGA 0.3-1.5 m/s^2 softens the default springs noticeably
    # a window centred just before the Arias 5 % point already holds the first strong cycles
    sm, half = rec["strong_motion"], rec["moving_window"]["length_s"] / 2
    assert sm["start_s"] - half < m1["minimum"]["time_s"] < sm["end_s"] + half
    assert (tmp_path / "plots" / "event_00000.png").stat().st_size > 10_000


def test_output_only_without_an_input_channel(events):
    """Without the input: SSI-cov in every window and the strong motion from the response's Arias
    intensity. The input's colour enters the output-only estimates, and the response's intensity
    interval is later and longer than the input's, hence the looser bounds than the input-output
    acceptance (one seed). On the default truth (x, y and twist per floor) the output-only track of
    this seed reads 6-8 % low through the whole strong motion, as the softened first mode
    approaches the band where the ground motion's own spectrum is strong: the bound is 10 %, and
    this is why the input, when measured, is used by default."""
    import dataclasses

    seed, ev, _ = events[0]
    w = ev.window
    keep = [i for i, c in enumerate(w.channel_names) if c != w.input_channel]
    w = dataclasses.replace(w, channel_names=[w.channel_names[i] for i in keep], samples=w.samples[:, keep],
                            input_channel=None)
    res = analyse_event(w, EventConfig(), model_frequencies_hz=_model_frequencies(ev))
    assert res.method == "ssi-cov" and res.input_channel is None
    assert res.strong_motion.source == "response" and res.strong_motion.channel is None
    assert np.all(np.isnan(res.input_rms_m_s2)) and res.input_m_s2.size == 0
    j = _truth_mode(ev, res, 0)
    truth = ev.track(res.window_start_s, res.window_s)
    k, kt = res.tracks[0].min_index, int(np.argmin(truth.frequencies_hz[:, j]))
    assert k is not None
    assert abs(res.tracks[0].frequency_hz[k] / truth.frequencies_hz[k, j] - 1) <= 0.10
    assert abs(res.time_s[k] - res.time_s[kt]) <= 10.0
    for name in ("pre", "post"):
        ph = res.phase(name)
        assert ph is not None
        pm = next(p for p in ph.modes if p.mode == 1)
        assert abs(pm.frequency_hz / ev.small_amplitude_frequencies_hz[j] - 1) <= 0.02, (seed, name)
