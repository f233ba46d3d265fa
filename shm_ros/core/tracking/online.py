"""The tracker: estimates arrive one at a time (in time order), rows leave at once.

The first ``reference_windows`` estimates are buffered and establish the tracked modes (then their
rows leave together); each later estimate gives one :class:`TrackedRow`. The environmental models
and the novelty threshold are fitted on the first ``training_windows`` rows; later rows carry the
normalised frequencies, a novelty score and an alarm flag. :func:`shm_ros.core.tracking.track` runs
the same tracker over a whole campaign, so the node and the command agree window by window.
The tracker is a plain object (picklable): the history store checkpoints it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from shm_ros.core.tracking import environment as env
from shm_ros.core.tracking.assign import assign, gates
from shm_ros.core.tracking.config import EnvModel, ReferenceSource, TrackingConfig
from shm_ros.core.tracking.novelty import NoveltyChart
from shm_ros.core.tracking.reference import ReferenceMode, build_reference, cluster_arrays, model_modes
from shm_ros.core.tracking.shapes import aligned, mac_table, shapes_on, widen
from shm_ros.core.types import ModalEstimate

if TYPE_CHECKING:
    from shm_ros.core.structure import StructureSpec

MIN_TRAINING = 10  # windows with a novelty statistic needed before alarms are raised
NS_PER_DAY = 86400e9
# weight of the prediction's standard error in the residual scale: the coefficients' error is
# a lower bound on the error of a model pushed beyond its training conditions (its form may be off too)
EXTRAPOLATION = 3.0


@dataclass
class TrackedRow:
    """One window of the tracker (one ``TrackedModes`` message)."""

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
    normalised_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))  # NaN until trained
    alarm_modes: list[int] = field(default_factory=list)
    unassigned: int = 0  # the window's modes that matched no tracked mode


def raw_covariates(est: ModalEstimate) -> dict[str, float]:
    out: dict[str, float] = {}
    if est.temperature_c is not None:
        out["temperature_c"] = float(est.temperature_c)
    for k, v in est.covariates.items():
        if k not in out:
            out[k] = float("nan") if v is None else float(v)
    return out


class Tracker:
    """Online tracking (see the module docstring). ``structure``: the FE model for
    ``reference_source`` model/both."""

    def __init__(self, config: TrackingConfig | None = None, training_windows: int = 144,
                 structure: StructureSpec | None = None) -> None:
        self.config = config or TrackingConfig()
        if training_windows < 3:
            raise ValueError(f"training_windows must be >= 3, got {training_windows}")
        if self.config.reference_source != ReferenceSource.WINDOWS and structure is None:
            raise ValueError(f"reference_source={self.config.reference_source} needs a structure file")
        self.training_windows = training_windows
        self.structure = structure
        self.reference: list[ReferenceMode] = []
        self.sensors: list[str] = []
        self._buffer: list[ModalEstimate] = []
        self._ref_f = np.zeros(0)
        self._ref_s = np.zeros((0, 0))
        self._ref_d = np.zeros(0)
        self._misses = np.zeros(0, int)
        self._offset = np.zeros(0)
        self._t0: int | None = None
        self._last_ns: int | None = None
        self._last: dict[str, float] = {}  # last value of each covariate (imputes a missing one)
        self._lagged: dict[str, float] = {}
        self._train: list[tuple[np.ndarray, np.ndarray, dict[str, float]]] = []
        self._fits: list[env.EnvironmentalFit] = []
        self._pca: env.PcaModel | None = None
        self._damp_stats: np.ndarray = np.zeros((0, 2))
        self._chart = NoveltyChart(self.config.ewma_lambda, 0)
        self.trained = False
        self._above = 0  # consecutive windows above the threshold
        self._pool: deque[tuple[int, float, float, np.ndarray]] = deque()
        self.n_rows = 0
        self.unassigned = 0
        self.notes: list[str] = []

    # -- public ---------------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        return bool(self.reference)

    @property
    def numbers(self) -> list[int]:
        return [r.number for r in self.reference]

    @property
    def environment(self) -> list[env.EnvironmentalFit]:
        return list(self._fits)

    @property
    def threshold(self) -> float:
        return self._chart.threshold if self.trained else float("nan")

    def add(self, est: ModalEstimate) -> list[TrackedRow]:
        if self.reference:
            return [self._row(est)]
        self._buffer.append(est)
        need = 1 if self.config.reference_source == ReferenceSource.MODEL else self.config.reference_windows
        if len(self._buffer) < need:
            return []
        return self._establish(slide=True)

    def flush(self) -> list[TrackedRow]:
        """End of the record: a reference from fewer windows than ``reference_windows`` (an event
        catalogue), and the environmental model from fewer than ``training_windows`` rows."""
        rows = self._establish(slide=False) if not self.reference and self._buffer else []
        if self.reference and not self.trained and len(self._train) >= 3:
            self._fit()
        return rows

    # -- reference ------------------------------------------------------------------------------
    def _establish(self, slide: bool) -> list[TrackedRow]:
        sensors: list[str] = []
        for e in self._buffer:
            sensors += [s for s in e.sensor_ids if s not in sensors]
        fe = model_modes(self.structure, sensors) if self.structure is not None and \
            self.config.reference_source != ReferenceSource.WINDOWS else None
        reference = build_reference(self._buffer, sensors, self.config, fe)
        if not reference:
            if slide:  # nothing recurs yet: slide the reference period on
                self._buffer.pop(0)
            return []
        self.sensors, self.reference = sensors, reference
        self._ref_f = np.array([r.frequency_hz for r in reference])
        self._ref_s = np.array([r.shape for r in reference])
        self._ref_d = np.array([r.damping for r in reference])
        self._misses = np.zeros(len(reference), int)
        self._offset = np.zeros(len(reference))
        self._chart.resize(2 * len(reference))
        pending, self._buffer = self._buffer, []
        return [self._row(e) for e in pending]

    def _add_sensors(self, ids: list[str]) -> None:
        new = [s for s in ids if s not in self.sensors]
        if new:
            self.sensors += new
            self._ref_s = widen(self._ref_s, len(self.sensors))
            for r in self.reference:
                r.shape = widen(r.shape, len(self.sensors))
            self._pool = deque((i, f, d, widen(s, len(self.sensors))) for i, f, d, s in self._pool)

    # -- covariates -----------------------------------------------------------------------------
    def _features(self, est: ModalEstimate) -> dict[str, float]:
        raw = raw_covariates(est)
        if self._t0 is None:
            self._t0 = est.start_ns
        dt_h = 0.0 if self._last_ns is None else (est.start_ns - self._last_ns) / 3.6e12
        self._last_ns = est.start_ns
        for k, v in raw.items():
            if math.isfinite(v):
                self._last[k] = v
        x = {k: self._last.get(k, float("nan")) for k in set(raw) | set(self._last)}
        tau = self.config.lag_hours
        if tau > 0:
            for k in sorted(x):
                if not k.startswith("temperature") or not math.isfinite(x[k]):
                    continue
                lag = f"{k}_lag"
                prev = self._lagged.get(lag)
                a = 1.0 if prev is None else 1.0 - math.exp(-max(dt_h, 0.0) / tau)
                self._lagged[lag] = x[k] if prev is None else prev + a * (x[k] - prev)
            x.update(self._lagged)
        x[env.TIME] = (est.start_ns - self._t0) / NS_PER_DAY
        return x

    # -- one window -----------------------------------------------------------------------------
    def _predicted(self, x: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(frequency the assignment expects, reference it is compared with for the gate)."""
        pred, base = self._ref_f.copy(), self._ref_f.copy()
        main = self.config.covariate
        for k, fit in enumerate(self._fits):
            p = env.predict(fit, x, main)
            if math.isfinite(p) and p > 0 and math.isfinite(fit.reference_hz):
                pred[k], base[k] = p + self._offset[k], fit.reference_hz
        return pred, base

    def _row(self, est: ModalEstimate) -> TrackedRow:
        cfg = self.config
        self._add_sensors(est.sensor_ids)
        x = self._features(est)
        n_t, n_s = len(self.reference), len(self.sensors)
        f_w = np.array([m.frequency_hz for m in est.modes], dtype=float)
        d_w = np.array([m.damping_ratio for m in est.modes], dtype=float)
        s_w = shapes_on(est, self.sensors)
        pred, base = self._predicted(x)
        spread = np.array([r.spread for r in self.reference])
        a = assign(f_w, s_w, pred, gates(cfg, pred, base, self._misses, spread), self._ref_s, cfg)
        freq, damp = np.full(n_t, np.nan), np.full(n_t, np.nan)
        shapes = np.full((n_t, n_s), np.nan)
        for k in range(n_t):
            i = a.index[k]
            if i < 0:
                self._misses[k] += 1
                continue
            self._misses[k] = 0
            freq[k], damp[k] = f_w[i], d_w[i]
            shapes[k] = aligned(s_w[i], self._ref_s[k])
            if cfg.adapt > 0:
                self._follow(k, freq[k], damp[k], shapes[k], pred[k])
        self.unassigned += a.unassigned.size
        for i in a.unassigned:
            if np.isfinite(f_w[i]) and f_w[i] > 0:
                self._pool.append((self.n_rows, float(f_w[i]), float(d_w[i]), s_w[i]))
        row = TrackedRow(est.window_id, est.start_ns, self.numbers, freq, damp, a.mac, list(self.sensors),
                         shapes, {k: v for k, v in raw_covariates(est).items()},
                         normalised_hz=np.full(n_t, np.nan), unassigned=int(a.unassigned.size))
        self.n_rows += 1
        if self.trained:
            self._score(row, x)
        else:
            self._train.append((freq.copy(), damp.copy(), x))
            if len(self._train) >= self.training_windows:
                self._fit()
        if cfg.birth_windows > 0 and self.n_rows % max(1, cfg.birth_windows // 4) == 0:
            self._births(est.window_id)
        return row

    def _follow(self, k: int, f: float, d: float, shape: np.ndarray, pred: float) -> None:
        c = self.config.adapt
        self._ref_f[k] = (1 - c) * self._ref_f[k] + c * f
        new = np.where(np.isfinite(shape), shape, self._ref_s[k])
        self._ref_s[k] = np.where(np.isfinite(self._ref_s[k]), (1 - c) * self._ref_s[k] + c * new, new)
        if math.isfinite(d):
            self._ref_d[k] = d if not math.isfinite(self._ref_d[k]) else (1 - c) * self._ref_d[k] + c * d
        if k < len(self._fits) and math.isfinite(self._fits[k].reference_hz):
            self._offset[k] = (1 - c) * self._offset[k] + c * (f - (pred - self._offset[k]))

    # -- new modes ------------------------------------------------------------------------------
    def _births(self, window_id: str) -> None:
        cfg = self.config
        horizon = self.n_rows - cfg.birth_windows
        while self._pool and self._pool[0][0] < horizon:
            self._pool.popleft()
        if len(self._pool) < cfg.min_presence * cfg.birth_windows:
            return
        items = list(self._pool)
        f = np.array([p[1] for p in items])
        clusters = cluster_arrays(f, np.array([p[2] for p in items]), np.array([p[3] for p in items]),
                                  np.array([p[0] for p in items]), cfg.cluster_cutoff, cfg.min_presence,
                                  cfg.birth_windows)
        taken: set[int] = set()
        for fm, shape, presence, dm, members, spread in clusters:
            mac = mac_table(shape[None, :], self._ref_s)[0] if self.reference else np.zeros(0)
            near = np.abs(fm - self._ref_f) / self._ref_f <= cfg.max_freq_gate
            if np.any((mac >= cfg.mac_min) & near):
                continue  # a tracked mode that missed its gate, not a new one
            number = max(self.numbers, default=0) + 1
            self.reference.append(ReferenceMode(number, fm, shape.copy(), presence, dm, "born", spread=spread,
                                                born_window=window_id))
            self._ref_f = np.append(self._ref_f, fm)
            self._ref_s = np.vstack([self._ref_s.reshape(-1, len(self.sensors)), shape[None, :]])
            self._ref_d = np.append(self._ref_d, dm)
            self._misses = np.append(self._misses, 0)
            self._offset = np.append(self._offset, 0.0)
            self._chart.resize(2 * len(self.reference))
            taken |= {int(m) for m in members}
            self.notes.append(f"mode {number} ({fm:.4g} Hz) appeared by window {window_id}")
        if taken:
            self._pool = deque(p for j, p in enumerate(items) if j not in taken)

    # -- environment and novelty ----------------------------------------------------------------
    def _fit(self) -> None:
        cfg = self.config
        n_t = len(self.reference)
        freq = np.array([np.pad(f, (0, n_t - f.size), constant_values=np.nan) for f, _, _ in self._train])
        damp = np.array([np.pad(d, (0, n_t - d.size), constant_values=np.nan) for _, d, _ in self._train])
        names = sorted({k for _, _, x in self._train for k in x})
        xs = {k: np.array([x.get(k, np.nan) for _, _, x in self._train]) for k in names}
        measured = [k for k in names if k != env.TIME and np.isfinite(xs[k]).any()]
        choice = EnvModel(cfg.env_model)
        if choice is EnvModel.PCA or (choice is EnvModel.AUTO and not measured):
            self._pca = env.PcaModel.fit(freq)
            self._fits = [env.fit_mode(r.number, freq[:, k], {}, cfg.covariate, EnvModel.CONSTANT)
                          for k, r in enumerate(self.reference)]
            if self._pca is None:
                self.notes.append("no covariate and too few complete windows for PCA: constant frequencies")
        else:
            use = {k: v for k, v in xs.items() if k in measured or k == env.TIME}
            self._fits = [env.fit_mode(r.number, freq[:, k], use, cfg.covariate, choice)
                          for k, r in enumerate(self.reference)]
        logd = np.log(np.where(damp > 0, damp, np.nan))
        self._damp_stats = np.full((n_t, 2), np.nan)
        for k in range(n_t):
            v = logd[:, k][np.isfinite(logd[:, k])]
            if v.size >= 3:
                self._damp_stats[k] = np.median(v), np.std(v)
        for k, fit in enumerate(self._fits):
            self._chart.set_autocorrelation(2 * k, fit.autocorrelation)
        stats = [self._chart.update(self._residuals(freq[w], damp[w], {k: xs[k][w] for k in names})[0])
                 for w in range(len(self._train))]
        self._chart.calibrate(np.array(stats), cfg.alarm_quantile)
        if len(self._train) < MIN_TRAINING:
            self._chart.threshold = float("inf")
            self.notes.append(f"fewer than {MIN_TRAINING} training windows: no novelty threshold, no alarms")
        self.trained = True
        self._train = []

    def _residuals(self, f: np.ndarray, d: np.ndarray, x: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """Chart inputs [z_f1, z_d1, z_f2, ...] and the normalised frequencies of one window."""
        n_t = f.size
        z = np.full(2 * n_t, np.nan)
        norm = np.full(n_t, np.nan)
        if self._pca is not None:
            m = self._pca.mean.size
            zf = np.full(n_t, np.nan)
            zf[:m] = self._pca.residual_z(f[:m])
            z[0::2] = zf
            norm[:m] = self._pca.normalised(f[:m])
        else:
            for k, fit in enumerate(self._fits[:n_t]):
                p = env.predict(fit, x, self.config.covariate)
                if math.isfinite(p) and math.isfinite(f[k]):
                    se = env.prediction_std(fit, x, self.config.covariate, p)
                    z[2 * k] = (f[k] - p) / math.hypot(fit.residual_std_hz, EXTRAPOLATION * se)
                    norm[k] = f[k] - p + fit.reference_hz
        if self.config.novelty_damping and self._damp_stats.size:
            for k in range(min(n_t, self._damp_stats.shape[0])):
                mu, sd = self._damp_stats[k]
                if d[k] > 0 and math.isfinite(mu) and sd > 0:
                    z[2 * k + 1] = (math.log(d[k]) - mu) / sd
        return z, norm

    def _score(self, row: TrackedRow, x: dict[str, float]) -> None:
        z, row.normalised_hz = self._residuals(row.frequencies_hz, row.damping, x)
        row.novelty_score = self._chart.update(z)
        row.novelty_threshold = self._chart.threshold
        above = math.isfinite(row.novelty_score) and row.novelty_score > self._chart.threshold
        self._above = self._above + 1 if above else 0
        row.novelty_alarm = self._above >= self.config.alarm_windows
        if row.novelty_alarm:
            dims = [n for n in self.numbers for _ in (0, 1)]
            row.alarm_modes = sorted(set(self._chart.alarm_modes(dims, self.config.alarm_quantile)))
