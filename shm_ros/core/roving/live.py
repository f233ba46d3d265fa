"""A roving recording as it comes (the core of the live roving node): samples and transforms
accumulate, the robot's current setup is judged (:func:`~shm_ros.core.roving.advice.setup_enough`)
and, once it is enough, the next point chosen (:func:`~shm_ros.core.roving.advice.next_point`).

**The setup so far.** The robot says at which measurement point it stands (:meth:`LiveRoving.start`);
from then on, the samples whose filtered tf position lies at that point (the rules of
:func:`~shm_ros.core.roving.setups.cut_setups`) form the setup, with the clock offset corrected as
offline. Each :meth:`LiveRoving.advise` identifies it and merges it with the setups already finished.

**Shape std at the point.** The point's component of a mode and its standard error come from the
references' transmissibility over the setup so far, the step the offline merge uses
(:func:`~shm_ros.core.roving.transmissibility.roving_components`: the roving channel's short-time
spectra fitted on all references' over the bins around the mode, times the merged reference shape);
the fit's standard error shrinks with the dwell and grows with the sensors' noise. It is combined in
quadrature with the merge's own ``shape_std`` at the point.

**Global modes.** :meth:`LiveRoving.result` runs the offline pipeline
(:func:`~shm_ros.core.roving.pipeline.roving_modes`) on everything received, so a recording replayed
through the live graph gives what the offline command gives.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from shm_ros.core.band import nominal_frequencies
from shm_ros.core.identify import identify_prepared
from shm_ros.core.modal import mac
from shm_ros.core.roving.advice import next_point, setup_enough
from shm_ros.core.roving.merge_post import GlobalMode, merge_post
from shm_ros.core.roving.nominal import MIN_MAC
from shm_ros.core.roving.pipeline import AXIS, RovingConfig, RovingResult, prepare_setup, roving_modes
from shm_ros.core.roving.setups import cut_setups, sensor_track, setup_channels
from shm_ros.core.roving.transforms import TransformBuffer
from shm_ros.core.roving.transmissibility import roving_components
from shm_ros.core.structure import StructureSpec
from shm_ros.core.types import ModalEstimate
from shm_ros.errors import InputError

__all__ = ["AdviceConfig", "PointAdvice", "LiveRoving"]


@dataclass
class AdviceConfig:
    shape_std_max: float = 0.05  # every mode of interest: shape std at the point below this
    frequency_tol: float = 0.005  # ... and its last n_stable frequencies within this fraction
    n_stable: int = 3
    n_modes: int = 3  # the modes of interest: the lowest n_modes of the nominal model
    segment_s: float = 4.0  # spectral segment of the transmissibility error (resolution 1 / segment_s)
    min_segments: int = 4  # fewer independent segments: no shape std yet
    min_setup_s: float = 10.0  # below this much of the setup, no estimate yet ("continue")
    frequency_match: float = 0.15  # an identified mode is a mode of interest within this fraction


@dataclass
class PointAdvice:
    point_id: str
    recorded_s: float
    enough: bool
    reasons: list[str]
    frequencies_hz: list[float]
    shape_std: list[float]
    next_point_id: str = ""
    expected_reduction: float = float("nan")
    next_position: tuple[float, float, float] | None = None
    estimate: ModalEstimate | None = field(default=None, repr=False)

    @property
    def status(self) -> str:
        return "enough" if self.enough else "continue"


class _Stream:
    """One sensor's samples in arrival order (stamps ns, values)."""

    def __init__(self) -> None:
        self.times: list[np.ndarray] = []
        self.values: list[np.ndarray] = []
        self.n = 0

    def add(self, times_ns: np.ndarray, values: np.ndarray) -> None:
        self.times.append(np.asarray(times_ns, dtype=np.int64))
        self.values.append(np.asarray(values, dtype=float))
        self.n += len(times_ns)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.times:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        if len(self.times) > 1:
            self.times, self.values = [np.concatenate(self.times)], [np.concatenate(self.values)]
        return self.times[0], self.values[0]


