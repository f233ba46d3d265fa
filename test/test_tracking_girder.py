"""Tracking acceptance on simulated girder campaigns of modal estimates (``tracking_tables``: the
simulator's truth per window, a hidden bilinear freezing knee, identification scatter, missed and
spurious modes, dropped channels, and an out-of-plane mode that a bending mode crosses as the deck
stiffens below freezing, MAC 0.56 at the sensors). The truth's own lateral and torsion modes (seen
by the off-centre sensors) lie among the vertical ones: each is a truth identity like any other.

Identities: over 8-day campaigns of nightly frost (frequencies up to 4-15 % above their median), >= 98 % of the windows
have every identified truth mode assigned to its identity (within 2 % of the true frequency).
Novelty: a 5 % loss of span 1's bending stiffness under a +-10 degC daily cycle with nightly frost
(the two training days contain freezing) raises an alarm within 12 windows; clean campaigns of the
same weather give on average <= 1 alarm episode per 8 days.

CI: 4 identity campaigns, 5 damaged and 5 clean; SHM_FULL=1: 10, 20 and 20 (the issue's sizes).
"""

from __future__ import annotations

import numpy as np
from conftest import full_size
from tracking_tables import LATERAL, girder_tables, identity_score

from shm_ros.core.tracking import TrackingConfig, track

N = 1152  # 8 days of 10-minute windows
IDENTITY_SEEDS = range(10) if full_size() else range(4)
NOVELTY_SEEDS = range(100, 120) if full_size() else range(100, 105)
DAMAGE_AT = int(0.6 * N)
FROST = {"t_mean_c": 4.0, "t_daily_c": 10.0, "below_per_c": -0.02}


def test_identities_survive_freezing_and_a_crossing():
    """Every seed >= 98 % (the issue's criterion per campaign), out-of-plane truth modes included;
    the crossing really happens."""
    scores = []
    for seed in IDENTITY_SEEDS:
        camp = girder_tables(seed, N, **FROST)
        res = track(camp.estimates, TrackingConfig())
        score, owner = identity_score(camp, res)
        scores.append(score)
        # all truth modes, the out-of-plane one included, have an identity of their own
        assert sorted(owner) == sorted(camp.identities) and len(set(owner.values())) == len(owner), owner
        # the truth's modes ascend in frequency, out-of-plane ones among them: the crossing is with
        # vertical bending mode 2, found by family
        bend, lat = camp.truth_f[:, camp.columns("vertical")[1]], camp.truth_f[:, camp.identities.index(LATERAL)]
        assert (bend > lat).any() and (bend < lat).any()  # the frequencies cross
        rise = camp.truth_f.max(axis=0) / np.median(camp.truth_f, axis=0) - 1
        assert 0.04 <= rise[:-1].max() <= 0.15, rise
    print("identity scores", np.round(scores, 4))
    assert min(scores) >= 0.98, scores


def test_damage_after_frost_is_detected_and_frost_is_not_novelty():
    """Detection: the issue asks >= 17 of 20 seeds. If the true rate were only 0.95, 5 of 5 CI
    seeds would fail with probability 1 - 0.95^5 = 23 %, so CI asks >= 4 of 5 (fails with 2.3 %);
    the full run asks 17 of 20. False alarms: mean episodes per clean 8-day campaign <= 1 (full: 20
    campaigns); CI (5 campaigns) allows 1.6: for Poisson counts with mean 1 per campaign, a sum of
    more than 8 over 5 campaigns has probability 6.8 %, and at the full run's measured rate (see
    docs/tracking.md) far less."""
    detected, delays, episodes, outside = 0, [], [], 0
    for seed in NOVELTY_SEEDS:
        camp = girder_tables(seed, N, damage_at=DAMAGE_AT, **FROST)
        train = camp.temperature_c[: N // 4]
        assert train.min() < -1.0, "the training period must contain a freezing spell"
        res = track(camp.estimates, TrackingConfig())
        hit = np.flatnonzero(res.novelty_alarm[DAMAGE_AT:DAMAGE_AT + 13])
        if hit.size:
            detected += 1
            delays.append(int(hit[0]))
            assert res.alarm_modes[DAMAGE_AT + hit[0]], "an alarm names its modes"
        clean = track(girder_tables(seed, N, **FROST).estimates, TrackingConfig())
        episodes.append(len(clean.episodes))
        outside += sum(bool(clean.outside_training[a:b + 1].any()) for a, b in clean.episodes)
    n = len(NOVELTY_SEEDS)
    msg = f"detected {detected}/{n}, delays {delays}, clean episodes {episodes} ({outside} outside training)"
    print(msg)
    assert detected >= (17 if full_size() else 4), msg
    assert np.mean(episodes) <= (1.0 if full_size() else 1.6), msg
