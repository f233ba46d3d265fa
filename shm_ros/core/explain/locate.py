"""Locate: where the calibrated nominal model and the data disagree, and which candidates to fit.

Residuals ``r[w, k] = ln f_obs - ln f_model`` (:class:`~.types.Baseline`) of the training windows
only (the held-out ones are read as missing: they stay a test of what locate proposes) are noise plus a per-mode
offset (model-form error) when the model lacks nothing that changes between windows. Anything else
shows up as structure in time, and locate asks, in this order:

1. *Noise or structure?* Per mode, a Ljung-Box test of the residual's autocorrelation; the white
   level of each mode is estimated from first differences (slow structure cancels in them).
2. *What does it co-vary with?* A forward selection of regressors shared by all modes (each mode has
   its own coefficients): temperature (with a lag, and a hinge whose knee is profiled), the response
   amplitude (``rms_accel_m_s2``, ``pga_m_s2``), a step in time (the exact single change point of the
   linear model, with the regressors already chosen kept in the model, so that a frequency-temperature
   relation persists across the step), a window of the day and a temperature threshold (intermittent
   masses). Each step adds the regressor with the largest drop of the summed chi-square over modes if
   that drop beats a chi-square threshold corrected for the profiling; covariates that move together
   (traffic and temperature share the daily cycle) are thus weighed jointly, not one by one.
3. *Where does it act?* The per-mode pattern of each selected effect is compared with every parameter
   group's modal sensitivities (weighted least squares of pattern = c x sensitivity with a relative
   model-form allowance); the groups that fit best name the candidates.
4. Damping: ln damping against amplitude (amplitude-dependent damping).
5. Observed modes no model mode pairs with (``baseline.unpaired``) are unmodelled modes.

ruptures is not a dependency: the one change point needed here (a step added to a linear model whose
other regressors stay in) is found exactly by scanning every window with projections, which costs
O(W^2) for the few thousand windows of a campaign, so no segmentation library is needed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from .candidates._common import daily_windows, hour_utc, hours_text
from .candidates.base import Context
from .types import Baseline, Mismatch, Proposal
from .whiteness import LAGS, STRUCTURED_P, ljung_box

STIFFNESS = ("EI", "bearings", "bearings_rot", "foundation", "damper")


@dataclass
class LocateConfig:
    whiteness_p: float = STRUCTURED_P  # Ljung-Box p-value below which a mode's residual is structured
    ljung_box_lags: int = LAGS
    significance: float = 1e-6  # per regressor family, after the Bonferroni factor of its profile
    max_effects: int = 3  # regressors selected (forward)
    lags_h: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0)  # thermal lag of the structure behind the air
    model_form_allowance: float = 0.15  # relative misfit of a pattern allowed by model-form error
    groups_per_effect: int = 3
    min_unpaired_fraction: float = 0.5  # unmodelled modes seen in at least this share of windows
    damping_significance: float = 1e-6
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class _Effect:
    kind: str  # temperature, temperature_knee, amplitude:<cov>, step, hours, below
    columns: np.ndarray  # (W, q)
    gain: float  # drop of the summed chi-square when it was added
    hints: dict[str, Any]
    pattern: np.ndarray | None = None  # (K,) per-mode size of the effect
    pattern_se: np.ndarray | None = None


def locate(obs, baseline: Baseline, context: Context, config: LocateConfig | None = None
           ) -> tuple[Mismatch, list[Proposal]]:
    """Residual analysis -> (mismatch, proposals); see the module docstring."""
    cfg = config or LocateConfig()
    R = training_only(np.asarray(baseline.log_residual, float), baseline.train)
    W, K = R.shape
    ok = np.isfinite(R)
    Rc = R - np.nanmedian(R, axis=0)
    sigma = np.array([_white_level(Rc[:, k]) for k in range(K)])
    white = [ljung_box(Rc[:, k], cfg.ljung_box_lags) for k in range(K)]
    structured = [baseline.mode_numbers[k] for k in range(K) if white[k] < cfg.whiteness_p]
    Z = np.where(ok, Rc / sigma, 0.0)
    covs = {k: np.asarray(v, float) for k, v in context.covariates.items()}
    hour = hour_utc(context)
    effects = _select(Z, ok, covs, np.asarray(context.times_s, float), hour, cfg) if structured else []
    X = np.column_stack([np.ones(W)] + [e.columns for e in effects]) if effects else np.ones((W, 1))
    _patterns(effects, X, Z, ok, sigma)
    proposals: list[Proposal] = []
    where: dict[str, list[tuple[str, float]]] = {}
    for e in effects:
        assert e.pattern is not None and e.pattern_se is not None
        ranked = _rank_groups(e.pattern, e.pattern_se, baseline.sensitivities, cfg)
        where[e.kind] = ranked
        proposals += _proposals_for(e, ranked, cfg)
    damp = _damping(obs, baseline, covs, cfg)
    if damp is not None:
        proposals.append(Proposal("amplitude_damping", "damping",
                                  f"modal damping rises with {damp['covariate']} (correlation {damp['r']:+.2f})",
                                  {"covariate": damp["covariate"]}))
    unpaired = [u for u in baseline.unpaired
                if u.get("fraction_of_windows") is None or u["fraction_of_windows"] >= cfg.min_unpaired_fraction]
    seen: set[tuple[str, str]] = set()
    unique = []
    for p in proposals:
        if (p.candidate, p.group) not in seen:
            seen.add((p.candidate, p.group))
            unique.append(p)
    corr = _correlations(R, covs, hour)
    summary = _summary(effects, where, damp, unpaired, structured)
    details = {"ljung_box_p": {int(m): float(p) for m, p in zip(baseline.mode_numbers, white, strict=True)},
               "white_level": {int(m): float(s) for m, s in zip(baseline.mode_numbers, sigma, strict=True)},
               "effects": [{"kind": e.kind, "chi2_gain": e.gain, "hints": e.hints,
                            "pattern": None if e.pattern is None else e.pattern.tolist(),
                            "groups": where.get(e.kind, [])} for e in effects],
               "damping": damp, "unmodelled_modes": unpaired}
    mism = Mismatch(modes=structured + [int(u["mode"]) for u in unpaired if u.get("mode") is not None],
                    sensors=list(getattr(obs, "sensor_ids", [])), covariates=corr, summary=summary, details=details)
    return mism, unique


def training_only(values: np.ndarray, train: np.ndarray | None) -> np.ndarray:
    """``values`` (W, K) with the held-out windows' rows missing (NaN): locate reads the training windows
    only, so that the held-out windows stay a test of everything the residual analysis proposes."""
    out = np.array(values, dtype=float)
    if train is not None:
        out[~np.asarray(train, bool)] = np.nan
    return out


# -- noise or structure ------------------------------------------------------------------------------

def _white_level(r: np.ndarray) -> float:
    d = np.diff(r[np.isfinite(r)])
    if d.size < 3:
        return 1.0
    return max(float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0)), 1e-6)


# -- what it co-varies with ----------------------------------------------------------------------------

def _fill(x: np.ndarray) -> np.ndarray:
    """Missing covariate values by linear interpolation (the nearest value at the ends)."""
    from .candidates._common import fill_missing

    return fill_missing(x)


def _gain(Z: np.ndarray, ok: np.ndarray, X: np.ndarray, cols: np.ndarray) -> float:
    """Drop of the summed chi-square over modes when ``cols`` join the design ``X`` (per mode fits on
    the windows where the mode was found)."""
    total = 0.0
    A = np.column_stack([X, cols])
    for k in range(Z.shape[1]):
        m = ok[:, k]
        z = Z[m, k]
        r0 = z - X[m] @ np.linalg.lstsq(X[m], z, rcond=None)[0]
        r1 = z - A[m] @ np.linalg.lstsq(A[m], z, rcond=None)[0]
        total += float(r0 @ r0 - r1 @ r1)
    return total


HOURS_STARTS = np.arange(0.0, 24.0, 0.5)
HOURS_LENGTHS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0)
HOURS_GAP = 3.0  # h between two windows of the day


def _hours(Z: np.ndarray, ok: np.ndarray, X: np.ndarray, hour: np.ndarray, first: list[list[float]],
           cfg: LocateConfig) -> tuple[_Effect | None, int]:
    """The window of the day whose indicator (with the ``first`` windows, if any) best explains the
    misfit, and the number of windows searched. Traffic has two peaks a day: with one window found,
    a second one at least ``HOURS_GAP`` away joins it when the pair gains more than the search's own
    threshold (one indicator for both: the same jam in the morning and the evening)."""
    best, n = None, 0
    have = daily_windows(hour, first) if first else np.zeros(hour.size, bool)
    # the second peak is apart from the first (morning and evening), not an extension of it
    near = (daily_windows(hour, [[(a - HOURS_GAP) % 24.0, (b + HOURS_GAP) % 24.0] for a, b in first]) if first
            else have)
    for h0 in HOURS_STARTS:
        for d in HOURS_LENGTHS:
            n += 1
            inside = daily_windows(hour, [h0, (h0 + d) % 24.0])
            if (near & inside).any():
                continue
            inside = inside | have
            if inside.mean() < 0.02 or inside.mean() > 0.5:
                continue
            col = inside.astype(float)[:, None]
            g = _gain(Z, ok, X, col)
            if best is None or g > best.gain:
                best = _Effect("hours", col, g, {"hours_utc": [*first, [float(h0), float((h0 + d) % 24.0)]]})
    if best is not None and not first:
        second, n2 = _hours(Z, ok, X, hour, best.hints["hours_utc"], cfg)
        if second is not None and second.gain - best.gain > _threshold(Z.shape[1], n2, cfg):
            return second, n + n2
    return best, n


def _step_profile(Z: np.ndarray, ok: np.ndarray, X: np.ndarray, lo: int, hi: int) -> tuple[int, float]:
    """Exact single change point of a step added to the linear model ``X``: for every window c the
    summed chi-square drop of the step column H(w >= c), by projections (all c at once)."""
    W = Z.shape[0]
    cs = np.arange(lo, hi)
    H = (np.arange(W)[:, None] >= cs[None, :]).astype(float)  # (W, C)
    gains = np.zeros(cs.size)
    for k in range(Z.shape[1]):
        m = ok[:, k]
        Xm, z, Hm = X[m], Z[m, k], H[m]
        Q, _ = np.linalg.qr(Xm)
        e = z - Q @ (Q.T @ z)
        Hr = Hm - Q @ (Q.T @ Hm)
        den = np.einsum("ij,ij->j", Hr, Hr)
        gains += np.where(den > 1e-9, (Hr.T @ e) ** 2 / np.maximum(den, 1e-12), 0.0)
    j = int(np.argmax(gains))
    return int(cs[j]), float(gains[j])


def _span(ok: np.ndarray, c: int) -> list[int]:
    """The windows a change found at ``c`` may lie in: from the first window after the last one with
    data before ``c`` to the first with data from ``c`` on (a held-out block reads as no data: a change
    inside it is placed by the windows around it)."""
    has = np.asarray(ok, bool).any(axis=1).reshape(-1)
    before = np.flatnonzero(has[:c])
    after = np.flatnonzero(has[c:])
    return [int(before[-1] + 1) if before.size else 0, int(c + after[0]) if after.size else int(c)]


def _threshold(df: int, n_profile: int, cfg: LocateConfig) -> float:
    return float(stats.chi2.isf(cfg.significance / max(n_profile, 1), df))


def _select(Z: np.ndarray, ok: np.ndarray, covs: dict[str, np.ndarray], t: np.ndarray, hour: np.ndarray,
            cfg: LocateConfig) -> list[_Effect]:
    W, K = Z.shape
    X = np.ones((W, 1))
    chosen: list[_Effect] = []
    temp = _fill(covs["temperature_c"]) if "temperature_c" in covs else None
    for _ in range(cfg.max_effects):
        options: list[tuple[float, _Effect]] = []  # (gain - threshold, effect)
        have = {e.kind for e in chosen}
        if temp is not None and "temperature" not in have:
            best = None
            for lag in cfg.lags_h:
                col = np.interp(t - 3600.0 * lag, t, temp)[:, None]
                g = _gain(Z, ok, X, col)
                if best is None or g > best.gain:
                    best = _Effect("temperature", col, g, {"covariate": "temperature_c", "lag_h": lag})
            assert best is not None
            options.append((best.gain - _threshold(K, len(cfg.lags_h), cfg), best))
        if temp is not None and "temperature" in have and "temperature_knee" not in have:
            tcol = next(e for e in chosen if e.kind == "temperature").columns[:, 0]
            knees = np.quantile(tcol, np.linspace(0.1, 0.9, 33))
            best = None
            for kn in knees:
                col = np.minimum(tcol - kn, 0.0)[:, None]
                g = _gain(Z, ok, X, col)
                if best is None or g > best.gain:
                    best = _Effect("temperature_knee", col, g, {"knee_c": float(kn)})
            assert best is not None
            options.append((best.gain - _threshold(K, knees.size, cfg), best))
        if temp is not None and "below" not in have:  # a threshold in temperature (ice, snow)
            cuts = np.quantile(temp, np.linspace(0.05, 0.95, 37))
            best = None
            for c in cuts:
                col = (temp < c).astype(float)[:, None]
                g = _gain(Z, ok, X, col)
                if best is None or g > best.gain:
                    best = _Effect("below", col, g, {"below_c": float(c)})
            assert best is not None
            options.append((best.gain - _threshold(K, cuts.size, cfg), best))
        for name in ("rms_accel_m_s2", "pga_m_s2"):
            if name in covs and f"amplitude:{name}" not in have:
                a = _fill(covs[name])
                if np.ptp(a) <= 0:
                    continue
                e = _Effect(f"amplitude:{name}", a[:, None], _gain(Z, ok, X, a[:, None]), {"covariate": name})
                options.append((e.gain - _threshold(K, 1, cfg), e))
        if "step" not in have and W >= 20:
            lo, hi = max(5, W // 50), W - max(5, W // 50)
            c, g = _step_profile(Z, ok, X, lo, hi)
            col = (np.arange(W) >= c).astype(float)[:, None]
            options.append((g - _threshold(K, hi - lo, cfg),
                            _Effect("step", col, g, {"change_index": c, "change_time_s": float(t[c]),
                                                     "change_span": _span(ok, c)})))
        if "hours" not in have:  # windows of the day (slow or jammed traffic, crowds)
            best, n = _hours(Z, ok, X, hour, [], cfg)
            if best is not None:
                options.append((best.gain - _threshold(K, n, cfg), best))
        if not options:
            break
        margin, eff = max(options, key=lambda o: o[0])
        if margin <= 0:
            break
        chosen.append(eff)
        X = np.column_stack([X, eff.columns])
    return chosen


def _patterns(effects: list[_Effect], X: np.ndarray, Z: np.ndarray, ok: np.ndarray, sigma: np.ndarray) -> None:
    """Per-mode size of each effect: its fitted contribution's signed range (in ln f), with its
    standard error, from the joint fit of every selected regressor."""
    K = Z.shape[1]
    spans = []
    col = 1
    for e in effects:
        q = e.columns.shape[1]
        spans.append(slice(col, col + q))
        col += q
        e.pattern, e.pattern_se = np.zeros(K), np.zeros(K)
    for k in range(K):
        m = ok[:, k]
        A = X[m]
        beta, *_ = np.linalg.lstsq(A, Z[m, k], rcond=None)
        res = Z[m, k] - A @ beta
        s2 = float(res @ res) / max(m.sum() - A.shape[1], 1)
        cov = s2 * np.linalg.pinv(A.T @ A)
        for e, sl in zip(effects, spans, strict=True):
            contrib = X[:, sl] @ beta[sl]
            lo, hi = np.quantile(contrib, [0.02, 0.98])
            ref = X[:, sl] @ np.ones(sl.stop - sl.start)
            sign = 1.0 if np.corrcoef(contrib, ref)[0, 1] >= 0 or np.ptp(ref) == 0 else -1.0
            span = float(np.ptp(X[:, sl], axis=0).max()) if sl.stop > sl.start else 1.0
            assert e.pattern is not None and e.pattern_se is not None
            e.pattern[k] = sign * (hi - lo) * sigma[k]
            # the size's standard error from the coefficients' (the first column dominates)
            e.pattern_se[k] = float(np.sqrt(max(cov[sl.start, sl.start], 0.0))) * span * sigma[k]


# -- where it acts --------------------------------------------------------------------------------------

def _rank_groups(p: np.ndarray, se: np.ndarray, sens: dict[str, np.ndarray], cfg: LocateConfig
                 ) -> list[tuple[str, float]]:
    """Groups by the weighted misfit of p = c s_g (chi-square per degree of freedom), best first.

    The model-form allowance of a mode is a share of the larger of its own shift and the typical
    mode's (RMS over the modes), as in the candidates' likelihood: a mode that barely moves may move
    several times more or less in the structure than the model says."""
    out = []
    typical = float(np.sqrt(np.mean(p ** 2)))
    var = se ** 2 + (cfg.model_form_allowance * np.maximum(np.abs(p), typical)) ** 2 + 1e-10
    for g, s in sens.items():
        s = np.asarray(s, float)
        if s.shape != p.shape or not np.any(np.abs(s) > 1e-6):
            continue
        c = float(np.sum(p * s / var) / np.sum(s * s / var))
        chi = float(np.sum((p - c * s) ** 2 / var)) / max(p.size - 1, 1)
        out.append((g, chi))
    out.sort(key=lambda t: t[1])
    return out


def _is_mass(g: str) -> bool:
    return g == "mass" or g.startswith("mass:")


def _proposals_for(e: _Effect, ranked: list[tuple[str, float]], cfg: LocateConfig) -> list[Proposal]:
    """Candidates for one selected effect on its best-fitting groups (within a factor 3 of the best
    misfit, at most ``groups_per_effect``)."""
    if not ranked:
        return []
    best = ranked[0][1]
    groups = [g for g, chi in ranked if chi <= max(3.0 * best, best + 2.0)]
    # at most groups_per_effect, but never one of a pair of equal fits without the other (a span
    # and its mirror image: the frequencies cannot tell them apart, the shapes can)
    chi = dict(ranked)
    keep = groups[:cfg.groups_per_effect]
    last = chi[keep[-1]] if keep else 0.0
    groups = keep + [g for g in groups[len(keep):] if abs(chi[g] - last) <= 1e-6 * max(1.0, last)]
    out: list[Proposal] = []
    h = dict(e.hints)
    for g in groups:
        why = f"{_words(e)}; the shifts across modes fit the sensitivities of {g}"
        support = g in ("bearings", "bearings_rot", "foundation")
        if e.kind == "temperature":
            if g == "damper":
                out.append(Proposal("damper_stiffness", g, why, h))
            elif support:
                out.append(Proposal("support_springs", g, why, h))
                out.append(Proposal("temperature_linear", g, why, h))
            elif not _is_mass(g):
                out.append(Proposal("temperature_linear", g, why, h))
        elif e.kind == "temperature_knee":
            if support:
                out.append(Proposal("support_springs", g, why, {**h, "covariate": "temperature_c"}))
            if not _is_mass(g) and g != "damper":
                out.append(Proposal("temperature_bilinear", g, why, h))
        elif e.kind.startswith("amplitude:"):
            if not _is_mass(g) and g != "damper":
                out.append(Proposal("amplitude_stiffness", g, why, h))
        elif e.kind == "step":
            if _is_mass(g):
                out.append(Proposal("added_mass", g, why, {**h, "when": "after"}))
            elif g == "damper":
                out.append(Proposal("damper_stiffness", g, why, h))
            else:
                if support:
                    out.append(Proposal("support_springs", g, why, h))
                out.append(Proposal("step", g, why, h))
        elif e.kind in ("hours", "below"):
            if _is_mass(g):
                out.append(Proposal("added_mass", g, why, {**h, "when": e.kind}))
            elif support and e.kind == "below":
                out.append(Proposal("support_springs", g, why, {"covariate": "temperature_c", "knee_c": h["below_c"]}))
            if e.kind == "below" and not _is_mass(g) and g != "damper":
                # stiffness that differs below a temperature (a freezing deck or bearing): a knee
                # there, with the slopes on either side free, holds a plain offset below it too
                out.append(Proposal("temperature_bilinear", g, why, {**h, "knee_c": h["below_c"]}))
    if e.kind in ("hours", "below", "step") and not any(p.candidate == "added_mass" for p in out):
        m = next((g for g, _ in ranked if _is_mass(g)), None)  # a mass change looks like a stiffness one
        if m is not None and e.kind != "step":
            out.append(Proposal("added_mass", m, f"{_words(e)}; a mass on {m} would shift the modes alike",
                                {**h, "when": e.kind}))
    return out


def _words(e: _Effect) -> str:
    h = e.hints
    if e.kind == "temperature":
        return f"the misfit follows the temperature (lag {h['lag_h']:g} h)"
    if e.kind == "temperature_knee":
        return f"its slope with temperature changes at about {h['knee_c']:.1f} degC"
    if e.kind.startswith("amplitude:"):
        return f"the misfit follows {h['covariate']}"
    if e.kind == "step":
        return f"the misfit steps at window {h['change_index']}"
    if e.kind == "hours":
        return f"the misfit differs {hours_text(h['hours_utc'])} (UTC) each day"
    if e.kind == "below":
        return f"the misfit differs below {h['below_c']:.1f} degC"
    return e.kind


# -- damping ---------------------------------------------------------------------------------------------

def _damping(obs, baseline: Baseline, covs: dict[str, np.ndarray], cfg: LocateConfig) -> dict[str, Any] | None:
    """ln damping of every paired mode against each amplitude covariate (pooled, per-mode centred)."""
    D = getattr(obs, "damping", None)
    if D is None:
        return None
    cols = [obs.mode_numbers.index(m) for m in baseline.mode_numbers if m in obs.mode_numbers]
    with np.errstate(divide="ignore", invalid="ignore"):
        L = training_only(np.log(np.asarray(D, float)[:, cols]), baseline.train)
    L = L - np.nanmedian(L, axis=0)
    best = None
    for name in ("rms_accel_m_s2", "pga_m_s2"):
        if name not in covs:
            continue
        a = _fill(covs[name])
        if np.ptp(a) <= 0:
            continue
        x = np.repeat(a[:, None], L.shape[1], axis=1)
        m = np.isfinite(L)
        r, p = stats.spearmanr(x[m], L[m])
        if p < cfg.damping_significance and r > 0 and (best is None or p < best["p"]):
            best = {"covariate": name, "r": float(r), "p": float(p)}
    return best


def _correlations(R: np.ndarray, covs: dict[str, np.ndarray], hour: np.ndarray) -> dict[str, float]:
    """Correlation of the modes' mean centred misfit with each covariate (and with time)."""
    Rc = R - np.nanmedian(R, axis=0)
    has = np.isfinite(Rc).any(axis=1)  # held-out windows (and windows without a mode) have none
    y = np.full(R.shape[0], np.nan)
    y[has] = np.nanmean(Rc[has], axis=1)
    out = {}
    series = {**covs, "time": np.arange(R.shape[0], dtype=float)}
    for k, v in series.items():
        x = _fill(v)
        m = np.isfinite(y)
        if m.sum() > 3 and np.ptp(x[m]) > 0 and np.ptp(y[m]) > 0:
            out[k] = float(np.corrcoef(x[m], y[m])[0, 1])
    return out


def _summary(effects, where, damp, unpaired, structured) -> str:
    parts = []
    for e in effects:
        g = where.get(e.kind) or []
        parts.append(_words(e) + (f", acting on {g[0][0]}" if g else ""))
    if damp:
        parts.append(f"damping rises with {damp['covariate']}")
    if unpaired:
        parts.append(f"{len(unpaired)} observed mode(s) pair with no model mode")
    if not parts:
        return "the misfit is noise around constant per-mode offsets (model-form error)" + (
            "" if not structured else "; some modes show structure no tested covariate explains")
    return "; ".join(parts) + "."
