"""Environmental models of the tracked frequencies: regression on covariates, or PCA without them.

Per tracked mode the candidates are

(each linear in f^2, i.e. in stiffness, which is what temperature changes; errors in Hz)

- ``constant``; ``linear`` in the main covariate x (``temperature_c``);
- ``bilinear``: ``a + b x + c min(x - knee, 0)`` (bearings and deck stiffen below freezing), the
  knee chosen on a grid over the training range;
- ``multi``: every measured covariate (temperatures at several points, each also through a
  first-order lag for thermal inertia, ``rms_accel_m_s2``, ...) and time; ``multi_knee`` adds the knee.

and the one with the smallest held-out error (blocked cross-validation: contiguous blocks of the
training windows, so neighbouring windows do not vouch for each other) is kept; among candidates
within 5 % of the best the simplest wins. The chosen model's residual spread and lag-1
autocorrelation over the training windows scale what the novelty chart sees. Without any
covariate the ``pca`` model takes over: the leading
principal components of the standardised frequencies (found in every window) are the environment,
and a window's residual is what its modes do beyond them.

``normalised = f - prediction(x) + reference`` is the frequency at the training period's mean
conditions (exported beside the tracked frequencies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shm_ros.core.tracking.config import EnvModel

N_FOLDS = 5
MIN_FIT = 6  # windows of a mode needed to fit anything but a constant
TIME = "time_d"  # the time feature: days since the first window
MIN_TREND_DAYS = 30.0  # training span before time is a candidate covariate
SIMPLER = [EnvModel.CONSTANT, EnvModel.LINEAR, EnvModel.BILINEAR, EnvModel.MULTI, EnvModel.MULTI_KNEE]


@dataclass
class EnvironmentalFit:
    mode: int
    intercept_hz: float  # sqrt of the f^2 model's intercept
    slope_hz_per_unit: float  # per unit of the main covariate (above the knee), at the reference
    slope_pct_per_unit: float
    r2: float
    residual_std_hz: float  # in-sample residual spread: the residual scale of the novelty chart
    n: int
    model: str = "constant"
    features: list[str] = field(default_factory=list)  # design columns after the intercept
    coefficients: list[float] = field(default_factory=list)  # of f^2 (Hz^2), intercept first
    knee: float = float("nan")
    reference_hz: float = float("nan")  # frequency at the training period's mean conditions
    heldout_rmse_hz: dict[str, float] = field(default_factory=dict)  # every candidate's (selection)
    autocorrelation: float = 0.0  # lag-1, of the training residuals (window to window), >= 0
    coefficient_cov: list[list[float]] = field(default_factory=list)  # of the f^2 coefficients


def _design(x: dict[str, np.ndarray], features: list[str], knee: float, main: str, n: int) -> np.ndarray:
    cols = [np.ones(n)]
    for name in features:
        if name == "knee":
            cols.append(np.minimum(x[main] - knee, 0.0))
        else:
            cols.append(x[name])
    return np.column_stack(cols)


def _lstsq(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.where(np.std(a, axis=0) > 0, np.std(a, axis=0), 1.0)
    scale[0] = 1.0
    sol = np.linalg.lstsq(a / scale, y, rcond=None)[0]
    return sol / scale


def _cv_rmse(a: np.ndarray, y: np.ndarray) -> float:
    """Blocked cross-validated RMSE in Hz of a model fitted to ``y`` = f^2."""
    n = y.size
    if n < 2 * N_FOLDS or a.shape[1] >= n - n // N_FOLDS - 1:
        return float("inf")
    err = np.empty(n)
    for test in np.array_split(np.arange(n), N_FOLDS):
        train = np.ones(n, bool)
        train[test] = False
        at = a[train]
        if np.any(np.ptp(at[:, 1:], axis=0) == 0) if at.shape[1] > 1 else False:
            return float("inf")  # a column constant in the fold: not identifiable there
        err[test] = np.sqrt(y[test]) - _root(a[test] @ _lstsq(at, y[train]))
    return float(np.sqrt(np.mean(err ** 2)))


def _root(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(v, 0.0, None))


def candidate_features(x: dict[str, np.ndarray], main: str, train: np.ndarray) -> dict[EnvModel, list[str]]:
    """Design columns of each candidate model, given the covariates measured in training. Time
    enters only after ``MIN_TREND_DAYS`` of training: over a few days a trend cannot be told from
    weather, and extrapolated it drifts away from every later window."""
    usable = [k for k, v in x.items() if np.isfinite(v[train]).mean() >= 0.9 and np.ptp(v[train][
        np.isfinite(v[train])]) > 0]
    if TIME in usable and np.ptp(x[TIME][train]) < MIN_TREND_DAYS:
        usable.remove(TIME)
    out: dict[EnvModel, list[str]] = {EnvModel.CONSTANT: []}
    if main in usable:
        out[EnvModel.LINEAR] = [main]
        out[EnvModel.BILINEAR] = [main, "knee"]
    multi = ([main] if main in usable else []) + [k for k in usable if k != main]
    if len(multi) > 1:
        out[EnvModel.MULTI] = multi
        if main in usable:
            out[EnvModel.MULTI_KNEE] = [*multi, "knee"]
    return out


def knee_grid(xm: np.ndarray) -> np.ndarray:
    xm = xm[np.isfinite(xm)]
    if xm.size < 10:
        return np.zeros(0)
    lo, hi = np.quantile(xm, [0.1, 0.9])
    return np.arange(np.ceil(2 * lo) / 2, hi + 0.25, 0.5)


def refine_knee(xs: dict[str, np.ndarray], feats: list[str], knee: float, main: str, y: np.ndarray) -> float:
    """The knee to a fraction of a degree: least squares over +-0.5 of the best grid value (a
    knee misplaced by half a degree costs a freezing girder a percent of frequency)."""
    from scipy.optimize import minimize_scalar

    def sse(k: float) -> float:
        a = _design(xs, feats, k, main, y.size)
        return float(np.sum((np.sqrt(y) - _root(a @ _lstsq(a, y))) ** 2))

    return float(minimize_scalar(sse, bounds=(knee - 0.5, knee + 0.5), method="bounded",
                                 options={"xatol": 0.01}).x)


def fit_mode(number: int, f: np.ndarray, x: dict[str, np.ndarray], main: str, choice: EnvModel
             ) -> EnvironmentalFit:
    """The environmental model of one mode on its training rows (``f`` NaN = not found)."""
    use = np.isfinite(f)
    for v in x.values():
        use &= np.isfinite(v)
    y = f[use]
    if y.size < 2:
        return EnvironmentalFit(number, float("nan"), float("nan"), float("nan"), float("nan"), float("nan"),
                                int(y.size))
    xs = {k: v[use] for k, v in x.items()}
    fy = y
    y = fy ** 2  # the models are linear in stiffness, i.e. in f^2
    cands = candidate_features(x, main, use) if y.size >= MIN_FIT else {EnvModel.CONSTANT: []}
    if choice not in (EnvModel.AUTO, EnvModel.PCA):
        cands = {choice: cands[choice]} if choice in cands else {EnvModel.CONSTANT: []}
    knees = knee_grid(xs[main]) if main in xs else np.zeros(0)
    scores: dict[EnvModel, tuple[float, float]] = {}
    for kind, feats in cands.items():
        best = (float("inf"), float("nan"))
        for knee in (knees if "knee" in feats else [float("nan")]):
            err = _cv_rmse(_design(xs, feats, knee, main, y.size), y)
            if err < best[0]:
                best = (err, float(knee))
        if "knee" in feats and np.isfinite(best[1]):
            knee = refine_knee(xs, feats, best[1], main, y)
            best = (min(best[0], _cv_rmse(_design(xs, feats, knee, main, y.size), y)), knee)
        scores[kind] = best
    best_err = min(s[0] for s in scores.values())
    if len(cands) == 1:
        # a model asked for by name needs no held-out error to be chosen (a mode found in fewer
        # windows than the folds need still gets it), unless its knee could not be placed
        kind = next(iter(cands))
        if "knee" in cands[kind] and not np.isfinite(scores[kind][1]):
            kind = EnvModel.CONSTANT
    elif not np.isfinite(best_err):
        kind = EnvModel.CONSTANT
    else:
        kind = next(k for k in SIMPLER if k in scores and scores[k][0] <= 1.05 * best_err)
    feats, knee = cands.get(kind, []), scores.get(kind, (np.inf, np.nan))[1]
    a = _design(xs, feats, knee, main, y.size)
    coef = _lstsq(a, y)
    res = fy - _root(a @ coef)
    ss = float(np.sum((fy - fy.mean()) ** 2))
    r2 = 1.0 - float(np.sum(res ** 2)) / ss if ss > 0 else 0.0
    dof = max(1, y.size - a.shape[1])
    # the residual scale is the in-sample one: a held-out fold that holds the only freezing night
    # of the training period measures extrapolation to an unseen spell, not normal scatter
    sd = max(float(np.sqrt(np.sum(res ** 2) / dof)), 1e-9 * abs(float(fy.mean())))
    ac = float(np.corrcoef(res[:-1], res[1:])[0, 1]) if res.size > 3 and np.std(res) > 0 else 0.0
    res2 = y - a @ coef
    cov = float(np.sum(res2 ** 2) / dof) * np.linalg.pinv(a.T @ a)
    mean_x = {k: float(np.mean(v)) for k, v in xs.items()}
    ref = float(predict_one(coef, feats, knee, main, mean_x))
    # d f / d x = (d f^2 / d x) / (2 f) at the reference conditions
    slope = float(coef[1 + feats.index(main)]) / (2 * ref) if main in feats else 0.0
    pct = float(100 * slope / ref) if ref else float("nan")
    return EnvironmentalFit(number, float(np.sqrt(max(coef[0], 0.0))), slope, pct, r2,
                            sd, int(y.size), kind.value, list(feats), [float(c) for c in coef], knee, ref,
                            {k.value: float(v[0]) for k, v in scores.items()}, float(np.clip(ac, 0.0, 0.95)),
                            cov.tolist())


def predict_one(coef: np.ndarray | list[float], feats: list[str], knee: float, main: str,
                x: dict[str, float]) -> float:
    """Frequency predicted by one fit for one window's covariates (NaN when one it needs is missing)."""
    out = float(coef[0])
    for c, name in zip(coef[1:], feats, strict=True):
        v = min(x.get(main, np.nan) - knee, 0.0) if name == "knee" else x.get(name, np.nan)
        out += float(c) * float(v)
    return float(np.sqrt(out)) if out > 0 else float("nan")


