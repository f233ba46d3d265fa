"""Where identities come from and what has no covariate: the reference seeded from the FE model,
an event catalogue (20 earthquakes years apart: no 24-window minimum), modes born later, damping
in the chart, and the PCA environment when no covariate is measured."""

from __future__ import annotations

import numpy as np
from test_tracking_core import F0, SENSORS, _campaign, _shapes
from tracking_tables import girder_tables, identity_score

from shm_ros.core.simulate.scenario import GIRDER_STRUCTURE
from shm_ros.core.structure import structure_from_dict
from shm_ros.core.tracking import TrackingConfig, track
from shm_ros.core.types import ModalEstimate, Mode


def test_reference_seeded_from_the_fe_model():
    """The nominal structure file's FE modes name the tracked modes: with ``both`` the data fix the
    frequencies (the FE model is a few % off the truth) and every identity holds; with ``model``
    alone the identities start from the FE frequencies and shapes. The planar FE model knows only
    the girder's vertical modes: it seeds those, and the truth's lateral and torsion modes (seen by
    the off-centre sensors) are tracked modes of their own, named by the data."""
    spec = structure_from_dict(GIRDER_STRUCTURE)
    camp = girder_tables(3, 300, crossing=False)
    vertical = camp.columns("vertical")[:4]
    other = [k for k, f in enumerate(camp.families) if f != "vertical"]
    assert other, "the truth has out-of-plane modes"
    both = track(camp.estimates, TrackingConfig(reference_source="both"), structure=spec)
    assert [r.source for r in both.reference[:4]] == ["both"] * 4
    score, owner = identity_score(camp, both)
    assert score >= 0.98 and [owner[camp.identities[j]] for j in vertical] == [0, 1, 2, 3], (score, owner)
    # every truth mode has a tracked mode of its own; the out-of-plane ones come from the windows
    assert sorted(owner) == sorted(camp.identities) and len(set(owner.values())) == len(owner), owner
    assert all(both.reference[owner[camp.identities[j]]].source == "windows" for j in other), owner
    alone = track(camp.estimates, TrackingConfig(reference_source="model"), structure=spec)
    found = np.isfinite(alone.observations.frequencies_hz[:, :4]).mean(axis=0)
    assert found.min() >= 0.9, found  # the four lowest FE modes are tracked in (nearly) every window
    fr = alone.observations.frequencies_hz[:, :4]
    truth = camp.truth_f[:, vertical]
    assert np.nanmax(np.abs(fr / truth - 1)) < 0.02  # ... each as its own truth mode
    # the out-of-plane modes are born from the data, each as a tracked mode of its own
    _, owner = identity_score(camp, alone)
    assert sorted(owner) == sorted(camp.identities) and len(set(owner.values())) == len(owner), owner
    assert all(alone.reference[owner[camp.identities[j]]].source == "born" for j in other), owner


def test_event_catalogue_of_twenty_earthquakes_years_apart():
    """20 windows, one per earthquake over 19 years: amplitude softening of up to 6 % and the
    season move the frequencies; every mode found keeps its identity."""
    rng = np.random.default_rng(4)
    shapes = _shapes()
    est, truth = [], []
    year = int(365.25 * 86400e9)
    for w in range(20):
        pga = rng.uniform(0.2, 3.0)
        temp = rng.uniform(-5, 25)
        f = F0 * (1 - 0.02 * pga) * (1 - 0.003 * (temp - 10)) * (1 + rng.normal(0, 0.002, F0.size))
        keep = rng.uniform(size=F0.size) > 0.1
        modes = [Mode(float(f[k]), 0.03, shapes[k] + rng.normal(0, 0.03, len(SENSORS))) for k in np.flatnonzero(keep)]
        est.append(ModalEstimate(f"eq{w}", w * year, w * year + int(120e9), SENSORS, modes, temperature_c=temp,
                                 covariates={"pga_m_s2": pga}))
        truth.append(list(np.flatnonzero(keep)))
    res = track(est, TrackingConfig())
    assert res.observations.n_windows == 20 and res.observations.mode_numbers == [1, 2, 3, 4, 5]
    fr = res.observations.frequencies_hz
    for w, ks in enumerate(truth):
        assert sorted(np.flatnonzero(np.isfinite(fr[w])).tolist()) == sorted(int(k) for k in ks), w
    assert any("training windows" in n for n in res.notes)  # too few for a novelty threshold: said so
    assert not res.novelty_alarm.any()


def test_a_mode_appears_later_and_lost_modes_leave_gaps():
    est, _, _ = _campaign(13, n=400, damage_at=2.0)
    x = np.linspace(0.1, 1.0, len(SENSORS))
    new_shape = np.cos(2.2 * np.pi * x)
    rng = np.random.default_rng(0)
    for e in est[200:]:  # e.g. a bearing that seized: a new mode near 9.5 Hz
        cols = [SENSORS.index(s) for s in e.sensor_ids]
        phi = new_shape[cols] + rng.normal(0, 0.02, len(cols))
        e.modes = sorted([*e.modes, Mode(9.5 * (1 + rng.normal(0, 0.002)), 0.02, phi / np.abs(phi).max())],
                         key=lambda m: m.frequency_hz)
    for e in est[250:300]:  # mode 2 is lost for a while
        e.modes = [m for m in e.modes if abs(m.frequency_hz / F0[1] - 1) > 0.03]
    res = track(est, TrackingConfig())
    born = [r for r in res.reference if r.source == "born"]
    assert len(born) == 1 and born[0].number == 6 and abs(born[0].frequency_hz - 9.5) < 0.1
    col = res.observations.mode_numbers.index(6)
    fr = res.observations.frequencies_hz
    assert np.isnan(fr[:200, col]).all() and np.isfinite(fr[240:, col]).mean() > 0.9
    assert np.isnan(fr[250:300, 1]).all() and np.isfinite(fr[300:, 1]).mean() > 0.85
    assert res.observations.damping is not None and np.isfinite(res.observations.damping[240:, col]).mean() > 0.9


def test_pca_environment_without_covariates_and_damping_in_the_chart():
    """No temperature measured: the PCA model takes the common temperature movement out; a 2 %
    stiffness loss of modes 1-2 (a pattern the environment does not produce) still alarms, and the
    clean part stays quiet. Damping in the chart changes neither."""
    for damping in (False, True):
        est, _, _ = _campaign(14, n=1152, damage_at=0.75, damage=0.02)
        for e in est:
            e.temperature_c = None
        res = track(est, TrackingConfig(novelty_damping=damping))
        assert any(n.startswith("no covariate") for n in res.notes)
        cut = int(0.75 * 1152)
        normal = res.novelty_alarm[res.n_training:cut]
        assert normal.mean() <= 0.01, normal.mean()
        assert res.novelty_alarm[cut:cut + 12].any() and res.novelty_alarm[cut + 12:].mean() > 0.8
        raw = res.observations.frequencies_hz[res.n_training:cut, 0]
        norm = res.normalised_hz[res.n_training:cut, 0]
        assert np.nanstd(norm) < 0.5 * np.nanstd(raw)
