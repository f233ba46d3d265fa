"""The identify bench's accuracy comparison with pyOMA2 (bench/bench_identify.py): the frequency
errors of the two tools are compared window by window, so that "equal or smaller" is judged on the
difference (free of the windows' own scatter), with its standard error."""

from __future__ import annotations

import numpy as np

from bench.bench_identify import paired_frequency_difference


def test_paired_difference_says_larger_only_when_it_is_shown():
    rng = np.random.default_rng(0)
    peer = rng.uniform(0.05, 0.2, (40, 2))
    same = peer + rng.normal(0, 0.01, (40, 2))  # scatter of the picking only: not shown larger
    worse = peer + 0.02 + rng.normal(0, 0.01, (40, 2))  # larger on every window
    ours = np.column_stack([same[:, 0], worse[:, 1]])
    rows = [list(r) for r in ours]
    rows[3][0] = None  # a mode one tool missed leaves that window out of its comparison
    d = paired_frequency_difference(rows, [list(r) for r in peer])
    assert d[0]["windows"] == 39 and d[1]["windows"] == 40
    assert d[0]["equal_or_smaller"] and not d[1]["equal_or_smaller"]
    assert abs(d[1]["mean"] - 0.02) < 3 * d[1]["se"] and d[1]["se"] < 0.005
