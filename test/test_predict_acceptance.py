"""Acceptance of the response prediction (issue "predict"; docs/predict.md).

1. The true model (the analysis class, simulated by an independent solver: the simulator's complex
   modal superposition) predicts noise-free records to NRMS < 1 %, and records with sensor noise of
   3 % of the response RMS to within 1 point of 3 %.
2. Eight-story building with damper braces from the simulator's truth (its default model-form
   error: x, y and twist per floor with eccentric masses, a flexural component, non-proportional
   story dashpots, sensors off the stiffness centre, sensor gains/offsets/noise, unmeasured y ground
   motion and wind), nominal story stiffnesses 10-20 % off, 6 earthquakes: calibrated jointly on 3 (one time-domain
   likelihood), the updated model predicts the other 3. Floors 2, 4, 6, 8 are measured; floor 5 and
   the top story's drift are compared with the simulator's truth.

Seeds: SHM_FULL=1 pools 10 seeds and applies the issue's criteria to the pooled values; measured
there (truth eccentricity 1-2 % of the plan; joint likelihood with the AR(2) residual model; unmeasured
floors expanded): median updated NRMS 9.1 % (limit 20 %), updated/nominal at most 0.61 (limit < 1),
strong-motion coverage 0.896 (limits 0.80-0.99), peaks inside 0.900 (limit 0.80), floor 5 / drift
NRMS at most 16.2 % (limit 20 %). The truth's top-story drift is read at one plan point (the top
hidden sensor's): differencing the two top hidden sensors at their own, misplaced, plan positions
added floor 7's whole rotation times their 0.1-1 m plan distance (seed 7: 17.7 % of the drift) and
made the worst value 21.0 %.
CI runs seed 0 alone (see the printed line for its numbers). The NRMS, ratio and
hidden-floor criteria keep their limits. The peak criterion counts 12 peaks (4 channels x 3
events): at the rate 0.833 measured before the truth's eccentricity was reduced (the lowest seen),
P(fewer than 7 of 12 inside) = 0.008 (binomial), so CI asks for >= 7 of 12, which a correct
method passes with probability 0.99. The coverage limits 0.80-0.99 are kept (seed 0 pools ~8000
strong-motion samples).
"""

from __future__ import annotations

import numpy as np
import pytest
from predict_synth import FULL, STORY_HEIGHT_M, simulate_quakes

from shm_ros.core.bayes.records import RecordSet
from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.core.models import build_model
from shm_ros.core.predict import EventRecord, PredictConfig, draws_from_posterior, event_from_window, predict_event
from shm_ros.core.predict.signals import baseline_correct, nrms_pct, pre_event_end, strong_motion
from shm_ros.core.simulate.excitation import earthquake
from shm_ros.core.simulate.linear import from_state_space
from shm_ros.core.structure import structure_from_dict

SEEDS = list(range(10)) if FULL else [0]


def _true_model_case(noise: float) -> tuple[float, float]:
    """(NRMS %, noise % of response RMS) of the nominal model on records it generated itself."""
    from shm_ros.core.simulate.scenario import shear_building_structure

    d = shear_building_structure(8)
    for f in d["shear_building"]["floors"]:
        f["height"] = STORY_HEIGHT_M
    d["shear_building"]["dampers"] = [{"between": [i, i + 1], "c": 4.0e6} for i in range(8)]
    model = build_model(structure_from_dict(d))
    M, K, C = model.mass(), model.stiffness(), model.damping()
    n, fs = model.n_dof, 50.0
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ C]])
    B = np.concatenate([np.zeros(n), -np.ones(n)])[:, None]
    ids = ["f1", "f4", "f6", "f8"]
    S = np.stack([model.sensor_rows[s] for s in ids])
    sysm = from_state_space(A, B, S @ A[n:], S @ B[n:] + 1.0)  # absolute = relative + ground
    rng = np.random.default_rng(3)
    ag = earthquake(rng, 3000, fs, 10.0, 1.0)
    y = sysm.simulate(ag, 1.0 / fs)
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    y_meas = y + noise * rms * rng.standard_normal(y.shape)
    rec = EventRecord("w", 0, fs, ag[None, :], y_meas, ids)
    pred = predict_event(model, rec, None, PredictConfig(n_draws=0))
    nr = [pred.channel(c).scores["nrms_pct"] for c in ids]
    return float(np.max(nr)), float(np.min(nr))  # type: ignore[arg-type]


