"""Cheap modal-estimate campaigns for the tracking tests: the simulator's girder truth per window
(``shm_ros.core.simulate``: its finer truth model, hidden bilinear freezing knee, damage) without
simulating responses, plus what identification does to it (frequency and shape scatter, missed
modes, spurious modes, dropped channels), plus one synthetic out-of-plane mode whose frequency hardly
moves with temperature, so that vertical bending mode 2 crosses it as the deck stiffens below freezing
(their MAC at the sensors is about 0.56: neither frequency order nor a loose shape test tells them
apart). Identities are the truth's, followed by MAC continuity of the truth's full shapes over a
grid of deck-stiffness factors (the grid also makes the campaign cheap: modal truth is interpolated
between grid nodes, not solved per window). The truth's modes are of every family it has (with
``model_form``, the default, the girder's lateral and torsion modes lie among the vertical ones):
``TableCampaign.families`` says which is which, ``TableCampaign.columns`` picks one family.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shm_ros.core.modal import mac
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.simulate.scenario import EffectRequest
from shm_ros.core.types import ModalEstimate, Mode

LATERAL = -1  # identity of the synthetic out-of-plane mode (the truth's modes: 0, 1, ..., every family)


@dataclass
class TableCampaign:
    estimates: list[ModalEstimate]
    truth_ids: list[list[int]]  # per window, the truth identity of each reported mode (None = spurious)
    truth_f: np.ndarray  # (n_windows, n_truth) true frequencies by identity (last column: the synthetic mode)
    temperature_c: np.ndarray
    damage_window: int | None
    identities: list[int]  # identity of each truth_f column
    families: list[str]  # the truth's mode family of each truth_f column ("vertical", "lateral", "torsion")

    def columns(self, family: str) -> list[int]:
        """The truth_f columns of one mode family, ascending frequency at the first window."""
        cols = [k for k, f in enumerate(self.families) if f == family]
        return sorted(cols, key=lambda k: self.truth_f[0, k])


def _grid_truth(campaign, others: dict[str, float], lo: float, hi: float, n: int = 41):
    """Modal truth on a grid of the deck factor, columns ordered by identity (MAC continuity)."""
    grid = np.linspace(lo, hi, n)
    freqs, shapes, fams = [], [], []
    prev = None
    for g in grid:
        _, modal = campaign.truth_model.system({**others, "EI": float(g)})
        f, s = np.asarray(modal.frequencies_hz), np.asarray(modal.shapes).T  # (modes, sensors)
        fam = np.asarray(list(modal.families) or ["vertical"] * f.size, dtype=object)
        if prev is not None:  # keep identities: each column follows its most similar previous shape
            m = mac(prev[:, None, :], s[None, :, :])
            order = np.argmax(m, axis=1)
            if len(set(order.tolist())) == order.size:
                f, s, fam = f[order], s[order], fam[order]
        s = s * np.sign(np.sum(s * (prev if prev is not None else s), axis=1, keepdims=True) + 1e-30)
        freqs.append(f)
        shapes.append(s)
        fams.append(fam)
        prev = s
    return grid, np.array(freqs), np.array(shapes), [str(f) for f in fams[0]]


def girder_tables(seed: int, n_windows: int = 1152, *, t_mean_c: float = 5.0, t_daily_c: float = 6.0,
                  damage_at: int | None = None, damage_factor: float = 0.95, crossing: bool = True,
                  lateral_hz: float = 7.9, missing: float = 0.07, spurious: float = 1.0,
                  f_scatter: float = 0.002, below_per_c: float = -0.05) -> TableCampaign:
    sc = named_scenario("girder", n_windows=n_windows, seed=seed)
    sc.t_mean_c, sc.t_daily_c = t_mean_c, t_daily_c
    sc.temperature_period_s = 600.0
    sc.effects = [EffectRequest("temperature_bilinear", {"below_per_c": below_per_c})]
    if damage_at is not None:
        sc.effects.append(EffectRequest("damage", {"at": f"{damage_at * sc.interval_s + 1}s",
                                                   "factor": damage_factor, "where": "span1"}))
    c = simulate_campaign(sc)
    factors: list[dict[str, float]] = [c.factors(i) for i in range(n_windows)]
    deck = np.array([fac.get("EI", 1.0) for fac in factors])
    lo, hi = deck.min() * 0.999, deck.max() * 1.001
    grids = {}
    for fac in factors:
        key = tuple(sorted((k, v) for k, v in fac.items() if k != "EI"))
        if key not in grids:
            grids[key] = _grid_truth(c, dict(key), lo, hi)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(77,)))
    sensors = c.sensor_ids
    x = np.linspace(0.05, 0.95, len(sensors))
    temp = np.array([c.conditions(i).temperature_c for i in range(n_windows)])
    measured = np.array([c.measured_temperature(i) for i in range(n_windows)], float)
    estimates, ids_all, truth_rows = [], [], []
    lat_shape = None
    for i in range(n_windows):
        key = tuple(sorted((k, v) for k, v in factors[i].items() if k != "EI"))
        grid, gf, gs, fams = grids[key]
        j = int(np.clip(np.searchsorted(grid, deck[i]) - 1, 0, grid.size - 2))
        w = (deck[i] - grid[j]) / (grid[j + 1] - grid[j])
        f: np.ndarray = (1 - w) * gf[j] + w * gf[j + 1]
        s: np.ndarray = (1 - w) * gs[j] + w * gs[j + 1]
        damp = np.full(f.size, 0.015)
        if crossing:
            if lat_shape is None:  # MAC 0.56 with vertical mode 2 at the sensors
                v2 = [k for k in np.argsort(gf[0]) if fams[k] == "vertical"][1]
                v = gs[0, v2] / np.linalg.norm(gs[0, v2])
                o = np.sin(1.5 * np.pi * x) + 0.5 * np.cos(3.3 * np.pi * x)
                o = o - (o @ v) * v
                lat_shape = 0.75 * v + 0.66 * o / np.linalg.norm(o)
                lat_shape /= np.abs(lat_shape).max()
            f = np.append(f, lateral_hz * (1 + 0.0004 * (temp[i] - 5.0)))
            s = np.vstack([s, lat_shape])
            damp = np.append(damp, 0.01)
        truth_rows.append(f)
        modes: list[Mode] = []
        ids: list[int | None] = []
        cols = [k for k in range(len(sensors)) if rng.uniform() > 0.03]
        for k in range(f.size):
            if rng.uniform() < missing:
                continue
            phi = s[k, cols] / np.abs(s[k, cols]).max() + rng.normal(0, 0.03, len(cols))
            phi = phi / np.abs(phi).max() * rng.choice([-1, 1])
            modes.append(Mode(float(f[k] * (1 + rng.normal(0, f_scatter))),
                              float(damp[k] * np.exp(rng.normal(0, 0.25))), phi))
            ids.append(k if (not crossing or k < f.size - 1) else LATERAL)
        for _ in range(rng.poisson(spurious)):
            phi = rng.normal(size=len(cols))
            modes.append(Mode(float(rng.uniform(3.0, 30.0)), 0.02, phi / np.abs(phi).max()))
            ids.append(None)
        order = np.argsort([m.frequency_hz for m in modes])
        start = int(c.window_starts_ns[i])
        estimates.append(ModalEstimate(f"w{i:05d}", start, start + int(600e9), [sensors[k] for k in cols],
                                       [modes[o] for o in order], temperature_c=float(measured[i]),
                                       covariates={"rms_accel_m_s2": float(np.exp(rng.normal(-4, 0.5)))}))
        ids_all.append([ids[o] for o in order])
    n_v = len(truth_rows[0]) - (1 if crossing else 0)
    identities = list(range(n_v)) + ([LATERAL] if crossing else [])
    families = list(grids[next(iter(grids))][3]) + (["lateral"] if crossing else [])
    return TableCampaign(estimates, ids_all, np.array(truth_rows), temp, damage_at, identities, families)


def identity_score(camp: TableCampaign, res) -> tuple[float, dict[int, int]]:
    """Fraction of windows in which every identified truth mode is assigned to its identity's
    tracked mode, within 2 % of the true frequency; and the identity -> tracked-mode-index map
    (each tracked mode's majority identity)."""
    fr = res.observations.frequencies_hz
    votes: dict[int, dict[int, int]] = {}
    for w, (e, ids) in enumerate(zip(camp.estimates, camp.truth_ids, strict=True)):
        for m, ident in zip(e.modes, ids, strict=True):
            if ident is None:
                continue
            got = np.flatnonzero(fr[w] == m.frequency_hz)
            if got.size:
                votes.setdefault(ident, {}).setdefault(int(got[0]), 0)
                votes[ident][int(got[0])] += 1
    owner = {ident: max(v.items(), key=lambda kv: kv[1])[0] for ident, v in votes.items()}
    good = 0
    for w, (e, ids) in enumerate(zip(camp.estimates, camp.truth_ids, strict=True)):
        ok = True
        for m, ident in zip(e.modes, ids, strict=True):
            if ident is None:
                continue
            col = camp.identities.index(ident)
            k = owner.get(ident)
            if k is None or fr[w, k] != m.frequency_hz or abs(m.frequency_hz / camp.truth_f[w, col] - 1) > 0.02:
                ok = False
                break
        good += ok
    return good / len(camp.estimates), owner
