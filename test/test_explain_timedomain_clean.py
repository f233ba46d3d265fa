"""explain on earthquake series in the time domain: a clean series (no amplitude effect) raises no
amplitude entry, and the verdict's JSON keeps its keys (docs/explain.md, "Time domain").

The series of :mod:`explain_td_cases` without an effect (the simulator's default model-form error only).
CI runs seed 0, SHM_FULL=1 seeds 0-9; the false-alarm rate itself is the shipped threshold's calibration
(``threshold_timedomain.json``: the 99th percentile of the largest gain over 100 clean series, checked
against its recorded gains in ``test_explain_engine.py``).
"""

from __future__ import annotations

import pytest
from explain_td_cases import DAMP, STIFF, run_series
from predict_synth import FULL

CLEAN_SEEDS = list(range(10)) if FULL else [0]


@pytest.mark.parametrize("seed", CLEAN_SEEDS)
def test_clean_has_no_amplitude_entry(seed):
    _, v = run_series(None, seed)
    print(f"seed {seed}: gains {[(c.label, round(c.log_evidence_gain, 1)) for c in v.tried]}")
    assert not [c for c in v.missing_physics if c.name in (STIFF, DAMP)]


def test_verdict_json_backward_compatible():
    _, v = run_series(None, 0)
    d = v.to_dict()
    assert set(d) >= {"mismatch", "missing_physics", "fit", "candidates", "threshold", "notes"}
    assert "nrms_pct" in d["fit"]["before"] and "frequency_rmse_pct" not in d["fit"]["before"]
    assert {c["label"].endswith("/within_event") for c in d["candidates"]} == {True, False}
