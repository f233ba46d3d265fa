"""Random test cases for explain: a tracked-modes table whose truth lies outside the analysis model's
class, with one missing physics effect (or none) drawn at random, without simulating signals.

Per window the truth's modal properties come from the simulator's truth model
(``shm_ros.core.simulate``: the named ``girder`` or ``building`` scenario with its default model-form
error: finer scattered truth, Timoshenko deck / plan eccentricity, out-of-plane mode families) at the
window's effect factors, interpolated over a grid of factors (as ``test/tracking_tables.py`` does) so
that a case costs well under a second. Identification scatter is then drawn per window: frequency
0.2-0.5 % per mode, damping 10-20 % (relative, log-normal), shapes 2 % of the unit-max shape, and
3 % of the entries missing (a tracker misses a mode now and then).

The table holds the in-plane modes and the lowest out-of-plane modes the sensors see (the girder's
torsion and lateral modes, the building's y sway and torsion), numbered by ascending frequency as a
tracker would number them; only the ``clean`` case keeps the in-plane modes alone.

Effects and their ranges (the size is what the truth does, measured on the noise-free truth; the
generator rescales the effect until it holds):

==================================  =====================================================================
temperature_dependent_stiffness     girder EI / EI:k, building EI; linear or bilinear (knee inside the
                                    campaign's temperatures); peak-to-peak frequency change 2-6 %
amplitude_dependent_stiffness       EI x 1 / (1 + a / a_ref), a = the window's RMS acceleration (traffic
                                    by the hour, occasional storms); peak-to-peak 2-5 %
amplitude_dependent_damping         damping x (1 + a / a_ref); damping rises 40-120 % peak-to-peak
added_mass                          one span / floor (mass:k) or the whole deck / every floor (mass),
                                    3-10 % of that mass, intermittent (rush hours, below a temperature,
                                    after a time)
support_flexibility                 soil springs under the bearings / a foundation on soil (the
                                    simulator's effect) whose stiffness changes: scour at a time (the
                                    most affected mode moves 1.5-5 %) or frozen ground below a knee
                                    temperature (2-5 % peak-to-peak); a constant soil spring alone is
                                    absorbed by the calibration within the model-form error
stiffness_change_at_time            EI:k or EI steps at a window in 30-75 % of the campaign, the most
                                    affected mode moves 1.5-5 %; on top of a mild linear temperature
                                    dependence of the deck (-0.1 to -0.3 %/degC of stiffness)
damper_stiffness                    building with damper braces on some stories (the file lists their
                                    dashpots, not the braces' stiffness); the braces' stiffness follows
                                    the temperature (viscoelastic) or drops at a time; 2-5 % / >= 1.5 %
unmodelled_modes                    no effect: only the model-form truth's out-of-plane modes
clean                               no effect, in-plane modes only
==================================  =====================================================================
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shm_ros.core.observations import ModalObservations
from shm_ros.core.simulate import named_scenario, simulate_campaign
from shm_ros.core.simulate.excitation import traffic_profile
from shm_ros.core.simulate.scenario import EffectRequest

EFFECTS = ("clean", "temperature_dependent_stiffness", "amplitude_dependent_stiffness",
           "amplitude_dependent_damping", "added_mass", "support_flexibility", "stiffness_change_at_time",
           "damper_stiffness", "unmodelled_modes")
N_IN_PLANE = {"girder": 5, "building": 4}
N_OUT_OF_PLANE = 3
MIN_COVARIATE_PTP = 0.02  # peak-to-peak frequency change of covariate effects
MIN_STEP = 0.015
MIN_MASS_FRACTION = 0.03
GRID = 13
MISSING = 0.03


@dataclass
class CaseTruth:
    name: str  # vocabulary name, "clean" or "unmodelled_modes"
    where: str  # parameter group (groups.py names) or "" for none
    parameters: dict[str, Any] = field(default_factory=dict)
    size: float = 0.0  # peak-to-peak (or step) relative change of the most affected in-plane mode
    out_of_plane_modes: list[int] = field(default_factory=list)  # tracked mode numbers
    in_plane_modes: list[int] = field(default_factory=list)
    change_index: int | None = None  # first window after a step / the start of an "after" window
    knee_c: float | None = None
    second: CaseTruth | None = None  # a second effect (``draw_case(..., second_step=True)``)


@dataclass
class Case:
    kind: str  # "girder" | "building"
    seed: int
    obs: ModalObservations
    structure: dict[str, Any]  # the nominal structure file (with ``parameters:``)
    truth: CaseTruth
    f_true: np.ndarray  # (W, K) noise-free truth frequencies of the table's columns
    start_epoch_s: float  # POSIX time of the first window's middle (obs.times are POSIX seconds)
    factors: list[dict[str, float]]  # per window, the truth's group factors
    z_true: np.ndarray | None = None  # (W, K) noise-free truth damping ratios of the table's columns


def draw_case(seed: int, effect: str | None = None, kind: str | None = None, n_windows: int = 864,
              form: str | None = None, second_step: bool = False) -> Case:
    """One random case (``effect``/``kind`` drawn when not given; damper_stiffness is a building).

    ``form`` fixes a temperature effect's form (linear / bilinear); ``second_step`` adds, after the
    drawn effect, a stiffness loss of one span / story (or all) at a window in the last 40 % of the
    campaign, moving the most affected in-plane mode by 1.5-4 % (``truth.second``)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(4242,)))
    effect = effect or str(rng.choice(EFFECTS))
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r} (known: {', '.join(EFFECTS)})")
    if kind is None:  # a building's foundation sway is not a candidate yet (docs/explain.md): girder soil only
        kind = ("building" if effect == "damper_stiffness" else "girder" if effect == "support_flexibility"
                else str(rng.choice(["girder", "building"])))
    if effect == "damper_stiffness" and kind != "building":
        raise ValueError("damper_stiffness needs the building")
    sc = named_scenario(kind, n_windows=n_windows, seed=seed, temperature_period_s=600.0)
    structure = copy.deepcopy(sc.structure)
    n_units = len(structure["girder"]["spans"]) if kind == "girder" else len(structure["shear_building"]["floors"])
    truth = CaseTruth(effect, "")
    requests: list[EffectRequest] = []
    if effect == "support_flexibility":
        if kind == "girder":
            requests.append(EffectRequest("support_flexibility", {"k_soil_n_m": float(rng.uniform(4e9, 2e10))}))
            truth.where = "bearings"
        else:
            requests.append(EffectRequest("support_flexibility", {"k_soil_rel": float(rng.uniform(1.5, 4.0))}))
            truth.where = "foundation"
        truth.parameters = dict(requests[0].params)
    stories: list[int] = []
    if effect == "damper_stiffness":
        lo = int(rng.integers(1, n_units // 2 + 1))
        stories = list(range(lo, min(n_units, lo + int(rng.integers(2, 5))) + 1))
        k_rel = float(rng.uniform(0.15, 0.4))
        requests.append(EffectRequest("damper", {"k_rel": k_rel, "c_rel_s": 0.02,
                                                 "stories": "+".join(str(s) for s in stories)}))
        floors = structure["shear_building"]["floors"]
        structure["shear_building"]["dampers"] = [
            {"between": [s - 1, s], "c": 0.02 * k_rel * float(floors[s - 1]["stiffness"])} for s in stories]
        truth.where = "damper"
        truth.parameters = {"k_rel": k_rel, "stories": stories}
    sc.effects = requests
    camp = simulate_campaign(sc)
    tm = camp.truth_model
    if kind == "girder":  # one span's mass (the simulator's added mass is the whole deck's)
        names = tm.model.parameter_names
        for k in range(n_units):
            tm.groups[f"mass:{k + 1}"] = [names.index(f"span{k + 1}_mass")]
    else:
        names = tm.model.parameter_names
        shift = tm.info["floor_shift"]
        for k in range(n_units):
            tm.groups[f"mass:{k + 1}"] = [names.index(f"floor{k + 1 + shift}_mass")]
        if shift:  # the foundation's soil spring is the truth's story 1
            tm.groups["foundation"] = [names.index("story1")]
    W = n_windows
    cond = [camp.conditions(i) for i in range(W)]
    temp_true = np.array([c.temperature_c for c in cond])
    hour = np.array([c.local_hour for c in cond])
    t_s = np.array([c.t_s for c in cond])
    temp_meas = np.array([camp.measured_temperature(i) for i in range(W)], float)
    rms, pga = _amplitudes(rng, kind, hour, W)

    # -- reference modes: identities (family, rank) of the table's columns --------------------
    _, modal0 = tm.system({})
    ip_fam = modal0.in_plane_family
    fam0 = list(modal0.families)
    oop = [(f, r) for f, r in _ids(fam0) if f != ip_fam][:N_OUT_OF_PLANE]
    ip = [(ip_fam, r) for r in range(N_IN_PLANE[kind])]
    keep_ids = ip + ([] if effect == "clean" else oop)

    def solve(fac: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, m = tm.system(fac)
        ids = _ids(list(m.families))
        cols = [ids.index(i) for i in keep_ids]
        return m.frequencies_hz[cols], m.damping_ratios[cols], m.shapes[:, cols].T

    # -- per-window factors of the drawn effect, scaled to its stated size ---------------------
    size_target = 0.0
    damp_factor = np.ones(W)

    base_factors = [camp.factors(i) for i in range(W)]

    def factors_for(scale: float) -> list[dict[str, float]]:
        if effect in ("clean", "unmodelled_modes", "amplitude_dependent_damping"):
            return [dict(f) for f in base_factors]
        return _effect_factors(scale)

    spec: dict[str, Any] = {}
    if effect == "temperature_dependent_stiffness":
        group = "EI" if (kind == "building" or rng.uniform() < 0.7) else f"EI:{int(rng.integers(1, n_units + 1))}"
        form = form or str(rng.choice(["linear", "bilinear"]))
        spec = {"group": group, "form": form}
        if form == "bilinear":
            knee = float(np.quantile(temp_true, rng.uniform(0.3, 0.6)))
            spec.update(knee_c=knee, above_ratio=float(rng.uniform(0.0, 0.3)))
            truth.knee_c = knee
        size_target = float(rng.uniform(1.15 * MIN_COVARIATE_PTP, 0.06))
    elif effect == "amplitude_dependent_stiffness":
        spec = {"group": "EI"}
        size_target = float(rng.uniform(1.15 * MIN_COVARIATE_PTP, 0.05))
    elif effect == "added_mass":
        one = rng.uniform() < 0.6
        group = f"mass:{int(rng.integers(1, n_units + 1))}" if one else "mass"
        when = str(rng.choice(["rush_hours", "below", "after"]))
        spec = {"group": group, "when": when, "fraction": float(rng.uniform(MIN_MASS_FRACTION, 0.10))}
        if one and kind == "building":
            spec["fraction"] = float(rng.uniform(0.08, 0.25))  # one floor among eight: a heavier share
        if when == "below":
            spec["below_c"] = float(np.quantile(temp_true, rng.uniform(0.2, 0.4)))
        if when == "after":
            spec["at_index"] = int(rng.integers(int(0.3 * W), int(0.7 * W)))
            truth.change_index = spec["at_index"]
    elif effect == "stiffness_change_at_time":
        group = (f"EI:{int(rng.integers(1, n_units + 1))}" if rng.uniform() < 0.7 else "EI")
        at = int(rng.integers(int(0.3 * W), int(0.75 * W)))
        spec = {"group": group, "at_index": at, "alpha_per_c": float(-rng.uniform(0.001, 0.003)),
                "t_ref_c": float(np.mean(temp_true)), "direction": float(rng.choice([-1.0, 1.0], p=[0.75, 0.25]))}
        truth.change_index = at
        size_target = float(rng.uniform(1.15 * MIN_STEP, 0.05))
    elif effect == "damper_stiffness":
        mode = str(rng.choice(["temperature", "failure"]))
        spec = {"group": "damper", "mode": mode}
        if mode == "failure":
            spec["at_index"] = int(rng.integers(int(0.3 * W), int(0.75 * W)))
            truth.change_index = spec["at_index"]
            size_target = float(rng.uniform(1.15 * MIN_STEP, 0.05))
        else:
            spec["t_ref_c"] = float(np.mean(temp_true))
            size_target = float(rng.uniform(1.15 * MIN_COVARIATE_PTP, 0.05))
    elif effect == "support_flexibility":  # the soil's stiffness changes: scour at a time, or frost
        mode = str(rng.choice(["scour", "frozen"]))
        spec = {"group": truth.where, "mode": mode, **truth.parameters}
        if mode == "scour":
            spec.update(at_index=int(rng.integers(int(0.3 * W), int(0.75 * W))), direction=-1.0)
            truth.change_index = spec["at_index"]
            size_target = float(rng.uniform(1.15 * MIN_STEP, 0.05))
        else:
            spec["knee_c"] = float(np.quantile(temp_true, rng.uniform(0.3, 0.6)))
            truth.knee_c = spec["knee_c"]
            size_target = float(rng.uniform(1.15 * MIN_COVARIATE_PTP, 0.05))
    elif effect == "amplitude_dependent_damping":
        spec = {"rise": float(rng.uniform(0.4, 1.2))}
        a_lo, a_hi = np.quantile(rms, [0.01, 0.99])
        a_ref = (a_hi - a_lo) / spec["rise"]
        damp_factor = 1.0 + rms / a_ref
        truth.parameters = {"accel_ref_m_s2": float(a_ref), "rise": spec["rise"]}

    def _effect_factors(scale: float) -> list[dict[str, float]]:
        out = []
        for i in range(W):
            f = dict(base_factors[i])
            g = spec.get("group", "")
            if effect == "temperature_dependent_stiffness":
                dt = temp_true[i] - spec.get("knee_c", float(np.mean(temp_true)))
                if spec["form"] == "linear":
                    v = 1.0 - scale * dt
                else:  # stiffer below the knee (freezing), a little softer above
                    v = 1.0 - scale * (spec["above_ratio"] * dt + min(dt, 0.0))
                f[g] = f.get(g, 1.0) * max(v, 0.2)
            elif effect == "amplitude_dependent_stiffness":
                f[g] = f.get(g, 1.0) / (1.0 + rms[i] * scale)
            elif effect == "added_mass":
                on = {"rush_hours": any(a <= hour[i] < b for a, b in ((7.0, 9.5), (17.0, 19.5))),
                      "below": temp_true[i] < spec.get("below_c", 0.0),
                      "after": i >= spec.get("at_index", W)}[spec["when"]]
                if on:
                    f[g] = f.get(g, 1.0) * (1.0 + spec["fraction"])
            elif effect == "stiffness_change_at_time":
                f["EI"] = f.get("EI", 1.0) * (1.0 + spec["alpha_per_c"] * (temp_true[i] - spec["t_ref_c"]))
                if i >= spec["at_index"]:
                    f[g] = f.get(g, 1.0) * max(1.0 + spec["direction"] * scale, 0.2)
            elif effect == "support_flexibility":
                if spec["mode"] == "scour":
                    v = max(1.0 - scale, 0.05) if i >= spec["at_index"] else 1.0
                else:  # frozen ground stiffens below the knee
                    v = 1.0 + scale * max(spec["knee_c"] - temp_true[i], 0.0)
                f[g] = f.get(g, 1.0) * v
            elif effect == "damper_stiffness":
                if spec["mode"] == "failure":
                    f["damper"] = max(1.0 - scale, 0.0) if i >= spec["at_index"] else 1.0
                else:  # viscoelastic braces soften as they warm
                    f["damper"] = float(np.exp(-scale * (temp_true[i] - spec["t_ref_c"])))
            out.append(f)
        return out

    scale = 0.0
    if size_target > 0:
        scale = {"temperature_dependent_stiffness": size_target / max(np.ptp(temp_true), 1.0),
                 "amplitude_dependent_stiffness": 2 * size_target / max(np.ptp(rms), 1e-9),
                 "stiffness_change_at_time": 2 * size_target, "damper_stiffness": size_target,
                 "support_flexibility": size_target}[effect]
        if effect == "damper_stiffness" and spec["mode"] == "temperature":
            scale = size_target / max(np.ptp(temp_true), 1.0)
        if effect == "damper_stiffness" and spec["mode"] == "failure":
            scale = min(0.5, 4 * size_target)
        if effect == "support_flexibility":
            scale = (min(0.5, 4 * size_target) if spec["mode"] == "scour"
                     else 20 * size_target / max(np.ptp(temp_true), 1.0))
    factors = factors_for(scale)
    f_true, z_true, phi_true = _table_truth(solve, factors)
    n_ip = len(ip)
    def measure(f: np.ndarray) -> float:
        if truth.change_index is None or effect == "added_mass":
            return _ptp_size(f, None)
        # a step's own part: the truth with and without it at the same conditions
        g = spec["group"]
        v = (max(1.0 - scale, 0.0) if g == "damper" else max(1.0 - scale, 0.05) if g in ("bearings", "foundation")
             else max(1.0 + spec["direction"] * scale, 0.2))
        return float(np.max(np.abs(np.log(solve({g: v})[0][:n_ip] / solve({})[0][:n_ip]))))

    size = measure(f_true[:, :n_ip])
    for _ in range(2):  # rescale to the drawn size (the relation is close to linear in the scale)
        if size_target <= 0 or abs(size / size_target - 1.0) < 0.1:
            break
        scale *= size_target / max(size, 1e-6)
        if (effect == "damper_stiffness" and spec["mode"] == "failure") or spec.get("mode") == "scour":
            scale = min(scale, 0.95)
        factors = factors_for(scale)
        f_true, z_true, phi_true = _table_truth(solve, factors)
        size = measure(f_true[:, :n_ip])
    if second_step:  # a later stiffness loss on top of the drawn effect
        srng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(4244,)))
        g2 = f"EI:{int(srng.integers(1, n_units + 1))}" if srng.uniform() < 0.7 else "EI"
        at2 = int(srng.integers(int(0.6 * W), int(0.85 * W)))
        target2 = float(srng.uniform(1.15 * MIN_STEP, 0.04))
        f0 = solve({})[0][:n_ip]
        s2 = 2 * target2
        for _ in range(4):  # the loss's own size at the nominal conditions
            got = float(np.max(np.abs(np.log(solve({g2: 1.0 - s2})[0][:n_ip] / f0))))
            s2 = min(0.8, s2 * target2 / max(got, 1e-6))
        for i in range(at2, W):
            factors[i] = {**factors[i], g2: factors[i].get(g2, 1.0) * (1.0 - s2)}
        f_true, z_true, phi_true = _table_truth(solve, factors)
        truth.second = CaseTruth("stiffness_change_at_time", g2, {"scale": s2, "direction": -1.0}, size=target2,
                                 change_index=at2)
    if effect == "added_mass":
        size = _ptp_size(f_true[:, :n_ip], None)
    truth.size = float(size)
    if effect not in ("amplitude_dependent_damping", "clean", "unmodelled_modes"):
        truth.where = spec["group"]
        truth.parameters = {**truth.parameters, **{k: v for k, v in spec.items() if k != "group"}}
        truth.parameters["scale"] = float(scale)
    if effect == "amplitude_dependent_stiffness":
        truth.parameters["accel_ref_m_s2"] = float(1.0 / scale)
    if effect == "amplitude_dependent_damping":
        z_true = z_true * damp_factor[:, None]
        truth.where = "damping"
    if stories:
        truth.parameters["stories"] = stories

    # -- the tracked table: identification scatter, numbering by ascending frequency ----------
    nrng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(4243,)))
    K = f_true.shape[1]
    order = np.argsort(np.mean(f_true, axis=0))
    f_true, z_true, phi_true = f_true[:, order], z_true[:, order], phi_true[:, order]
    ident = [keep_ids[j] for j in order]
    f_sig = nrng.uniform(0.002, 0.005, K)
    z_sig = nrng.uniform(0.10, 0.20, K)
    f_obs = f_true * (1.0 + f_sig * nrng.standard_normal((W, K)))
    z_obs = z_true * np.exp(z_sig * nrng.standard_normal((W, K)))
    phi = phi_true + 0.02 * nrng.standard_normal(phi_true.shape)
    phi = phi / np.max(np.abs(phi), axis=2, keepdims=True)
    miss = nrng.uniform(size=(W, K)) < MISSING
    f_obs[miss], z_obs[miss] = np.nan, np.nan
    phi[miss] = np.nan
    numbers = list(range(1, K + 1))
    truth.in_plane_modes = [numbers[j] for j in range(K) if ident[j][0] == ip_fam]
    truth.out_of_plane_modes = [numbers[j] for j in range(K) if ident[j][0] != ip_fam]
    sensors = _table_sensors(tm, kind)
    rows = [tm.sensor_ids.index(s) for s in sensors]
    covs = {"temperature_c": temp_meas, "rms_accel_m_s2": rms}
    if kind == "building":
        covs["pga_m_s2"] = pga
    obs = ModalObservations(times=sc.start_epoch_s + t_s, mode_numbers=numbers, frequencies_hz=f_obs,
                            shapes=phi[:, :, rows], sensor_ids=sensors, damping=z_obs, covariates=covs,
                            time_kind="iso")
    return Case(kind=kind, seed=seed, obs=obs, structure=structure, truth=truth, f_true=f_true,
                start_epoch_s=float(sc.start_epoch_s + t_s[0]), factors=factors, z_true=z_true)