class LiveRoving:
    """See module doc. Fixed sensors give one value per sample (their ``source.axis``), roving sensors
    three (their own frame); all sensors share one sample clock (the references')."""

    def __init__(self, spec: StructureSpec, config: RovingConfig | None = None,
                 advice: AdviceConfig | None = None) -> None:
        if not spec.roving or not spec.measurement_points:
            raise InputError(f"structure {spec.name!r}: no roving sensor or no measurement points")
        self.spec, self.config, self.advice = spec, config or RovingConfig(), advice or AdviceConfig()
        self.buffer = TransformBuffer(cache_s=None)
        self.streams = {s.id: _Stream() for s in list(spec.sensors) + list(spec.roving)}
        self.references = [s.id for s in spec.sensors]
        self.nominal = nominal_frequencies(spec, self.advice.n_modes)
        model = spec.model_kind.build(spec)
        shapes = model.modes(n_modes=self.advice.n_modes).shapes
        at = {s.id: s.at for s in spec.sensors} | {p.id: p.at for p in spec.measurement_points}
        self._rows = {k: np.asarray(model.location_row(a)) @ shapes for k, a in at.items()}
        self.finished: list[ModalEstimate] = []  # the estimates of the setups the robot has left
        self.visited: list[str] = []
        self._point = ""
        self._since = 0
        self._names: list[str] = []
        self._history: list[list[float]] = []
        self._last: PointAdvice | None = None

    # -- input ------------------------------------------------------------------------------------
    def add_transform(self, parent: str, child: str, stamp_ns: int, translation, rotation,
                      static: bool = False) -> None:
        self.buffer.set_transform(parent, child, stamp_ns, translation, rotation, static=static)

    def add_samples(self, sensor_id: str, times_ns: np.ndarray, values: np.ndarray) -> None:
        if sensor_id not in self.streams:
            raise InputError(f"sensor {sensor_id!r} is not in structure {self.spec.name!r}")
        self.streams[sensor_id].add(times_ns, values)

    @property
    def samples(self) -> int:
        """Samples every sensor has delivered."""
        return min(s.n for s in self.streams.values())

    def aligned(self) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
        n = self.samples
        t0, _ = self.streams[self.references[0]].arrays()
        refs = {r: self.streams[r].arrays()[1][:n] for r in self.references}
        rov = {s.id: self.streams[s.id].arrays()[1][:n].reshape(n, 3) for s in self.spec.roving}
        if t0.size < n:
            raise InputError(f"reference {self.references[0]!r}: fewer stamps than samples")
        return t0[:n], refs, rov

    @property
    def sample_rate_hz(self) -> float:
        t, _ = self.streams[self.references[0]].arrays()
        if t.size < 2:
            raise InputError("fewer than two samples: no sample rate yet")
        return 1e9 / float(np.median(np.diff(t)))

    # -- the robot's setup ------------------------------------------------------------------------
    def start(self, point_id: str, since_ns: int = 0) -> None:
        """The robot stands at ``point_id`` from the sample stamped ``since_ns`` on (0: from the newest
        sample on); its previous setup is finished."""
        if point_id not in {p.id for p in self.spec.measurement_points}:
            raise InputError(f"point {point_id!r} is not a measurement point of structure {self.spec.name!r}")
        self.finish()
        self._point, self._history = point_id, []
        self._since = since_ns or (int(self.aligned()[0][-1]) + 1 if self.samples else 0)

    def recorded_s(self) -> float:
        """Seconds of samples since the robot's ``since`` (moving ones included)."""
        times = self.aligned()[0]
        if times.size < 2:
            return 0.0
        return int(np.sum(times >= self._since)) / self.sample_rate_hz

    def finish(self) -> None:
        """The robot leaves its point: the setup's last estimate joins the finished ones."""
        if self._last is not None and self._last.estimate is not None:
            self.finished.append(self._last.estimate)
            self.visited.append(self._last.point_id)
        self._last, self._point = None, ""

    def advise(self) -> PointAdvice:
        """Is the current setup enough, and (if so) where next (see module doc)."""
        if not self._point:
            raise InputError("no point: the robot has not said where it stands")
        p, a = self._point, self.advice
        y, fs = self._setup_data()
        recorded = 0.0 if y is None else y.shape[0] / fs
        n = a.n_modes
        if y is None or recorded < a.min_setup_s:
            out = PointAdvice(p, recorded, False, [f"{recorded:.1f} s recorded at {p} (needs >= {a.min_setup_s:g} s "
                                                   "before a first estimate)"], [np.nan] * n, [np.nan] * n)
            self._last = out
            return out
        est = identify_prepared(prepare_setup(y, self._names, len(self.references), fs, self.config)[1],
                                replace(self.config.identify, reference_channels=self.references,
                                        nominal_frequencies_hz=self.config.identify.nominal_frequencies_hz
                                        or nominal_frequencies(self.spec, 6))).estimate
        modes = merge_post(self.finished + [est], self.references)
        freqs, stds = [], []
        for g in self._interest(modes):
            freqs.append(np.nan if g is None else g.frequency_hz)
            stds.append(np.nan if g is None else self._point_std(g, y, fs))
        self._history.append(freqs)
        hist = [[h[m] for h in self._history if np.isfinite(h[m])] for m in range(n)]
        verdict = setup_enough(stds, hist, a.shape_std_max, a.frequency_tol, a.n_stable)
        out = PointAdvice(p, recorded, verdict.enough, verdict.reasons, freqs, stds, estimate=est)
        if verdict.enough:
            self._suggest(out)
        self._last = out
        return out

    def _setup_data(self) -> tuple[np.ndarray | None, float]:
        times, refs, rov = self.aligned()
        start = int(np.searchsorted(times, self._since))
        times = times[start:]
        if times.size < 2:
            return None, 1.0
        fs = self.sample_rate_hz
        tracks, along = [], {}
        for s in self.spec.roving:
            tr = sensor_track(self.buffer, self.spec.frame, s, times, rov[s.id][start:])
            assert tr.acceleration is not None
            tracks.append(tr)
            along[s.id] = tr.acceleration[:, AXIS[s.direction]] * s.source.sign
        cut = cut_setups(tracks, self.spec.measurement_points, self.config.tolerance_m, 0.0, self.config.filter_s)
        mine = [s for s in cut.setups if s.points[self.spec.roving[0].id] == self._point]
        if not mine:
            return None, fs
        setup = max(mine, key=lambda s: s.samples)
        y, self._names = setup_channels(setup, {r: v[start:] for r, v in refs.items()}, along)
        return y, fs

    def _interest(self, modes: list[GlobalMode]) -> list[GlobalMode | None]:
        """The global mode that is each mode of interest: one optimal assignment on the frequency's
        distance from the nominal one (within ``frequency_match``) and the MAC against the nominal
        model over every component the mode has (the references, the points visited and this one: a
        torsion mode beside a bending mode can look like it at two references, rarely along the whole
        deck; at least ``nominal.MIN_MAC``, so a mode this survey has not found yet stays unassigned
        rather than taken by its neighbour). Every global mode takes part, those this setup has not
        found too: the point's shape std comes from the transmissibility, which needs no pick here,
        and a mode found in the earlier setups is not replaced by a neighbour while this one has yet
        to show it."""
        cands = list(modes)
        if not cands:
            return [None] * len(self.nominal)
        df = np.abs(np.array([g.frequency_hz for g in cands])[None, :] / np.array(self.nominal)[:, None] - 1)
        m = np.ones(df.shape)
        for c, g in enumerate(cands):
            ids = [k for k, v in g.shape.items() if k in self._rows and np.isfinite(v)]
            if len(ids) > 1:
                m[:, c] = mac(g.vector(ids)[None, :], self.rows(ids).T)
        ok = (df <= self.advice.frequency_match) & (m >= MIN_MAC)
        rows, cols = linear_sum_assignment(np.where(ok, df / self.advice.frequency_match + (1 - m), 1e6))
        out: list[GlobalMode | None] = [None] * len(self.nominal)
        for r, c in zip(rows, cols, strict=True):
            if ok[r, c]:
                out[r] = cands[c]
        return out

    def _point_std(self, g: GlobalMode, y: np.ndarray, fs: float) -> float:
        """The point's shape std of mode ``g`` (module doc): transmissibility error and merge std."""
        nper = int(round(self.advice.segment_s * fs))
        if y.shape[0] < self.advice.min_segments * nper:
            return float("nan")
        ref = np.array([g.shape[r] for r in self.references])
        _, err = roving_components(y[:, :len(self.references) + 1], fs, len(self.references), g.frequency_hz,
                                   g.damping_ratio, ref, segment_s=self.advice.segment_s)
        std_m = g.shape_std.get(self._point, np.nan)
        return float(np.hypot(err[0], std_m if np.isfinite(std_m) else 0.0))

    def measured_and_candidates(self) -> tuple[list[str], list[str]]:
        """The references and visited points (this one included), and the points not visited yet."""
        done = set(self.visited) | {self._point}
        return (self.references + [p for p in self.visited if p != self._point] + [self._point],
                [p.id for p in self.spec.measurement_points if p.id not in done])

    def rows(self, ids: list[str]) -> np.ndarray:
        """Nominal shapes of the modes of interest at ``ids`` (sensors or points), (len(ids), n_modes)."""
        return np.array([self._rows[i] for i in ids]).reshape(len(ids), self.advice.n_modes)

    @property
    def noise_std(self) -> float:
        """Measurement error of one shape row in :func:`next_point`: the std the setups are recorded
        to, on the nominal shapes' scale (largest component over the points and references)."""
        return self.advice.shape_std_max * float(np.max(np.abs(np.array(list(self._rows.values())))))

    def _suggest(self, out: PointAdvice) -> None:
        measured, cands = self.measured_and_candidates()
        if not cands:
            return
        best, red = next_point(self.rows(measured), self.rows(cands), self.noise_std)
        out.next_point_id, out.expected_reduction = cands[best], float(red[best])
        pos = next(p.position for p in self.spec.measurement_points if p.id == cands[best])
        out.next_position = None if pos is None else (float(pos[0]), float(pos[1]), float(pos[2]))

    # -- global modes -----------------------------------------------------------------------------
    def result(self) -> RovingResult:
        """The offline pipeline on everything received (see module doc)."""
        times, refs, rov = self.aligned()
        return roving_modes(self.spec, times, self.sample_rate_hz, refs, rov, self.buffer, self.config)
