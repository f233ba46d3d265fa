"""Mode identities across many windows, their environmental dependence, and novelty.

``track(estimates, TrackingConfig())`` turns a sequence of per-window modal estimates (modes
unnumbered, sorted by frequency, spurious ones possible, true ones sometimes missing) into the
tracked-modes table of docs/interfaces.md §4:

1. **Reference set** from the first ``reference_windows`` windows: their modes are clustered on
   ``|f_i - f_j| / max(f_i, f_j) + (1 - MAC_ij)`` (average linkage, as the stabilization-diagram
   picking); a cluster present in at least ``min_presence`` of those windows is a tracked mode,
   numbered from 1 by ascending frequency, with the median frequency and a representative shape.
2. **Assignment** window by window: the optimal one-to-one assignment
   (``scipy.optimize.linear_sum_assignment``) of the window's modes to the tracked modes on
   ``|df| / f_ref / freq_tol + (1 - MAC) / (1 - mac_min)``, with both terms gated at 1. The
   reference frequency and shape then follow slow drift (temperature) by an exponential average
   (``adapt``), so the frequency gate can stay narrow.
3. **Environment**: per tracked mode, frequency against the covariate (``temperature_c``) by least
   squares over the training part (the first ``training_fraction`` of the windows).
4. **Novelty**: residuals from that environmental model, standardised by their training spread,
   combined into ``mean(z_k^2)`` over the modes found; the alarm threshold is the
   ``alarm_quantile`` of the training scores. A window whose modes moved in a way temperature does
   not explain (damage, added mass, a support change) stands out.

MAC is computed on the sensors both shapes have (windows may lose channels).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.optimize import linear_sum_assignment

from shm_ros.core.bayes.observations import ModalObservations
from shm_ros.core.config import option
from shm_ros.core.modal import mac as modal_mac
from shm_ros.core.types import ModalEstimate

__all__ = ["TrackingConfig", "ReferenceMode", "EnvironmentalFit", "TrackingResult", "track",
           "Tracker", "TrackedRow"]


MIN_TRAINING = 10  # windows with a novelty score needed before alarms are raised


@dataclass
class TrackingConfig:
    reference_windows: int = option(24, "windows that establish the tracked mode set")
    min_presence: float = option(0.5, "a tracked mode is found in at least this fraction of the "
                                 "reference windows")
    cluster_cutoff: float = option(0.05, "cut-off of |df|/f + (1 - MAC) when clustering the "
                                   "reference windows' modes")
    freq_tol: float = option(0.05, "assignment gate: |f - f_ref| / f_ref")
    mac_min: float = option(0.8, "assignment gate: MAC with the reference shape")
    adapt: float = option(0.1, "exponential average of the reference after each assignment (0 = fixed)")
    covariate: str = option("temperature_c", "environmental variable of the frequency regression")
    # the node trains on its first ``training_windows`` rows instead (it cannot know the total)
    training_fraction: float = option(0.25, "first fraction of the windows that trains the "
                                      "environmental model and the novelty threshold", ros=False)
    alarm_quantile: float = option(0.99, "novelty threshold = this quantile of the training scores")

    def __post_init__(self) -> None:
        if self.reference_windows < 1:
            raise ValueError(f"reference_windows must be >= 1, got {self.reference_windows}")
        for name in ("min_presence", "training_fraction", "alarm_quantile"):
            v = getattr(self, name)
            if not 0 < v <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {v}")
        if not 0 < self.freq_tol < 1 or not 0 <= self.mac_min < 1:
            raise ValueError("freq_tol must be in (0, 1) and mac_min in [0, 1)")
        if not 0 <= self.adapt < 1:
            raise ValueError(f"adapt must be in [0, 1), got {self.adapt}")


@dataclass
class ReferenceMode:
    number: int
    frequency_hz: float  # median over the reference windows
    shape: np.ndarray  # over TrackingResult.observations.sensor_ids (NaN = sensor never seen)
    presence: float  # fraction of the reference windows in which it was found


@dataclass
class EnvironmentalFit:
    mode: int
    intercept_hz: float
    slope_hz_per_unit: float  # per unit of the covariate (Hz per deg C for temperature)
    slope_pct_per_unit: float
    r2: float
    residual_std_hz: float
    n: int


@dataclass
class TrackingResult:
    observations: ModalObservations  # the tracked-modes table (docs/interfaces.md §4)
    reference: list[ReferenceMode]
    mac_to_reference: np.ndarray  # (n_windows, n_modes), NaN = not found
    environment: list[EnvironmentalFit]
    novelty_score: np.ndarray  # (n_windows,), NaN where no tracked mode was found
    novelty_threshold: float
    novelty_alarm: np.ndarray  # (n_windows,) bool
    n_training: int
    unassigned: int  # identified modes that matched no tracked mode (spurious or new)
    # covariate outside the range seen in training: the environmental model extrapolates there,
    # so an alarm may only mean that the training period was too short
    outside_training: np.ndarray | None = None
    window_ids: list[str] = field(default_factory=list)  # in time order, as the table's rows
    notes: list[str] = field(default_factory=list)


def _shapes_on(est: ModalEstimate, sensors: list[str]) -> np.ndarray:
    """(n_modes, n_sensors) shapes of one window on the common sensor list (NaN where absent)."""
    out = np.full((len(est.modes), len(sensors)), np.nan)
    col = {s: j for j, s in enumerate(sensors)}
    idx = [col[s] for s in est.sensor_ids]
    for k, m in enumerate(est.modes):
        out[k, idx] = np.asarray(m.mode_shape, dtype=float)
    return out


def _reference(estimates: list[ModalEstimate], sensors: list[str], cfg: TrackingConfig
               ) -> list[ReferenceMode]:
    f_list: list[float] = []
    shp_list: list[np.ndarray] = []
    win_list: list[int] = []
    for w, est in enumerate(estimates):
        s = _shapes_on(est, sensors)
        for k, m in enumerate(est.modes):
            if np.isfinite(m.frequency_hz) and m.frequency_hz > 0:
                f_list.append(m.frequency_hz)
                shp_list.append(s[k])
                win_list.append(w)
    if not f_list:
        return []
    f, shp, win = np.array(f_list), np.array(shp_list), np.array(win_list)
    if f.size == 1:
        labels = np.zeros(1, int)
    else:
        d = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :])
        mac = modal_mac(shp[:, None, :], shp[None, :, :], min_common=2)
        d = d + (1.0 - mac)
        iu = np.triu_indices(f.size, 1)
        labels = fcluster(linkage(np.clip(d[iu], 0, None), method="average"),
                          t=cfg.cluster_cutoff, criterion="distance") - 1
    refs = []
    n_ref = len(estimates)
    for lab in np.unique(labels):
        members = np.flatnonzero(labels == lab)
        presence = np.unique(win[members]).size / n_ref
        if presence < cfg.min_presence:
            continue
        fm = float(np.median(f[members]))
        rep = members[np.argmin(np.abs(f[members] - fm))]
        refs.append((fm, shp[rep], presence))
    refs.sort(key=lambda r: r[0])
    return [ReferenceMode(k + 1, fm, s, p) for k, (fm, s, p) in enumerate(refs)]


def _aligned(shape: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``shape`` with the sign that agrees with ``ref`` on their common sensors."""
    ok = np.isfinite(shape) & np.isfinite(ref)
    return -shape if ok.any() and float(shape[ok] @ ref[ok]) < 0 else shape