def _ids(families: list[str]) -> list[tuple[str, int]]:
    """(family, rank within the family) of each mode (ascending frequency)."""
    seen: dict[str, int] = {}
    out = []
    for f in families:
        out.append((f, seen.get(f, 0)))
        seen[f] = seen.get(f, 0) + 1
    return out


def _table_sensors(tm, kind: str) -> list[str]:
    """The nominal model's sensors (the building's ground sensor is its input, not a response)."""
    if kind == "building":
        return [s for s in tm.sensor_ids if s != "g0"]
    return list(tm.sensor_ids)


def _amplitudes(rng: np.random.Generator, kind: str, hour: np.ndarray, W: int) -> tuple[np.ndarray, np.ndarray]:
    """RMS acceleration per window: traffic by the hour (girder) or wind (building), log-normal
    scatter, a storm or two (a day-long lift of the wind part); PGA of rare small earthquakes."""
    base = 0.02 if kind == "girder" else 0.004
    profile = np.array([traffic_profile(h) for h in hour]) if kind == "girder" else np.ones(W)
    wind = np.ones(W)
    for _ in range(int(rng.integers(1, 3))):
        c, half = int(rng.integers(0, W)), int(rng.integers(40, 120))
        wind[max(0, c - half):c + half] += float(rng.uniform(1.5, 3.0))
    rms = base * (0.7 * profile + 0.3 * wind if kind == "girder" else wind) * np.exp(0.25 * rng.standard_normal(W))
    pga = np.zeros(W)
    quakes = rng.uniform(size=W) < 0.005
    pga[quakes] = rng.uniform(0.05, 0.5, int(quakes.sum()))
    rms = rms + 0.02 * pga
    return rms, pga


