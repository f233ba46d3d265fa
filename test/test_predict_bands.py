"""Acceptance of the predictive bands outside the model's class (docs/predict.md, "Bands that hold").

Truth campaigns from test/predict_truth.py (``SHM_PREDICT_TRUTH`` picks the source; default here
``opensees``: the independent OpenSeesPy generator's hysteretic campaigns, test/predict_opensees.py:
yielding story springs, mass centres 2-6 % of the plan off, non-proportional damping, a damper).
Each campaign calibrates the planar model on its first events (joint time-domain posterior, each
event its own error variance; the model error by leave-one-event-out cross-validation) and
predicts its later ones. Criteria (pooled over campaigns):

- coverage: the median over events of the strong-motion coverage of the 95 % band in 0.85-0.99;
- peaks inside: the measured peaks inside their 95 % interval >= 85 %;
- sharpness: the mean 95 % half-width <= 3 x the RMS prediction error (strong motion);
- accuracy: median NRMS <= max(15 %, oracle NRMS + 3 points), the oracle being the model class
  fitted by least squares to the predicted events themselves;
- the updated model below the nominal one on >= 90 % of events;
- unmeasured floors and drift ratios: the truth's peak inside its 95 % interval >= 85 %.

Seeds: derived from the git tree of ``shm_ros/core`` (:func:`acceptance_seeds`), so no seed is
chosen; the full size (``SHM_FULL=1``: 10 campaigns, 2-4 calibration and 2-5 predicted events,
3-10 stories; ``SHM_PREDICT_LOG=1`` appends its figures, commit, tree and seeds to the log at the end
of docs/predict.md).

CI runs two campaigns (3 + 3 events each, 3-6 stories, seeds from the same hash), pooled as the
full run pools its ten, with thresholds a method behaving as it does today passes with >= 99 %
probability: `python -m bench.calibrate_predict_bands --campaigns 60 --extra 13851861` scores 60
development campaigns of this profile (and a CI campaign that once fell below the older one-campaign
threshold) and pools every one of their 1,830 pairs (docs/results/predict_bands_reduced.json). Over
those pairs the 0.5 % quantiles are: median coverage 0.713, peaks inside 0.500, unmeasured inside
0.625, events below nominal 3 of 6; the 99.5 % quantiles: sharpness 2.73 (max 2.94), median NRMS
25.2 points above max(15 %, oracle) (max 32.7). Thresholds, each beyond its quantile and chosen so
that all six together fail 0.6 % of the pairs (the JSON's ``pairs_failing_any_threshold``; the
extra campaign, weighted as one in 61, makes that pessimistic): coverage >= 0.65, peaks >= 0.45,
unmeasured >= 0.50, below nominal >= 3 of 6, sharpness <= 3.5, NRMS <= max(15 %, oracle) + 30
points. (One campaign alone scatters too widely for a useful 99 % bound: unmeasured inside went
down to 0.33 on campaign 13851861.) The criteria themselves are the full run's.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from acceptance_seeds import acceptance_seeds, core_tree
from predict_bands import score_campaign
from predict_truth import Profile, truth_source

FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
ROOT = Path(__file__).resolve().parents[1]
#: the reduced check's thresholds, as ``bench.calibrate_predict_bands`` derived and wrote them
REDUCED_THRESHOLDS = json.loads((ROOT / "docs" / "results" / "predict_bands_reduced.json").read_text())["thresholds"]


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
    n = 10 if FULL else 2
    seeds = [DEV_BASE + k for k in range(int(os.environ.get("SHM_PREDICT_DEV_N", n)))] if DEV else acceptance_seeds(n)
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
        assert sharp <= 3.0
    else:  # two campaigns of 3 + 3 events: the 99 % thresholds of the module doc, as derived
        figures = {"coverage": coverage, "peaks": peaks, "unmeasured": hidden, "sharpness": sharp,
                   "below_nominal": float(cat["better"].sum()), "nrms_over_limit_points": nrms - max(15.0, oracle)}
        for name, (op, bound) in REDUCED_THRESHOLDS.items():
            holds = figures[name] >= bound if op == ">=" else figures[name] <= bound
            assert holds, f"{name} {figures[name]:.3f}, needs {op} {bound}"


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
