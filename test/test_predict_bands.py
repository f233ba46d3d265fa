"""Acceptance of the predictive bands outside the model's class (docs/predict.md, "Bands that hold").

Truth campaigns from test/predict_truth.py (``SHM_PREDICT_TRUTH`` picks the source; default the
project's simulator with mass centres 2-6 % of the plan off the stiffness centre, non-proportional
damping, damper braces and softening story springs). Each campaign calibrates the planar model on
its first events (joint time-domain posterior; the model error by leave-one-event-out
cross-validation) and predicts its later ones. Criteria (pooled over campaigns):

- coverage: the median over events of the strong-motion coverage of the 95 % band in 0.85-0.99;
- peaks inside: the measured peaks inside their 95 % interval >= 85 %;
- sharpness: the mean 95 % half-width <= 3 x the RMS prediction error (strong motion);
- accuracy: median NRMS <= max(15 %, oracle NRMS + 3 points), the oracle being the model class
  fitted by least squares to the predicted events themselves;
- the updated model below the nominal one on >= 90 % of events;
- unmeasured floors and drift ratios: the truth's peak inside its 95 % interval >= 85 %.

Seeds: derived from the git tree of ``shm_ros/core`` (:func:`acceptance_seeds`), so no seed is
chosen; the full size (``SHM_FULL=1``: 10 campaigns, 2-4 calibration and 2-5 predicted events)
records its figures, tree and seeds in docs/predict.md.

CI runs one campaign (3 + 3 events, seed from the same hash) with thresholds a correct method passes
with >= 99 % probability, from the full-size runs (docs/predict.md): the campaign's median coverage
>= 0.60 (campaign medians 0.67-1.00, normal: mean 0.89, sd 0.11; the upper end needs the full run,
a quarter of single events cover > 0.99); >= 7 of 12 measured peaks inside (binomial at the
measured 0.864: P(< 7) = 0.003); >= 27 of 36 unmeasured peaks inside (at 0.92: P(< 27) = 0.0004,
room for misses clustering within an event); the updated model below the nominal on at least one
of the 3 events (at 0.94 per event P(none) = 2e-4; two of three would fail 1.04 % of the time);
sharpness <= 6.4 (one campaign's ratio 0.47-3.58, lognormal: log mean 0.50, log sd 0.58, 99 %
quantile 6.4; pooled over 10 campaigns 1.5; the full run asks <= 3); median NRMS <= max(15 %,
oracle + 15 points) (one campaign's gap to the oracle -0.2 to 13.2 points, normal: mean 4.2, sd
4.6, 99 % quantile 14.9: events differ in their equivalent-linear stiffness and damping, which
calibration events of other strengths cannot pin), so CI bounds only gross failures and the
+ 3 criterion is the full run's.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from acceptance_seeds import acceptance_seeds, core_tree
from predict_bands import score_campaign
from predict_truth import Profile, truth_source

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
ROOT = Path(__file__).resolve().parents[1]


# development seeds (SHM_PREDICT_DEV=1): never the acceptance's, for tuning; nothing is recorded
DEV = os.environ.get("SHM_PREDICT_DEV", "") not in ("", "0")
DEV_BASE = 900_000


def profiles(seeds: list[int]) -> list[Profile]:
    """Full size: 2-4 calibration and 2-5 predicted events per campaign, drawn from the seed, 3-10
    stories; CI: 3 + 3 events, 3-6 stories. Records of 30 s at 50 Hz."""
    if not FULL:
        return [Profile(n_calibration=3, n_predicted=3, duration_s=30.0, fs=50.0, stories=(3, 6)) for _ in seeds]
    out = []
    for s in seeds:
        r = np.random.default_rng(s)
        out.append(Profile(n_calibration=int(r.integers(2, 5)), n_predicted=int(r.integers(2, 6)), duration_s=30.0,
                           fs=50.0, stories=(3, 10)))
    return out


def test_bands_hold_outside_the_model_class():
    n = 10 if FULL else 1
    seeds = [DEV_BASE + k for k in range(n)] if DEV else acceptance_seeds(n)
    src = truth_source("opensees")
    res = [score_campaign(src(s, p), s) for s, p in zip(seeds, profiles(seeds), strict=True)]
    for s, r in zip(seeds, res, strict=True):
        h, e = np.asarray(r["half"]), np.asarray(r["rmse"])
        print(f"campaign {s}: sharpness {np.mean(h) / np.sqrt(np.mean(e ** 2)):.2f}, NRMS - oracle "
              f"{np.median(r['nrms']) - np.median(r['oracle']):.1f}, coverage {np.median(r['coverage']):.3f}, "
              f"peaks {sum(r['peaks'])}/{len(r['peaks'])}, unmeasured {sum(r['hidden'])}/{len(r['hidden'])}, "
              f"below nominal {sum(r['better'])}/{len(r['better'])}")
    cat = {k: np.concatenate([np.asarray(r[k], float) for r in res]) for k in res[0] if k != "hidden_names"}
    coverage = float(np.median(cat["coverage"]))
    peaks = float(np.mean(cat["peaks"]))
    sharp = float(np.mean(cat["half"]) / np.sqrt(np.mean(cat["rmse"] ** 2)))
    nrms, oracle = float(np.median(cat["nrms"])), float(np.median(cat["oracle"]))
    better = float(np.mean(cat["better"]))
    hidden = float(np.mean(cat["hidden"]))
    print(f"\ncore tree {core_tree()[:12]} seeds {seeds}: events {cat['coverage'].size}, coverage (median) "
          f"{coverage:.3f} per event {np.round(cat['coverage'], 3).tolist()}, peaks inside {peaks:.3f}, "
          f"half-width / RMS error {sharp:.2f}, median NRMS {nrms:.1f} % (oracle {oracle:.1f} %), "
          f"updated below nominal {better:.2f}, unmeasured peaks inside {hidden:.3f}")
    print(f"per event below nominal {cat['better'].astype(int).tolist()}; per channel NRMS "
          f"{np.round(cat['nrms'], 1).tolist()}; oracle {np.round(cat['oracle'], 1).tolist()}; peaks "
          f"{cat['peaks'].astype(int).tolist()}; unmeasured {cat['hidden'].astype(int).tolist()}")
    checks = {"coverage": 0.85 <= coverage <= 0.99, "peaks": peaks >= 0.85, "sharpness": sharp <= 3.0,
              "NRMS": nrms <= max(15.0, oracle + 3.0), "below nominal": better >= 0.9, "unmeasured": hidden >= 0.85}
    if FULL and not DEV and os.environ.get("SHM_PREDICT_LOG", "") not in ("", "0"):
        _append_log(seeds, cat["coverage"].size, coverage, peaks, sharp, nrms, oracle, better, hidden, checks)
    if FULL:
        assert 0.85 <= coverage <= 0.99
        assert peaks >= 0.85
        assert nrms <= max(15.0, oracle + 3.0)
        assert better >= 0.9
        assert hidden >= 0.85
    else:  # one campaign of 3 + 3 events: thresholds of the module doc
        assert coverage >= 0.60
        assert cat["peaks"].sum() >= 7
        assert nrms <= max(15.0, oracle + 15.0)
        assert cat["better"].sum() >= 1
        assert cat["hidden"].sum() >= 27
    assert sharp <= (3.0 if FULL else 6.4)


def _append_log(seeds: list[int], events: int, coverage: float, peaks: float, sharp: float, nrms: float,
                oracle: float, better: float, hidden: float, checks: dict[str, bool]) -> None:
    """One line at the end of docs/predict.md (its last section is the acceptance log)."""
    import subprocess
    from datetime import UTC, datetime

    def git(*a: str) -> str:
        return subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True).stdout.strip()

    dirty = " (with uncommitted changes)" if git("status", "--porcelain", "--", "shm_ros", "test") else ""
    failed = [k for k, ok in checks.items() if not ok]
    line = (f"- {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, commit {git('rev-parse', '--short', 'HEAD')}{dirty}, "
            f"core tree `{core_tree()}`, seeds `{seeds}`: {events} events; coverage {coverage:.3f}, peaks inside "
            f"{peaks:.3f}, half-width / RMS error {sharp:.2f}, median NRMS {nrms:.1f} % (oracle {oracle:.1f} %, "
            f"limit {max(15.0, oracle + 3.0):.1f} %), below nominal {better:.2f}, unmeasured inside {hidden:.3f}: "
            + ("**all criteria hold**" if not failed else f"**fails: {', '.join(failed)}**") + "\n")
    with (ROOT / "docs" / "predict.md").open("a") as fh:
        fh.write(line)


def test_recorded_full_size_seeds_follow_from_the_recorded_tree():
    """docs/predict.md records the full run's core tree and seeds: the seeds must be the ones the
    tree gives (no seed chosen by hand)."""
    import re

    text = (ROOT / "docs" / "predict.md").read_text()
    found = re.findall(r"core tree\s+`([0-9a-f]{40})`,\s+seeds\s+`\[([0-9, ]+)\]`", text)
    assert found, "docs/predict.md does not record the full run's core tree and seeds"
    for tree, seeds in found:  # every run in the log
        assert [int(x) for x in seeds.split(",")] == acceptance_seeds(10, tree), tree