def _table_truth(solve, factors: list[dict[str, float]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth frequencies, damping, sensor shapes (W, K), (W, K), (W, K, S) over the windows' factors:
    exact at each distinct combination of the discrete groups, linear between grid nodes of the one
    group that varies continuously (the others are few-valued: steps, intermittent masses)."""
    W = len(factors)
    keys = sorted({k for f in factors for k in f})
    vals = {k: np.array([f.get(k, 1.0) for f in factors]) for k in keys}
    cont = [k for k in keys if np.unique(np.round(vals[k], 10)).size > 8]
    if len(cont) > 1:
        raise AssertionError(f"one continuously varying group expected, got {cont}")
    c = cont[0] if cont else None
    disc = [k for k in keys if k != c]
    combo = [tuple(round(float(vals[k][i]), 10) for k in disc) for i in range(W)]
    F = Z = P = None
    for key in sorted(set(combo)):
        idx = np.array([i for i in range(W) if combo[i] == key])
        base = dict(zip(disc, key, strict=True))
        if c is None:
            f, z, s = solve(base)
            fw, zw, sw = (np.repeat(a[None], idx.size, axis=0) for a in (f, z, s))
        else:
            x = vals[c][idx]
            grid = np.linspace(x.min(), x.max(), GRID) if np.ptp(x) > 0 else x[:1]
            sol = [solve({**base, c: float(g)}) for g in grid]
            gf, gz, gs = (np.array([s_[j] for s_ in sol]) for j in range(3))
            for m in range(1, len(grid)):  # keep each shape's sign along the grid
                sgn = np.sign(np.sum(gs[m] * gs[m - 1], axis=1) + 1e-30)
                gs[m] *= sgn[:, None]
            if grid.size == 1:
                fw, zw, sw = (np.repeat(a, idx.size, axis=0) for a in (gf, gz, gs))
            else:
                fw = np.column_stack([np.interp(x, grid, gf[:, k]) for k in range(gf.shape[1])])
                zw = np.column_stack([np.interp(x, grid, gz[:, k]) for k in range(gz.shape[1])])
                sw = np.stack([np.column_stack([np.interp(x, grid, gs[:, k, s]) for s in range(gs.shape[2])])
                               for k in range(gs.shape[1])], axis=1)
        if F is None:
            F, Z, P = np.zeros((W, fw.shape[1])), np.zeros((W, fw.shape[1])), np.zeros((W,) + sw.shape[1:])
        assert Z is not None and P is not None
        F[idx], Z[idx], P[idx] = fw, zw, sw
    assert F is not None and Z is not None and P is not None
    return F, Z, P


def _ptp_size(f: np.ndarray, _at: int | None) -> float:
    """Largest peak-to-peak relative change of a mode (1st-99th percentile, robust to one window)."""
    lf = np.log(f)
    return float(np.max(np.quantile(lf, 0.99, axis=0) - np.quantile(lf, 0.01, axis=0)))


# -- a baseline of the analysis model against a case (for locate's tests) ----------------------

def baseline_for(case: Case, n_model_modes: int = 12):
    """:class:`shm_ros.core.explain.types.Baseline` of the nominal model against ``case.obs``: the
    file's parameters at their MAP (per-mode misfit 2 % of model-form error, the file's priors) on
    the windows' median frequencies, tracked modes paired once by frequency and MAC
    (``gated_pairing``), residuals ``ln f_obs - ln f_model`` and each parameter group's modal
    sensitivities ``d ln f / d ln factor`` by central differences of the structure file."""
    from scipy.optimize import minimize

    from shm_ros.core.bayes.pairing import PairingGate, gated_pairing
    from shm_ros.core.explain.types import Baseline
    from shm_ros.core.models import build_model
    from shm_ros.core.structure import structure_from_dict

    obs = case.obs
    spec = structure_from_dict(copy.deepcopy(case.structure))
    model = build_model(spec)
    S = model.sensor_matrix(list(obs.sensor_ids))
    f_med = np.nanmedian(obs.frequencies_hz, axis=0)
    ref = obs.reference_shapes()
    sol = model.modes(None, n_model_modes)
    pairing = gated_pairing(f_med, ref, sol.frequencies_hz, S @ sol.shapes, PairingGate(0.2, 0.8), obs.mode_numbers)
    kk, jj = pairing.observed, pairing.model_index
    priors = [(p.name, 1.0, float(p.prior.params.get("std", 0.1))) for p in spec.parameters]

    def cost(x: np.ndarray) -> float:
        f = model.modes(np.exp(x), n_model_modes).frequencies_hz[jj]
        prior = np.sum((x / [max(s, 0.05) for _, _, s in priors]) ** 2)
        return float(np.sum((np.log(f_med[kk] / f) / 0.02) ** 2) + prior)

    x = minimize(cost, np.zeros(len(priors)), method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-3}).x
    theta = np.exp(x)
    f_model = model.modes(theta, n_model_modes).frequencies_hz[jj]
    resid = np.log(obs.frequencies_hz[:, kk]) - np.log(f_model)[None]
    sens = group_sensitivities(case.structure, theta, [p[0] for p in priors], jj, n_model_modes)
    return Baseline(mode_numbers=[obs.mode_numbers[k] for k in kk], model_index=[int(j) for j in jj],
                    log_residual=resid, f_model=f_model, sensitivities=sens,
                    theta={n: float(v) for (n, _, _), v in zip(priors, theta, strict=True)},
                    unpaired=[u.to_dict() for u in pairing.unmodelled])


def group_sensitivities(structure: dict[str, Any], theta: np.ndarray, names: list[str], jj: np.ndarray,
                        n_modes: int, h: float = 0.01) -> dict[str, np.ndarray]:
    """d ln f / d ln factor of the model modes ``jj`` for every parameter group (groups.py names),
    by central differences of the structure file at the calibrated parameters; groups that are 0 in
    the file (a foundation, damper braces) are differentiated at a reference value (their factor
    is then additive: x - 1 = value / reference)."""
    from shm_ros.core.models import build_model
    from shm_ros.core.structure import structure_from_dict

    base = copy.deepcopy(structure)
    for p, v in zip(base.get("parameters", []), theta, strict=False):  # bake the calibrated values in
        _scale_path(base, p["applies_to"], float(v))
    base.pop("parameters", None)

    def freqs(d: dict[str, Any]) -> np.ndarray:
        return build_model(structure_from_dict(copy.deepcopy(d)), include_parameters=False).modes(
            None, n_modes).frequencies_hz

    edits: dict[str, Any] = {}
    if base["kind"] == "girder":
        g = base["girder"]
        n = len(g["spans"])
        sec = g["section"]
        g["section"] = [dict(sec) for _ in range(n)] if isinstance(sec, dict) else sec
        edits["EI"] = lambda d, f: [s.update(E=s["E"] * f) for s in d["girder"]["section"]]
        edits["mass"] = lambda d, f: [s.update(rho=s["rho"] * f) for s in d["girder"]["section"]]
        for k in range(n):
            edits[f"EI:{k + 1}"] = lambda d, f, k=k: d["girder"]["section"][k].update(
                E=d["girder"]["section"][k]["E"] * f)
            edits[f"mass:{k + 1}"] = lambda d, f, k=k: d["girder"]["section"][k].update(
                rho=d["girder"]["section"][k]["rho"] * f)
        edits["bearings"] = lambda d, f: [b.update(k_vertical=b["k_vertical"] * f) for b in d["girder"]["bearings"]]
    else:
        fl = base["shear_building"]["floors"]
        edits["EI"] = lambda d, f: [x.update(stiffness=x["stiffness"] * f) for x in d["shear_building"]["floors"]]
        edits["mass"] = lambda d, f: [x.update(mass=x["mass"] * f) for x in d["shear_building"]["floors"]]
        for k in range(len(fl)):
            edits[f"EI:{k + 1}"] = lambda d, f, k=k: d["shear_building"]["floors"][k].update(
                stiffness=d["shear_building"]["floors"][k]["stiffness"] * f)
            edits[f"mass:{k + 1}"] = lambda d, f, k=k: d["shear_building"]["floors"][k].update(
                mass=d["shear_building"]["floors"][k]["mass"] * f)
    out: dict[str, np.ndarray] = {}
    for gname, edit in edits.items():
        lo, hi = copy.deepcopy(base), copy.deepcopy(base)
        edit(lo, 1 - h)
        edit(hi, 1 + h)
        out[gname] = (np.log(freqs(hi)) - np.log(freqs(lo)))[jj] / (np.log1p(h) - np.log1p(-h))
    if base["kind"] == "shear_building":  # a foundation floor on soil at a reference stiffness, and braces
        out["foundation"] = _foundation_sensitivity(base, freqs, jj, h)
        dampers = base["shear_building"].get("dampers") or []
        if dampers:
            lo = copy.deepcopy(base)
            hi = copy.deepcopy(base)
            for d in dampers:  # a reference brace: 30 % of the story's stiffness, in parallel
                s = int(max(d["between"])) - 1
                hi["shear_building"]["floors"][s]["stiffness"] *= 1 + 0.3 * h
            out["damper"] = (np.log(freqs(hi)) - np.log(freqs(lo)))[jj] / h
    return out


def _foundation_sensitivity(base: dict[str, Any], freqs, jj: np.ndarray, h: float) -> np.ndarray:
    fl = base["shear_building"]["floors"]
    total = sum(f["mass"] for f in fl)
    out = []
    for f in (1 - h, 1 + h):
        d = copy.deepcopy(base)
        d["shear_building"]["floors"].insert(0, {"mass": 0.15 * total, "stiffness": 3.0 * fl[0]["stiffness"] * f})
        d["shear_building"].pop("dampers", None)
        for s in d["sensors"]:
            s["at"]["floor"] = int(s["at"]["floor"]) + 1 if int(s["at"]["floor"]) > 0 else 0
        d.pop("input", None)
        out.append(np.log(freqs(d)))
    # the foundation adds a mode below the first: compare the building's modes (skip none: the sway
    # mode of a stiff soil sits above the building's lowest modes, so ranks hold for the low modes)
    return ((out[1] - out[0])[jj]) / (np.log1p(h) - np.log1p(-h))


def _scale_path(d: dict[str, Any], path: str, v: float) -> None:
    """Multiply the values at a parameter's ``applies_to`` path (``a.b[0,1].c``, ``a.b[*].c``) by v."""
    import re

    def walk(node: Any, parts: list[str]) -> None:
        head, rest = parts[0], parts[1:]
        m = re.fullmatch(r"(\w+)(?:\[([^\]]*)\])?", head)
        assert m is not None, path
        key, idx = m.group(1), m.group(2)
        if idx is None:
            if not rest:
                node[key] = float(node[key]) * v
            else:
                walk(node[key], rest)
            return
        seq = node[key]
        if isinstance(seq, dict):  # one section for every span
            seq = node[key] = [dict(seq) for _ in range(len(node.get("spans", [])) or 1)]
        picks = range(len(seq)) if idx == "*" else [int(i) for i in idx.split(",")]
        for i in picks:
            if not rest:
                seq[i] = float(seq[i]) * v
            else:
                walk(seq[i], rest)

    walk(d, path.split("."))
