"""Event records for the time-domain path of explain, and the model with per-event factors.

At the per-event resolution a time-domain candidate changes the model per event (an earthquake
record; within an event, per segment: :func:`segment_amplitudes`, :mod:`.td_varying`): the
existing amplitude candidates (:mod:`.candidates.amplitude_stiffness`, :mod:`.candidates.amplitude_damping`)
already turn one covariate value per "window" into a factor, so an event plays the part of a window.
:class:`FactorModel` is the structure's analysis model with two more parameters appended,

    K = s K(theta),    C = d C_inherent(theta at s = 1) + g (2 zeta_1 / omega_1) K(theta) + C_dampers,

``s`` a factor on every story's stiffness (the ``EI`` group of a shear building, which is all of
its K), ``d`` a factor on the inherent (Rayleigh / modal) damping and ``g`` an added
stiffness-proportional damping (dashpots beside the story springs, as friction or cracking in the
stories adds), scaled so that ``g`` is the first mode's added damping ratio in units of its inherent
one (``zeta_1``, ``omega_1`` of the unsoftened model at ``theta``): a mode ``j`` gains
``g zeta_1 omega_j / omega_1``. ``g`` is 0 in the nominal model. The inherent damping matrix is
the one of the unsoftened model: a softening spring leaves its dashpot alone, as in the simulator's
truth. The damper braces' dashpots are not scaled (their own law, not the structure's damping).
Rows ``[theta, r, s, d, g]`` (``r`` the damping shape, :data:`SHAPE_NAME`) go through the shared response code
(:func:`shm_ros.core.response.batch.batch_responses`), so a batch of parameter sets is one batched
discretisation per event.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import eigh
from scipy.ndimage import uniform_filter1d

from shm_ros.core.bayes.timedomain import AccelerationRecord
from shm_ros.core.models.base import AffineModel, generalized_modes_batch
from shm_ros.core.predict.config import Baseline
from shm_ros.core.predict.record import EventRecord
from shm_ros.core.predict.signals import baseline_correct, pre_event_end, strong_motion
from shm_ros.errors import InputError, NoWindowsError

from .fit_ratio import pre_event_noise_nrms

FACTOR_NAMES = ("_stiffness_factor", "_damping_factor", "_added_damping")
SHAPE_NAME = "_damping_shape"
SHAPE_RANGE = (0.25, 4.0)  # log-uniform prior of the damping shape (a nuisance of every model compared)


def shape_logprior(r: np.ndarray) -> np.ndarray:
    """Log-uniform density of the damping shape on :data:`SHAPE_RANGE` (-inf outside)."""
    r = np.asarray(r, float)
    lo, hi = SHAPE_RANGE
    ok = (r >= lo) & (r <= hi)
    return np.where(ok, -np.log(np.where(ok, r, 1.0)) - math.log(math.log(hi / lo)), -np.inf)


@dataclass
class FactorModel(AffineModel):
    """``model`` with :data:`SHAPE_NAME` and :data:`FACTOR_NAMES` appended to its parameters (module doc).

    The damping shape ``r`` multiplies every damping ratio of the file after the first (Rayleigh: the
    second anchor): a real structure's damping is not the file's in its spread over the modes either,
    and without this freedom a candidate that changes the damping within events gains hundreds of
    nats on a linear structure by trading damping between the first mode (ringing in the quiet tail)
    and the higher ones (in the strong motion). ``n_base`` counts the model's parameters and ``r``:
    the baseline every model compared shares."""

    n_base: int = 0

    @classmethod
    def of(cls, model: AffineModel) -> FactorModel:
        kw = {f.name: getattr(model, f.name) for f in dataclasses.fields(AffineModel)}
        kw["parameter_names"] = [*model.parameter_names, SHAPE_NAME, *FACTOR_NAMES]
        kw["K_terms"] = [*model.K_terms, None, None, None, None]
        kw["M_terms"] = [*model.M_terms, None, None, None, None]
        kw["damping_factors"] = [*model.damping_factors, [], [], [], []]
        kw["sensor_rows"] = dict(model.sensor_rows)
        return cls(**kw, n_base=model.n_parameters + 1)

    def nominal_theta(self) -> np.ndarray:
        th = np.ones(self.n_parameters)
        th[self.n_base + 2] = 0.0  # no added damping
        return th

    def damping_ratios_at(self, theta: np.ndarray | None = None) -> np.ndarray:
        th = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        z = AffineModel.damping_ratios_at(self, th)
        r = th[self.n_base - 1]
        return np.r_[z[:1], z[1:] * r] if z.size > 1 else np.r_[z, z * r]

    def damping_ratios_batch(self, thetas: np.ndarray) -> np.ndarray:
        th = self._thetas(thetas)
        z = AffineModel.damping_ratios_batch(self, th)
        r = th[:, self.n_base - 1, None]
        return np.column_stack([z[:, :1], z[:, 1:] * r]) if z.shape[1] > 1 else np.column_stack([z, z * r])

    def stiffness(self, theta: np.ndarray | None = None) -> np.ndarray:
        th = self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)
        return th[self.n_base] * AffineModel.stiffness(self, th)

    def stiffness_batch(self, thetas: np.ndarray) -> np.ndarray:
        th = self._thetas(thetas)
        return th[:, self.n_base, None, None] * AffineModel.stiffness_batch(self, th)

    def inherent_damping(self, theta: np.ndarray | None = None) -> np.ndarray:
        th = (self.nominal_theta() if theta is None else np.asarray(theta, dtype=float)).copy()
        d, g = th[self.n_base + 1], th[self.n_base + 2]
        th[self.n_base] = 1.0  # the dashpots of the unsoftened structure
        C = d * AffineModel.inherent_damping(self, th)
        if g != 0.0:
            K, M = AffineModel.stiffness(self, th), self.mass(th)
            w1 = math.sqrt(max(float(eigh(K, M, eigvals_only=True, subset_by_index=(0, 0))[0]), 1e-300))
            C = C + (g * 2.0 * float(self.damping_ratios_at(th)[0]) / w1) * K
        return C

    def inherent_damping_batch(self, thetas: np.ndarray) -> np.ndarray:
        th = self._thetas(thetas).copy()
        d, g = th[:, self.n_base + 1], th[:, self.n_base + 2]
        th[:, self.n_base] = 1.0  # the dashpots of the unsoftened structure
        C = d[:, None, None] * AffineModel.inherent_damping_batch(self, th)
        on = g != 0.0
        if np.any(on):
            K, M = AffineModel.stiffness_batch(self, th[on]), self.mass_batch(th[on])
            w1 = 2 * np.pi * np.maximum(generalized_modes_batch(K, M, 1).frequencies_hz[:, 0], 1e-150)
            z1 = self.damping_ratios_batch(th[on])[:, 0]
            C[on] += (g[on] * 2.0 * z1 / w1)[:, None, None] * K
        return C


@dataclass
class EventData:
    """Baseline-corrected event records on one set of channels, with per-event amplitude covariates."""

    window_ids: list[str]
    records: list[AccelerationRecord]
    covariates: dict[str, np.ndarray]  # pga_m_s2, rms_accel_m_s2: (E,)
    start_ns: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    noise_nrms: np.ndarray | None = None  # (E,) NRMS (%) the pre-event noise alone gives; NaN: none recorded


SEGMENT_S = 0.25  # within-event resolution: a fraction of a period of the modes that soften


def segment_amplitudes(records: list[AccelerationRecord], period_s: float,
                       segment_s: float = SEGMENT_S) -> tuple[list[np.ndarray], list[int]]:
    """Within each event, the local vibration amplitude per segment of ``segment_s``: the RMS of the
    measured outputs (mean square over channels) over a centred window of one ``period_s`` (a cycle of
    the first mode: a secant stiffness is a property of a cycle), then over the segment. Returns the
    (J_e,) amplitudes (m/s^2) and the samples per segment of every event."""
    amps, lens = [], []
    for r in records:
        n = r.outputs.shape[0]
        ms = uniform_filter1d(np.mean(r.outputs ** 2, axis=1), max(1, int(round(period_s / r.dt))), mode="nearest")
        L = max(1, int(round(segment_s / r.dt)))
        J = max(1, -(-n // L))
        pad = np.r_[ms, np.full(J * L - n, np.nan)].reshape(J, L)
        amps.append(np.sqrt(np.nanmean(pad, axis=1)))
        lens.append(L)
    return amps, lens


def _recorded(x: np.ndarray) -> bool:
    """Whether a channel's samples hold a record: finite values that vary."""
    x = x[np.isfinite(x)]
    return x.size > 1 and float(np.ptp(x)) > 0.0


