"""explain's reported parameters come from every window, training and held-out.

The held-out windows decide acceptance; afterwards they hold information the parameters need: a
stiffness change inside a held-out block is placed only by that block's windows (on the training
windows alone its time is free anywhere in the block). Cases: random single steps (test/explain_cases.py,
the simulator's model-form error) whose change falls inside a held-out block, 192 windows each.
"""

from __future__ import annotations

from explain_cases import draw_case

from shm_ros.core.explain.config import ExplainConfig
from shm_ros.core.explain.explain import explain, split
from shm_ros.core.structure import structure_from_dict

# seeds of draw_case(seed, "stiffness_change_at_time", n_windows=192) whose change window and the one
# before it are held out: 11 of 31000-31039. On the nine whose verdict holds a step (2026-11-27) it
# lands on the truth's window in all nine; fitted on the training windows it was off by 5, -4, -2,
# -2, 1, 4, 3, -2, -1. CI takes two (a girder and a building; 5 and -4 before).
SEEDS = (31001, 31002)
# the evidence check, prior sensitivity and surrogate check do not change what is named or fitted
FAST = ExplainConfig(nested_check=False, prior_sensitivity=False, surrogate_check=False)


def test_a_change_inside_a_held_out_block_is_placed_by_its_windows():
    errors = []
    for seed in SEEDS:
        case = draw_case(seed, "stiffness_change_at_time", n_windows=192)
        train = split(case.obs.times - case.obs.times[0], ExplainConfig())
        assert not train[case.truth.change_index], seed  # the premise
        v = explain(case.obs, structure_from_dict(case.structure), FAST)
        step = next(c for c in v.missing_physics if c.name == "stiffness_change_at_time")
        assert step.extra.get("estimated_on") == "all windows", step.extra
        errors.append(int(step.extra["change_window"]) - int(case.truth.change_index))
    # the change moves the most affected mode by 2-4.5 % against 0.2-0.5 % scatter per window: the
    # window is found to within one; on the training windows alone, anywhere within the hint's +-6
    assert max(abs(e) for e in errors) <= 1, errors