def _row(feats: list[str], knee: float, main: str, x: dict[str, float]) -> np.ndarray:
    return np.array([1.0] + [min(x.get(main, np.nan) - knee, 0.0) if n == "knee" else x.get(n, np.nan)
                             for n in feats], float)


def prediction_std(fit: EnvironmentalFit, x: dict[str, float], main: str, f: float) -> float:
    """Standard error of the predicted frequency (Hz) from the coefficients' uncertainty: small
    inside the training conditions, growing as the model extrapolates (a frost colder than any in
    training), so that the chart does not mistake extrapolation error for change."""
    if not fit.coefficient_cov or not math.isfinite(f) or f <= 0:
        return 0.0
    a = _row(fit.features, fit.knee, main, x)
    var = float(a @ np.asarray(fit.coefficient_cov) @ a)
    return math.sqrt(max(var, 0.0)) / (2 * f) if math.isfinite(var) else 0.0


def predict(fit: EnvironmentalFit, x: dict[str, float], main: str) -> float:
    if not fit.coefficients:
        return float("nan")
    return predict_one(fit.coefficients, fit.features, fit.knee, main, x)


@dataclass
class PcaModel:
    """Environment as the leading principal components of the standardised frequencies."""

    mean: np.ndarray  # (n_modes,)
    std: np.ndarray
    components: np.ndarray  # (n_modes, r)
    residual_std: np.ndarray  # (n_modes,) held-out, in the standardised units

    @classmethod
    def fit(cls, freq: np.ndarray, explained: float = 0.9) -> PcaModel | None:
        full = freq[np.all(np.isfinite(freq), axis=1)]
        m = freq.shape[1]
        if m < 2 or full.shape[0] < max(10, m + 2):
            return None
        mean, std = full.mean(axis=0), full.std(axis=0)
        std = np.where(std > 0, std, 1.0)
        y = (full - mean) / std
        _, sv, vt = np.linalg.svd(y, full_matrices=False)
        frac = np.cumsum(sv ** 2) / np.sum(sv ** 2)
        r = int(min(m - 1, np.searchsorted(frac, explained) + 1))
        comps = vt[:r].T
        # held-out residual scale: each mode predicted from the others (leave that mode out)
        res = np.full(y.shape, np.nan)
        for k in range(m):
            keep = np.arange(m) != k
            c = np.linalg.lstsq(comps[keep], y[:, keep].T, rcond=None)[0]
            res[:, k] = y[:, k] - (comps[k] @ c)
        return cls(mean, std, comps, np.sqrt(np.mean(res ** 2, axis=0)))

    def residual_z(self, f: np.ndarray) -> np.ndarray:
        """Standardised residual of each mode of one window, predicted from its other modes."""
        y = (f - self.mean) / self.std
        z = np.full(f.size, np.nan)
        ok = np.isfinite(y)
        for k in np.flatnonzero(ok):
            others = ok.copy()
            others[k] = False
            if others.sum() < self.components.shape[1]:
                continue
            c = np.linalg.lstsq(self.components[others], y[others], rcond=None)[0]
            z[k] = (y[k] - self.components[k] @ c) / self.residual_std[k]
        return z

    def normalised(self, f: np.ndarray) -> np.ndarray:
        z = self.residual_z(f)
        return self.mean + z * self.residual_std * self.std
