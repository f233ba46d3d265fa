"""Frozen ground under a girder's bearings (test/explain_cases.py, ``support_flexibility`` drawn as
"frozen": the soil in series with the bearings stiffens below a knee temperature) is named
``support_flexibility``, alone or tied with a knee of the same bearings' stiffness (the two forms
of one change, which frequencies and shapes cannot tell apart), with the truth's knee.

Before the frost knee became a parameter, five of six frozen cases at 576 windows (seeds 8030-8038)
were named a temperature knee of the bearings alone.

Statistical criterion at reduced size: the first ``N_CASES`` = 6 frozen draws from seed 8100 on (the
draw of scour or frost is the generator's; scour cases are in the acceptance test), 64 windows each,
without the second evidence estimator, prior sensitivity and surrogate check (they do not change the
names). A case passes when its top name (or tie) and the knee are right. Rate of a correct method at
this size, measured once on 30 other frozen draws (seeds 8400-8453): 28/30 at 64 windows (26/30 at
96). Taking p0 = 0.85 (below both), the number passing is binomial(6, p0) and
P(at least ``THRESHOLD`` = 3 of 6) = 1 - P(X <= 2) = 0.994, so a correct method fails this test with
probability below 1 %; at the old rate (1 in 6) P(at least 3 of 6) = 0.062, so that fault fails it
with probability 0.94. The test recomputes both probabilities and checks them.
"""

from __future__ import annotations

from explain_cases import draw_case
from explain_scoring import score
from scipy.stats import binom

from shm_ros.core.explain.config import ExplainConfig
from shm_ros.core.explain.explain import explain
from shm_ros.core.structure import structure_from_dict

WINDOWS = 64
N_CASES, THRESHOLD = 6, 3
P_CORRECT, P_OLD_FAULT = 0.85, 1 / 6


def _frozen_cases(n: int):
    seed = 8100
    while n:
        case = draw_case(seed, "support_flexibility", n_windows=WINDOWS)
        if case.truth.parameters.get("mode") == "frozen":
            n -= 1
            yield seed, case
        seed += 1


def test_the_threshold_is_the_binomial_one():
    passes = binom.sf(THRESHOLD - 1, N_CASES, P_CORRECT)  # P(X >= THRESHOLD)
    assert passes >= 0.99 and binom.sf(THRESHOLD, N_CASES, P_CORRECT) < 0.99  # the largest such threshold
    assert binom.sf(THRESHOLD - 1, N_CASES, P_OLD_FAULT) < 0.1


def test_frozen_supports_named_with_their_knee():
    rows = []
    for seed, case in _frozen_cases(N_CASES):
        v = explain(case.obs, structure_from_dict(case.structure),
                    ExplainConfig(nested_check=False, prior_sensitivity=False, surrogate_check=False))
        d = v.to_dict()
        s = score(d, case, v.figures)
        rows.append((seed, s.top, s.details.get("tied"), s.checks, s.top_ok and s.checks.get("knee", False)))
    print(f"frozen supports named with their knee: {sum(r[-1] for r in rows)}/{len(rows)}")
    assert sum(r[-1] for r in rows) >= THRESHOLD, rows
