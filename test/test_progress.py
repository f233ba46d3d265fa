"""Progress lines of long work: bar, count, elapsed time and ETA; rate-limited."""

from __future__ import annotations

import io

from shm_ros.core.progress import Progress


def test_line_has_count_and_eta_from_the_rate_so_far():
    p = Progress("windows", width=10)
    assert p.line(0, 4, 0.0) == "windows [          ] 0/4  0 s, ETA -"
    assert p.line(1, 4, 10.0) == "windows [##        ] 1/4  10 s, ETA 30 s"
    assert p.line(4, 4, 40.0) == "windows [##########] 4/4  40 s, done"


def test_updates_are_rate_limited_but_first_and_last_always_print():
    out = io.StringIO()
    p = Progress("x", stream=out, every_s=3600.0)
    for k in range(1, 101):
        p(k, 100)
    lines = out.getvalue().splitlines()
    assert len(lines) == 2 and lines[0].startswith("x [") and " 1/100 " in lines[0] and "100/100" in lines[1]


def test_a_count_is_shown_once():
    out = io.StringIO()
    p = Progress("x", stream=out, every_s=0.0)
    for _ in range(5):
        p(3, 3)
    assert len(out.getvalue().splitlines()) == 1


def test_sampler_progress_reports_and_leaves_the_draws_unchanged():
    """emcee and MH report (steps done, steps planned) while sampling; the draws are the same as
    without a progress callback."""
    import numpy as np

    from shm_ros.core.bayes.samplers import SamplerSettings, run_emcee, run_mh

    def log_prob(x):
        return -0.5 * np.sum(np.atleast_2d(x) ** 2, axis=1)

    for run in (run_emcee, run_mh):
        calls = []
        base = dict(n_steps=200, max_steps=200, rhat_target=2.0, ess_target=10.0, seed=4)
        quiet = run(log_prob, np.zeros(2), np.eye(2), SamplerSettings(**base), ["a", "b"])
        loud = run(log_prob, np.zeros(2), np.eye(2),
                   SamplerSettings(**base, progress=lambda d, t: calls.append((d, t))), ["a", "b"])
        np.testing.assert_array_equal(quiet.chains, loud.chains)
        assert calls and calls[-1][0] == calls[-1][1] and all(0 < d <= t for d, t in calls), (run, calls)