def test_true_model_noise_free_and_noisy():
    worst, _ = _true_model_case(0.0)
    assert worst < 1.0
    hi, lo = _true_model_case(0.03)
    assert 2.0 <= lo and hi <= 4.0, (lo, hi)


def _calibrate(model, spec, windows, cfg: PredictConfig):
    recs = []
    for w in windows:
        ev = event_from_window(w, model)
        n_pre = pre_event_end(ev.inputs[0], ev.fs, cfg.onset_arias, cfg.min_pre_event_s)
        recs.append(AccelerationRecord(1 / ev.fs, baseline_correct(ev.inputs.T, n_pre, cfg.baseline).T,
                                       baseline_correct(ev.outputs, n_pre, cfg.baseline), ev.channel_ids))
    uc = UpdateConfig(likelihood="time", n_chains=8, n_steps=150, max_steps=150, evidence=False,
                      ess_target=50, rhat_target=1.2)
    return update(model, RecordSet(recs), uc, spec.parameters)


def _one_seed(seed: int) -> dict:
    q = simulate_quakes(seed, 6, duration_s=50.0, fs=40.0, sensor_floors=(2, 4, 6, 8), truth_floors=(5, 7, 8))
    spec = structure_from_dict(q.structure)
    model = build_model(spec)
    cfg = PredictConfig(n_draws=200, seed=seed)
    post = _calibrate(model, spec, q.windows[:3], cfg)
    draws = draws_from_posterior(post, model, cfg.n_draws, np.random.default_rng(seed), cfg.relative_error)
    out: dict = {"nrms": [], "ratio": [], "inside": [], "outside_strong": 0, "n_strong": 0, "peaks": [],
                 "hidden": []}
    for w in q.windows[3:]:
        ev = event_from_window(w, model)
        p = predict_event(model, ev, draws, cfg)
        for cid in ("f4", "f8"):
            s = p.channel(cid).scores
            out["nrms"].append(s["nrms_pct"])
            out["ratio"].append(s["nrms_pct"] / s["nrms_pct_nominal"])
        for c in p.channels:
            if c.measured:
                assert c.values is not None
                y, lo, hi = c.values[p.strong], c.lower[p.strong], c.upper[p.strong]
                out["outside_strong"] += int(np.sum((y < lo) | (y > hi)))
                out["n_strong"] += y.size
                out["peaks"].append(bool(c.scores["peak_inside"]))
        truth = q.truth[w.window_id]
        col = q.truth_names.index
        f5 = nrms_pct(truth[:, col("h5")], p.channel("floor5").mean)
        drift = nrms_pct(truth[:, col("drift_top")], p.channel("drift_ratio8").mean * STORY_HEIGHT_M)
        out["hidden"] += [f5, drift]
        assert strong_motion(ev.inputs[0]).stop > 0
    return out


DOC_CI = (r"Seed 0 \(CI\): median updated NRMS at floors 4 and 8 ([\d.]+) % \(updated/nominal at most ([\d.]+)\), "
          r"strong-motion coverage of the 95 % band ([\d.]+), measured peaks inside their 95 % interval (\d+) "
          r"of (\d+), against the simulator's truth at most ([\d.]+) % NRMS for the floor-5 acceleration and "
          r"([\d.]+) % for the top-story drift")
