"""explain on earthquake series in the time domain: a clean series (no amplitude effect) raises no
amplitude entry, and the verdict's JSON keeps its keys and holds consistent values (docs/explain.md,
"Time domain").

The series of :mod:`explain_td_cases` without an effect (the simulator's default model-form error only).
CI runs seed 0, SHM_FULL=1 seeds 0-9; the false-alarm rate itself is the shipped threshold's calibration
(``threshold_timedomain.json``: the 99th percentile of the largest gain over 100 clean series, checked
against its recorded gains in ``test_explain_engine.py``).
"""

from __future__ import annotations

import json
import math

import pytest
from explain_td_cases import DAMP, STIFF, run_series
from predict_synth import FULL

CLEAN_SEEDS = list(range(10)) if FULL else [0]


@pytest.mark.parametrize("seed", CLEAN_SEEDS)
def test_clean_has_no_amplitude_entry(seed):
    _, v = run_series(None, seed)
    print(f"seed {seed}: gains {[(c.label, round(c.log_evidence_gain, 1)) for c in v.tried]}")
    assert not [c for c in v.missing_physics if c.name in (STIFF, DAMP)]


def test_verdict_json_keys_and_values():
    """The keys (backward compatible) and the values: the JSON equals the verdict it was written from,
    accepted means every check passed, the evidence gains and fit scores are finite, and the fit is no
    worse than the nominal model's. One test, so the series is explained once per process."""
    _, v = run_series(None, 0)
    d = json.loads(json.dumps(v.to_dict()))
    assert set(d) >= {"mismatch", "missing_physics", "fit", "candidates", "threshold", "notes"}
    assert "nrms_pct" in d["fit"]["before"] and "frequency_rmse_pct" not in d["fit"]["before"]
    assert {c["label"].endswith("/within_event") for c in d["candidates"]} == {True, False}
    before, after = d["fit"]["before"]["nrms_pct"], d["fit"]["after"]["nrms_pct"]
    assert before == pytest.approx(v.fit_before.nrms_pct) and after == pytest.approx(v.fit_after.nrms_pct)
    assert 0 < after <= before * 1.001 < 100, (before, after)
    for key in ("before", "after"):
        assert 0 < d["fit"]["held_out"][key]["nrms_pct"] < 100
    accepted = {c["label"] for c in d["candidates"] if c["accepted"]}
    assert accepted == {m["label"] for m in d["missing_physics"]}
    assert [m["label"] for m in d["missing_physics"]] == [c.label for c in v.missing_physics]
    for c in d["candidates"]:
        assert math.isfinite(c["log_evidence_gain"]), c["label"]
        failed = [r for r in c["reasons"] if r.startswith("failed")]
        assert c["reasons"] and (not failed) == c["accepted"], (c["label"], c["reasons"])
        for name, (lo, hi) in c["intervals"].items():
            assert lo <= hi and name in c["parameters"], (c["label"], name)
    assert all(isinstance(x, (int, float)) and math.isfinite(x) for x in d["threshold"].values()
               if not isinstance(x, (str, bool, dict, list)) and x is not None)