def event_data(events: list[EventRecord], onset_arias: float = 0.001, min_pre_event_s: float = 1.0,
               baseline: Baseline | str = Baseline.MEAN) -> EventData:
    """Records for the joint likelihood (offsets removed as the prediction stage removes them,
    :mod:`shm_ros.core.predict.signals`) and each event's amplitude: the input's peak (``pga_m_s2``)
    and the RMS of the measured outputs over the input's strong motion (5-95 % of its Arias
    intensity), averaged over channels in the mean-square sense (``rms_accel_m_s2``)."""
    if not events:
        raise NoWindowsError("explain (time domain): no event records")
    ids = events[0].channel_ids
    recs, pga, rms, notes, noise = [], [], [], [], []
    for ev in events:
        if ev.channel_ids != ids:
            raise InputError(f"event {ev.window_id}: channels {ev.channel_ids} differ from the first event's {ids}")
    # a channel with no record in an event (no finite sample: a missing sensor; a constant value: a dead
    # one) is left out of every event
    empty = [c for c in range(len(ids)) if any(not _recorded(np.asarray(ev.outputs, float)[:, c]) for ev in events)]
    keep = [c for c in range(len(ids)) if c not in empty]
    if not keep:
        raise NoWindowsError("explain (time domain): no output channel has a record in every event")
    if empty:
        notes.append(f"channel(s) {[ids[c] for c in empty]} left out: no record in at least one event")
    ids = [ids[c] for c in keep]
    for ev in events:
        y = np.asarray(ev.outputs, dtype=float)[:, keep]
        if not np.all(np.isfinite(y)):
            keep = np.all(np.isfinite(y), axis=1)
            notes.append(f"event {ev.window_id}: {int(np.sum(~keep))} samples with missing outputs set to 0")
            y = np.where(np.isfinite(y), y, 0.0)
        n_pre = pre_event_end(ev.inputs[0], ev.fs, onset_arias, min_pre_event_s)
        u = baseline_correct(ev.inputs.T, n_pre, baseline).T
        y = baseline_correct(y, n_pre, baseline)
        recs.append(AccelerationRecord(1.0 / ev.fs, u, y, list(ids)))
        s = strong_motion(u[0])
        pga.append(float(np.max(np.abs(u[0]))))
        rms.append(float(np.sqrt(np.mean(y[s] ** 2))))
        noise.append(pre_event_noise_nrms(y, n_pre))
    return EventData([e.window_id for e in events], recs,
                     {"pga_m_s2": np.array(pga), "rms_accel_m_s2": np.array(rms)},
                     [int(e.start_ns) for e in events], notes, np.array(noise))