def _assign(est: ModalEstimate, sensors: list[str], ref_f: np.ndarray, ref_s: np.ndarray,
            cfg: TrackingConfig):
    """One window's modes onto the tracked modes; updates ``ref_f``/``ref_s`` in place (drift).

    Returns frequency, damping, shape and MAC rows (NaN where not found) and the number of the
    window's modes left unassigned."""
    n_m, n_s = ref_f.size, len(sensors)
    freq, damp, macs = np.full(n_m, np.nan), np.full(n_m, np.nan), np.full(n_m, np.nan)
    shapes = np.full((n_m, n_s), np.nan)
    if not est.modes:
        return freq, damp, shapes, macs, 0
    f = np.array([m.frequency_hz for m in est.modes], dtype=float)
    s = _shapes_on(est, sensors)
    mac = modal_mac(s[:, None, :], ref_s[None, :, :], min_common=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        df = np.abs(f[:, None] - ref_f[None, :]) / ref_f[None, :] / cfg.freq_tol
    dm = (1.0 - mac) / (1.0 - cfg.mac_min)
    gate = (df <= 1.0) & (dm <= 1.0)
    cost = np.where(gate, df + dm, 1e6)
    rows, cols = linear_sum_assignment(np.nan_to_num(cost, nan=1e6))
    ok = gate[rows, cols]
    rows, cols = rows[ok], cols[ok]
    for i, k in zip(rows, cols, strict=True):
        freq[k] = f[i]
        damp[k] = est.modes[i].damping_ratio
        shapes[k] = _aligned(s[i], ref_s[k])
        macs[k] = mac[i, k]
        if cfg.adapt > 0:
            ref_f[k] = (1 - cfg.adapt) * ref_f[k] + cfg.adapt * f[i]
            new = np.where(np.isfinite(shapes[k]), shapes[k], ref_s[k])
            ref_s[k] = np.where(np.isfinite(ref_s[k]), (1 - cfg.adapt) * ref_s[k] + cfg.adapt * new,
                                new)
    return freq, damp, shapes, macs, len(est.modes) - rows.size


def track(estimates: list[ModalEstimate], config: TrackingConfig | None = None) -> TrackingResult:
    """Tracked modes of ``estimates`` (in time order; see the module docstring)."""
    cfg = config or TrackingConfig()
    estimates = sorted(estimates, key=lambda e: e.start_ns)
    if not estimates:
        raise ValueError("track: no modal estimates")
    sensors: list[str] = []
    for est in estimates:
        sensors += [s for s in est.sensor_ids if s not in sensors]
    reference = _reference(estimates[:cfg.reference_windows], sensors, cfg)
    notes: list[str] = []
    if not reference:
        raise ValueError(f"track: no mode is found in {cfg.min_presence:.0%} of the first "
                         f"{min(cfg.reference_windows, len(estimates))} windows")
    n_w, n_m, n_s = len(estimates), len(reference), len(sensors)
    freq = np.full((n_w, n_m), np.nan)
    damp = np.full((n_w, n_m), np.nan)
    shapes = np.full((n_w, n_m, n_s), np.nan)
    macs = np.full((n_w, n_m), np.nan)
    ref_f = np.array([r.frequency_hz for r in reference])
    ref_s = np.array([r.shape for r in reference])
    unassigned = 0
    for w, est in enumerate(estimates):
        freq[w], damp[w], shapes[w], macs[w], n_left = _assign(est, sensors, ref_f, ref_s, cfg)
        unassigned += n_left
    covariates = _covariates(estimates)
    times = np.array([e.start_ns / 1e9 for e in estimates])
    obs = ModalObservations(times=times, mode_numbers=[r.number for r in reference],
                            frequencies_hz=freq, shapes=shapes, sensor_ids=sensors, damping=damp,
                            covariates=covariates, time_kind="iso")
    n_train = max(3, int(np.ceil(cfg.training_fraction * n_w)))
    x = covariates.get(cfg.covariate)
    if x is None:
        notes.append(f"no covariate {cfg.covariate!r}: the environmental model is a constant")
    env, resid_z = _environment(freq, x, n_train, [r.number for r in reference])
    score, threshold, alarm = _novelty(resid_z, n_train, cfg.alarm_quantile)
    if not np.isfinite(threshold):
        notes.append(f"fewer than {MIN_TRAINING} training windows with tracked modes: no novelty "
                     "threshold, no alarms")
    outside = np.zeros(n_w, bool)
    if x is not None and np.isfinite(x[:n_train]).any():
        lo, hi = np.nanmin(x[:n_train]), np.nanmax(x[:n_train])
        margin = 0.05 * (hi - lo)
        outside = np.isfinite(x) & ((x < lo - margin) | (x > hi + margin))
        if np.any(alarm & outside):
            notes.append(f"{int(np.sum(alarm & outside))} of {int(alarm.sum())} novelty alarms are "
                         f"at {cfg.covariate} outside the training range [{lo:.3g}, {hi:.3g}]")
    return TrackingResult(obs, reference, macs, env, score, threshold, alarm, min(n_train, n_w),
                          unassigned, outside, [e.window_id for e in estimates], notes)


def _covariates(estimates: list[ModalEstimate]) -> dict[str, np.ndarray]:
    names: list[str] = []
    if any(e.temperature_c is not None for e in estimates):
        names.append("temperature_c")
    for e in estimates:
        names += [k for k in e.covariates if k not in names]
    out = {}
    for name in names:
        vals = []
        for e in estimates:
            v = e.temperature_c if name == "temperature_c" else e.covariates.get(name)
            vals.append(np.nan if v is None else float(v))
        out[name] = np.array(vals)
    return out


def _environment(freq: np.ndarray, x: np.ndarray | None, n_train: int, numbers: list[int]):
    """Per mode: least-squares line f = a + b x on the training windows; standardised residuals
    of every window (NaN where the mode or the covariate is missing)."""
    n_w, n_m = freq.shape
    z = np.full((n_w, n_m), np.nan)
    fits = []
    for k in range(n_m):
        f = freq[:, k]
        xx = np.zeros(n_w) if x is None else x
        use = np.isfinite(f) & np.isfinite(xx)
        tr = use.copy()
        tr[n_train:] = False
        if tr.sum() < 3:
            fits.append(EnvironmentalFit(numbers[k], np.nan, np.nan, np.nan, np.nan, np.nan,
                                         int(tr.sum())))
            continue
        a = np.column_stack([np.ones(tr.sum()), xx[tr]])
        coef = np.linalg.lstsq(a, f[tr], rcond=None)[0]
        if x is None or np.ptp(xx[tr]) == 0:
            coef = np.array([np.mean(f[tr]), 0.0])
        pred = coef[0] + coef[1] * xx
        res = f - pred
        sd = float(np.std(res[tr], ddof=2 if x is not None else 1)) or 1e-12
        ss = float(np.sum((f[tr] - f[tr].mean()) ** 2))
        r2 = 1.0 - float(np.sum(res[tr] ** 2)) / ss if ss > 0 else 0.0
        z[use, k] = res[use] / sd
        fits.append(EnvironmentalFit(numbers[k], float(coef[0]), float(coef[1]),
                                     float(100 * coef[1] / coef[0]), r2, sd, int(tr.sum())))
    return fits, z


def _novelty(z: np.ndarray, n_train: int, quantile: float):
    found = np.isfinite(z)
    with np.errstate(invalid="ignore", divide="ignore"):
        score = np.where(found.any(axis=1),
                         np.nansum(np.where(found, z * z, 0.0), axis=1) / found.sum(axis=1), np.nan)
    train = score[:n_train]
    train = train[np.isfinite(train)]
    # a quantile of a handful of scores is no threshold: below MIN_TRAINING no alarm is raised
    threshold = float(np.quantile(train, quantile)) if train.size >= MIN_TRAINING else np.inf
    alarm = np.isfinite(score) & (score > threshold)
    alarm[:n_train] = alarm[:n_train] & False  # the training period defines normal
    return score, threshold, alarm


@dataclass
class TrackedRow:
    """One window of the online tracker (one ``TrackedModes`` message)."""

    window_id: str
    start_ns: int
    mode_numbers: list[int]
    frequencies_hz: np.ndarray
    damping: np.ndarray
    macs: np.ndarray
    sensor_ids: list[str]
    shapes: np.ndarray  # (n_modes, n_sensors)
    covariates: dict[str, float]
    novelty_score: float = float("nan")  # NaN until the training windows are in
    novelty_threshold: float = float("nan")
    novelty_alarm: bool = False


class Tracker:
    """Online tracking for a node: estimates arrive one at a time (in time order).

    The first ``reference_windows`` estimates are buffered and establish the tracked modes (as in
    :func:`track`); from then on each estimate gives one :class:`TrackedRow` at once (the buffered
    ones first). The environmental model and the novelty threshold are fitted on the first
    ``training_windows`` rows; later rows carry a novelty score and an alarm flag.
    """

    def __init__(self, config: TrackingConfig | None = None, training_windows: int = 144) -> None:
        self.config = config or TrackingConfig()
        if training_windows < 3:
            raise ValueError(f"training_windows must be >= 3, got {training_windows}")
        self.training_windows = training_windows
        self.reference: list[ReferenceMode] = []
        self.sensors: list[str] = []
        self._buffer: list[ModalEstimate] = []
        self._ref_f = np.zeros(0)
        self._ref_s = np.zeros((0, 0))
        self._train: list[TrackedRow] = []
        self._fits: list[EnvironmentalFit] = []
        self._threshold = float("nan")
        self._has_covariate = False
        self.unassigned = 0

    @property
    def ready(self) -> bool:
        return bool(self.reference)

    def add(self, est: ModalEstimate) -> list[TrackedRow]:
        if not self.reference:
            self._buffer.append(est)
            if len(self._buffer) < self.config.reference_windows:
                return []
            for e in self._buffer:
                self.sensors += [s for s in e.sensor_ids if s not in self.sensors]
            self.reference = _reference(self._buffer, self.sensors, self.config)
            if not self.reference:  # nothing recurs yet: slide the reference period on
                self._buffer.pop(0)
                self.sensors = []
                return []
            self._ref_f = np.array([r.frequency_hz for r in self.reference])
            self._ref_s = np.array([r.shape for r in self.reference])
            pending, self._buffer = self._buffer, []
            return [self._row(e) for e in pending]
        return [self._row(est)]

    def _row(self, est: ModalEstimate) -> TrackedRow:
        f, d, s, m, left = _assign(est, self.sensors, self._ref_f, self._ref_s, self.config)
        self.unassigned += left
        cov = {k: float(v[0]) for k, v in _covariates([est]).items()}
        row = TrackedRow(est.window_id, est.start_ns, [r.number for r in self.reference], f, d, m,
                         list(self.sensors), s, cov)
        if len(self._train) < self.training_windows:
            self._train.append(row)
            if len(self._train) == self.training_windows:
                self._fit()
            return row
        x = cov.get(self.config.covariate, 0.0 if not self._has_covariate else np.nan)
        z = np.full(f.size, np.nan)
        for k, fit in enumerate(self._fits):
            if np.isfinite(fit.intercept_hz) and np.isfinite(f[k]) and np.isfinite(x):
                z[k] = (f[k] - fit.intercept_hz - fit.slope_hz_per_unit * x) / fit.residual_std_hz
        if np.isfinite(z).any():
            row.novelty_score = float(np.nanmean(z * z))
            row.novelty_alarm = bool(row.novelty_score > self._threshold)
        row.novelty_threshold = self._threshold
        return row

    def _fit(self) -> None:
        freq = np.array([r.frequencies_hz for r in self._train])
        xs = [r.covariates.get(self.config.covariate) for r in self._train]
        self._has_covariate = any(v is not None and np.isfinite(v) for v in xs)
        x = np.array([np.nan if v is None else v for v in xs]) if self._has_covariate else None
        self._fits, z = _environment(freq, x, len(self._train), [r.number for r in self.reference])
        _, self._threshold, _ = _novelty(z, len(self._train), self.config.alarm_quantile)

    @property
    def environment(self) -> list[EnvironmentalFit]:
        return list(self._fits)
