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


def test_a_loss_without_a_time_parameter_starts_where_its_windows_say():
    """A damper lost inside a held-out block (development case 20002: lost at window 78, held-out
    windows 72-95, locate's hint their first window): the loss is placed within the hinted span on
    every window and its size comes out right (0.002 of a story with the drifting misfit when it
    started at the hint; 0.088 now; truth 0.090)."""
    from explain_scoring import parameter_checks, top_entry

    case = draw_case(20002, "damper_stiffness", n_windows=192)
    train = split(case.obs.times - case.obs.times[0], ExplainConfig())
    assert not train[case.truth.change_index], "the premise: the loss falls in a held-out block"
    v = explain(case.obs, structure_from_dict(case.structure), FAST)
    top = top_entry(v.to_dict())
    assert top is not None and top["name"] == "damper_stiffness", top
    checks = parameter_checks("damper_stiffness", top, case.truth, case.obs.times)
    assert checks == {"time": True, "damper": True}, (checks, top["parameters"], top.get("time"))
    assert abs(int(top["change_window"]) - case.truth.change_index) <= 1, top
