"""The full-size figures the docs quote equal those the full-size runs wrote.

``docs/results/full_size.json`` holds each full-size acceptance run's figures as the docs print them;
the runs write it (``SHM_FULL=1``, test/full_size_results.py). Here, in CI and without running
anything: explain's tallies in docs/explain.md (40/40 right top names, 37/40 with every check, 0/50
false alarms) and predict's pooled figures in docs/predict.md and in test_predict_acceptance.py's
docstring (median NRMS 9.1 %, updated/nominal 0.61, coverage 0.896, peaks 0.900, 16.2 %) must be the
file's. A figure changed on either side fails (checked on a planted change).
"""

from __future__ import annotations

import re

import pytest
import test_predict_acceptance
from full_size_results import recorded
from test_explain_acceptance import documented_tallies
from test_predict_acceptance import FULL_KEYS, documented_figures

# the same figures in test_predict_acceptance.py's docstring
DOCSTRING = (r"median updated NRMS ([\d.]+) % \(limit 20 %\), updated/nominal at most ([\d.]+) \(limit < 1\), "
             r"strong-motion coverage ([\d.]+) \(limits 0.80-0.99\), peaks inside ([\d.]+) \(limit 0.80\), "
             r"floor 5 / drift NRMS at most ([\d.]+) % \(limit 20 %\)")


def mismatches(quoted: dict[str, str], written: dict[str, str]) -> dict[str, tuple[str, str | None]]:
    """The quoted figures that are not the written ones: name -> (quoted, written)."""
    return {k: (v, written.get(k)) for k, v in quoted.items() if written.get(k) != v}


def _predict_quotes() -> dict[str, dict[str, str]]:
    text = " ".join((test_predict_acceptance.__doc__ or "").split())
    m = re.search(DOCSTRING, text)
    assert m, "test_predict_acceptance.py's docstring no longer has its sentence of full-size figures"
    return {"docs/predict.md": dict(zip(FULL_KEYS, documented_figures(True), strict=True)),
            "test_predict_acceptance.py": dict(zip(FULL_KEYS, m.groups(), strict=True))}


def test_explain_tallies_are_the_full_size_run():
    run = recorded()["explain_acceptance"]
    assert set(run["figures"]) == {"top", "every_check", "alarms", "alarm_rate"}, run
    bad = mismatches(documented_tallies(), run["figures"])
    assert not bad, f"docs/explain.md quotes tallies its full-size run ({run['date']}) did not give: {bad}"


def test_predict_figures_are_the_full_size_run():
    run = recorded()["predict_acceptance"]
    assert set(run["figures"]) == set(FULL_KEYS), run
    for where, quoted in _predict_quotes().items():
        bad = mismatches(quoted, run["figures"])
        assert not bad, f"{where} quotes figures the full-size run did not give: {bad}"


@pytest.mark.parametrize("section", ["explain_acceptance", "predict_acceptance"])
def test_a_changed_figure_is_caught(section):
    written = recorded()[section]["figures"]
    quoted = (documented_tallies() if section == "explain_acceptance" else _predict_quotes()["docs/predict.md"])
    assert not mismatches(quoted, written)
    key = sorted(written)[0]
    planted = {**written, key: written[key] + "1"}
    assert set(mismatches(quoted, planted)) == {key}
    assert set(mismatches({**quoted, key: "7"}, written)) == {key}