#: the figures of DOC_FULL's groups, as docs/results/full_size.json names them
FULL_KEYS = ("median_nrms_pct", "ratio_max", "coverage", "peaks_inside", "hidden_max_pct")
DOC_FULL = (r"`SHM_FULL=1`, 10 seeds pooled: median NRMS ([\d.]+) %, updated/nominal at most ([\d.]+) on every event, "
            r"strong-motion coverage ([\d.]+), peaks inside ([\d.]+), floor 5 / drift at most ([\d.]+) % NRMS")


def documented_figures(full: bool) -> list[str]:
    """The figures docs/predict.md quotes for the CI run (seed 0) or the full-size run, as written."""
    import re
    from pathlib import Path

    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "predict.md").read_text().split())
    m = re.search(DOC_FULL if full else DOC_CI, text)
    assert m, "docs/predict.md no longer has its sentence of figures (DOC_FULL / DOC_CI in this test)"
    return list(m.groups())


def _same(documented: str, measured: float) -> bool:
    """``measured`` is within one unit of ``documented``'s last digit: the rounding, plus what another
    CPU's BLAS kernels move (OpenBLAS picks its kernels by CPU; on a second machine seed 0 gave 12.148 %
    and 0.8562 where the first gave figures that round to 12.2 % and 0.857)."""
    decimals = len(documented.partition(".")[2])
    return abs(measured - float(documented)) <= 10.0 ** -decimals + 1e-12


def test_documented_figures_are_read_and_compared():
    assert len(documented_figures(False)) == 7 and len(documented_figures(True)) == 5
    assert _same("0.856", 0.8563) and _same("12.2", 12.148) and not _same("12.1", 12.25) and _same("10", 10)
    assert not _same("10", 11.5) and not _same("0.857", 0.8555)


@pytest.mark.parametrize("seeds", [SEEDS])
def test_calibrated_prediction_of_other_events(seeds):
    res = [_one_seed(s) for s in seeds]
    nrms = np.concatenate([r["nrms"] for r in res])
    ratio = np.concatenate([r["ratio"] for r in res])
    coverage = 1 - sum(r["outside_strong"] for r in res) / sum(r["n_strong"] for r in res)
    peaks = np.mean(np.concatenate([r["peaks"] for r in res]))
    hidden = np.concatenate([r["hidden"] for r in res])
    print(f"median NRMS {np.median(nrms):.2f} %, max updated/nominal {ratio.max():.3f}, strong coverage "
          f"{coverage:.3f}, peaks inside {peaks:.3f}, NRMS max floor 5 {hidden[0::2].max():.2f} %, "
          f"top drift {hidden[1::2].max():.2f} %")
    assert np.median(nrms) <= 20.0
    assert np.all(ratio < 1.0)
    assert 0.80 <= coverage <= 0.99
    assert peaks >= (0.80 if FULL else 7 / 12)
    assert np.all(hidden < 20.0)
    # the figures docs/predict.md quotes for this run (seed 0 in CI, the 10 pooled seeds at full size)
    n_in = int(np.sum(np.concatenate([r["peaks"] for r in res])))
    n_peaks = sum(len(r["peaks"]) for r in res)
    measured = ([np.median(nrms), ratio.max(), coverage, peaks, hidden.max()] if FULL else
                [np.median(nrms), ratio.max(), coverage, n_in, n_peaks, hidden[0::2].max(), hidden[1::2].max()])
    if FULL:  # written for test_documented_results.py, which compares docs/predict.md's sentence with it
        from full_size_results import record

        record("predict_acceptance", {k: f"{m:.{d}f}" for k, m, d in zip(FULL_KEYS, measured, (1, 2, 3, 3, 1),
                                                                          strict=True)},
               "SHM_FULL=1 python -m pytest -s test/test_predict_acceptance.py")
        return
    stale = [(d, m) for d, m in zip(documented_figures(FULL), measured, strict=True) if not _same(d, m)]
    assert not stale, f"docs/predict.md quotes figures this run does not give (documented, measured): {stale}"
