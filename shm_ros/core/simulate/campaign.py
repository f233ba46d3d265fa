"""A monitoring campaign: windows of simulated recordings whose truth is known.

``simulate_campaign(scenario)`` is cheap: it builds the truth model, the sensor models, the
temperature record and the window schedule. Windows are produced one at a time by
:meth:`Campaign.window` (deterministic per window index, so an 8-day campaign never sits in memory
and any window can be recomputed alone). ``simulate_window`` is a one-call short-cut for tests.

Random streams: ``SeedSequence(seed, spawn_key=(stream, window))`` with streams 0 truth model,
1 sensors, 2 temperature, 3 loads of a window, 4 sensor noise of a window, 5 faults of a window,
6 the campaign's earthquake schedule.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import shm_ros.core.simulate.excitation as ex
from shm_ros.core.simulate.effects import Conditions, Effect, EffectError, make_effect
from shm_ros.core.simulate.linear import ModalSystem
from shm_ros.core.simulate.scenario import Scenario, named_scenario
from shm_ros.core.simulate.sensors import AXES, Recording, SensorModel, apply_faults
from shm_ros.core.simulate.truth import ModalTruth, TruthModel, WindowRun, build_truth
from shm_ros.core.simulate.truth_kinds import TRUTH_KINDS
from shm_ros.core.types import Window

AMPLITUDE_EFFECTS = ("amplitude_stiffness", "amplitude_damping")


def rng_for(seed: int, stream: int, index: int = 0) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(stream, index)))


@dataclass
class SimulatedWindow:
    """One simulated burst: true accelerations, what the sensors recorded, and the truth."""

    index: int
    start_ns: int
    fs: float
    sensor_ids: list[str]
    accel: np.ndarray  # (n, n_sensors) true absolute accelerations, m/s^2
    recording: Recording  # sensor readings (gravity, offsets, noise, faults)
    truth: dict[str, Any]  # the window's entry of truth.json

    def to_window(self) -> Window:
        """The recorded samples as a clean :class:`~shm_ros.core.types.Window` (faults that change
        stamps are ignored here; use the bag for those)."""
        return Window(window_id=f"w{self.index:05d}", start_ns=self.start_ns, sample_rate_hz=self.fs,
                      channel_names=list(self.sensor_ids), samples=self.recording.values.copy(),
                      temperature_c=self.truth.get("temperature_measured_c"),
                      is_event=bool(self.truth.get("event")),
                      pga_m_s2=float((self.truth.get("event") or {}).get("pga_m_s2", 0.0)),
                      input_channel=self.truth.get("input_sensor"))


@dataclass
class Campaign:
    scenario: Scenario
    effects: list[Effect]
    truth_model: TruthModel
    sensors: list[SensorModel]
    temperature_stamps_ns: np.ndarray
    temperature_true_c: np.ndarray
    temperature_measured_c: np.ndarray
    window_starts_ns: np.ndarray
    earthquakes: dict[int, dict[str, float]] = field(default_factory=dict)
    _model_form: dict[str, Any] | None = field(default=None, repr=False)

    @property
    def n_windows(self) -> int:
        return int(self.window_starts_ns.size)

    @property
    def nominal_structure(self) -> dict[str, Any]:
        """The nominal structure file's mapping: what the scenario says, no hidden effect."""
        return self.truth_model.nominal.to_dict()

    @property
    def sensor_ids(self) -> list[str]:
        return list(self.truth_model.sensor_ids)

    def window_bounds_ns(self, i: int) -> tuple[int, int]:
        n = int(round(self.scenario.window_s * self.scenario.fs))
        start = int(self.window_starts_ns[i])
        return start, start + int(round(n * 1e9 / self.scenario.fs))

    def conditions(self, i: int) -> Conditions:
        sc = self.scenario
        start, end = self.window_bounds_ns(i)
        inside = (self.temperature_stamps_ns >= start) & (self.temperature_stamps_ns < end)
        temp = float(np.mean(self.temperature_true_c[inside])) if np.any(inside) else float(
            np.interp(0.5 * (start + end), self.temperature_stamps_ns, self.temperature_true_c))
        t_mid = 0.5 * (start + end) / 1e9 - sc.start_epoch_s
        local = ((0.5 * (start + end) / 1e9 + sc.utc_offset_h * 3600.0) % 86400.0) / 3600.0
        return Conditions(t_s=t_mid, temperature_c=temp, local_hour=local)

    def factors(self, i: int) -> dict[str, float]:
        c = self.conditions(i)
        out: dict[str, float] = {}
        for e in self.effects:
            for g, f in e.factors(c).items():
                out[g] = out.get(g, 1.0) * f
        return out

    def measured_temperature(self, i: int) -> float | None:
        start, end = self.window_bounds_ns(i)
        inside = (self.temperature_stamps_ns >= start) & (self.temperature_stamps_ns < end)
        return float(np.mean(self.temperature_measured_c[inside])) if np.any(inside) else None

    # -- one window ---------------------------------------------------------------------------
    def window(self, i: int, with_idle_axes: bool | None = None) -> SimulatedWindow:
        """Window ``i``: the same numbers whoever calls it (BLAS runs on one thread here, since
        a threaded BLAS may round matrix products differently)."""
        with single_blas_thread():
            return self._window(i, with_idle_axes)

    def _window(self, i: int, with_idle_axes: bool | None) -> SimulatedWindow:
        sc = self.scenario
        if not 0 <= i < self.n_windows:
            raise IndexError(f"window {i} out of range (campaign has {self.n_windows})")
        cond = self.conditions(i)
        factors = self.factors(i)
        n = int(round(sc.window_s * sc.fs))
        dt = 1.0 / sc.fs
        rng = rng_for(sc.seed, 3, i)
        amp = [e for e in self.effects if e.key in AMPLITUDE_EFFECTS]
        sys, modal = self.truth_model.system(factors)
        slow = float(np.min(-sys.poles.real[sys.conjugate])) if np.any(sys.conjugate) else 1.0
        n_warm = int(round(min(120.0, max(10.0, 5.0 / slow)) * sc.fs))
        u, event = self._inputs(rng, n_warm + n, cond, i, sys)

        def inputs_for(other: ModalSystem) -> np.ndarray:  # the same draws of loads, for another system
            return self._inputs(rng_for(sc.seed, 3, i), n_warm + n, cond, i, other)[0]

        y, modal, extra = self.truth_model.respond(WindowRun(factors=factors, amplitude_effects=amp, system=sys,
                                                             modal=modal, inputs=u, dt=dt, n_warm=n_warm,
                                                             inputs_for=inputs_for))
        xyz = y[n_warm:].reshape(n, len(self.sensors), 3)  # x, y, z of the structure at every sensor
        accel = np.ascontiguousarray(np.column_stack([xyz[:, c, AXES.index(s.frame_axis)]
                                                      for c, s in enumerate(self.sensors)]))
        start, end = self.window_bounds_ns(i)
        stamps = start + np.round(np.arange(n) * (1e9 / sc.fs)).astype(np.int64)
        nrng = rng_for(sc.seed, 4, i)
        values = np.column_stack([s.measure(nrng, xyz[:, c]) for c, s in enumerate(self.sensors)])
        idle = None
        if with_idle_axes if with_idle_axes is not None else sc.output == "imu":
            idle = np.stack([s.idle_axes(nrng, n) for s in self.sensors], axis=1)
        rec = Recording(sensor_ids=self.sensor_ids, axes=[s.axis for s in self.sensors], stamps_ns=stamps,
                        values=values, idle=idle)
        faults = [f for f in sc.faults if f.window == i]
        done = (apply_faults(rec, faults, sc.fs, rng_for(sc.seed, 5, i), block_level=sc.output == "block")
                if faults else [])
        truth = self._truth_entry(i, start, end, cond, factors, modal, accel, event, done, extra)
        return SimulatedWindow(index=i, start_ns=start, fs=sc.fs, sensor_ids=self.sensor_ids, accel=accel,
                               recording=rec, truth=truth)

    def windows(self, indices: list[int] | None = None) -> Iterator[SimulatedWindow]:
        for i in indices if indices is not None else range(self.n_windows):
            yield self.window(i)

    def _inputs(self, rng: np.random.Generator, n: int, cond: Conditions, i: int,
                sys: ModalSystem | None = None) -> tuple[np.ndarray, dict | None]:
        """Inputs of a window (``TruthModel.loads``) and its earthquake, if any."""
        return self.truth_model.loads(rng, n, cond, self.scenario, sys, self.earthquakes.get(i))

    def _truth_entry(self, i, start, end, cond, factors, modal: ModalTruth, accel, event, faults, extra) -> dict:
        shapes = {sid: modal.shapes[r].round(6).tolist() for r, sid in enumerate(modal.sensor_ids)}
        entry = {
            "index": i, "start_ns": start, "end_ns": end,
            "start": _iso(start), "end": _iso(end),
            "temperature_c": round(cond.temperature_c, 4),
            "temperature_measured_c": _r(self.measured_temperature(i), 4),
            "local_hour": round(cond.local_hour, 4),
            "frequencies_hz": [float(f) for f in modal.frequencies_hz],
            "mode_families": list(modal.families),
            "damping_ratios": [float(z) for z in modal.damping_ratios],
            "mode_shapes": shapes,
            "effect_factors": {k: float(v) for k, v in sorted(factors.items())},
            "rms_accel_m_s2": {sid: float(np.sqrt(np.mean(accel[:, c] ** 2))) for c, sid in enumerate(self.sensor_ids)},
            "event": event,
            "faults": faults,
        }
        if self.truth_model.nominal.input_sensor:
            entry["input_sensor"] = self.truth_model.nominal.input_sensor
        entry.update(extra)
        return entry

    # -- the whole campaign's truth -----------------------------------------------------------
    def truth_header(self) -> dict[str, Any]:
        sc, tm = self.scenario, self.truth_model
        return {
            "scenario": sc.name,
            "seed": sc.seed,
            "kind": tm.kind,
            "structure_name": tm.nominal.name,
            "sample_rate_hz": sc.fs,
            "window_s": sc.window_s,
            "pause_s": sc.pause_s,
            "n_windows": self.n_windows,
            "sensor_ids": self.sensor_ids,
            "hidden_effects": [e.describe() for e in self.effects],
            "faults": [vars(f) for f in sc.faults],
            "truth_model": self.truth_model_summary(),
            "model_form": self.model_form_report(),
            "sensors": [{"id": s.sensor_id, "axis": s.axis, "gain": s.gain, "offsets_m_s2": list(s.offsets),
                         "gravity_axis": s.gravity_axis, "noise_rms_m_s2": s.noise_rms, "lsb_m_s2": s.lsb,
                         "full_scale_m_s2": s.full_scale, "misalignment_deg": s.misalignment_deg,
                         "cross_axis": list(s.cross_axis),
                         "sensitivity_xyz": None if s.sensitivity is None else list(s.sensitivity)}
                        for s in self.sensors],
            "temperature_sensor": {"id": "t1", "period_s": sc.temperature_period_s},
            "earthquakes": {str(k): v for k, v in sorted(self.earthquakes.items())},
        }

    def model_form_report(self) -> dict[str, Any]:
        """What the best-fitting analysis model misses of the truth at reference conditions
        (:func:`shm_ros.core.simulate.model_form.model_form_report`), computed once."""
        if self._model_form is None:
            from shm_ros.core.simulate.model_form import model_form_report

            self._model_form = model_form_report(self.truth_model).to_dict()
        return self._model_form

    def truth_model_summary(self) -> dict[str, Any]:
        tm = self.truth_model
        out: dict[str, Any] = {"n_dof": tm.model.n_dof, "structure": tm.spec.to_dict()}
        out.update(tm.summary())
        return out


def single_blas_thread() -> contextlib.AbstractContextManager:
    """One BLAS thread (``threadpoolctl``) for reproducible products and fast small eigenproblems."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - pinned in requirements/base.txt
        return contextlib.nullcontext()
    return threadpool_limits(1)


def _iso(t_ns: int) -> str:
    from datetime import datetime, timezone

    return datetime.fromtimestamp(t_ns / 1e9, tz=timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _r(v: float | None, nd: int) -> float | None:
    return None if v is None else round(v, nd)


def simulate_campaign(scenario: Scenario) -> Campaign:
    """Plan a campaign: truth model, sensors, temperature record and window schedule."""
    sc = scenario
    if sc.fs <= 0 or sc.window_s <= 0 or sc.n_windows < 1:
        raise ValueError("scenario: fs, window_s must be > 0 and n_windows >= 1")
    if sc.pause_s <= 1.0 and sc.n_windows > 1:
        raise ValueError("scenario: pause_s must exceed 1 s so that each burst is one window")
    if sc.output not in ("block", "imu"):
        raise ValueError(f"scenario: output {sc.output!r} (block or imu)")
    kind = sc.structure.get("kind", sc.kind)
    effects = [make_effect(r.key, kind, r.params, sc.start_epoch_s) for r in sc.effects]
    keys = [e.key for e in effects]
    if len(set(keys)) != len(keys):
        raise EffectError(f"scenario: an effect is listed twice ({', '.join(keys)})")
    if sum(k.startswith("temperature") for k in keys) > 1:
        raise EffectError("scenario: choose one of temperature_linear and temperature_bilinear")
    if any(k in AMPLITUDE_EFFECTS for k in keys):
        dmp = next((e for e in effects if e.key == "damper"), None)
        if dmp is not None and dmp.params["model"] == "maxwell":
            raise EffectError("scenario: amplitude-dependent effects work with kelvin_voigt dampers only")
    truth = build_truth(sc.structure, effects, rng_for(sc.seed, 0), refine=sc.refine, scatter=sc.property_scatter,
                        misplacement_std_m=sc.misplacement_std_m, damping_range=sc.truth_damping,
                        n_truth_modes=sc.n_truth_modes, fs=sc.fs, model_form=sc.model_form,
                        eccentricity=None if sc.eccentricity is None else (float(sc.eccentricity[0]),
                                                                            float(sc.eccentricity[1])))
    srng = rng_for(sc.seed, 1)
    sensors = []
    for sid in truth.sensor_ids:
        s = truth.nominal.sensor(sid)
        frame = {"vertical": "z", "x": "x", "y": "y"}.get(s.direction, s.source.axis)
        sensors.append(SensorModel.draw(srng, sid, s.source.axis, noise_rms=sc.noise_rms_m_s2,
                                        imperfect=sc.model_form, frame_axis=frame))
    interval_ns = int(round(sc.interval_s * 1e9))
    start_ns = int(round(sc.start_epoch_s * 1e9))
    starts = start_ns + interval_ns * np.arange(sc.n_windows, dtype=np.int64)
    period_ns = int(round(sc.temperature_period_s * 1e9))
    t_end = starts[-1] + int(round(sc.window_s * 1e9))
    tstamps = np.arange(start_ns, t_end + period_ns, period_ns, dtype=np.int64)
    trng = rng_for(sc.seed, 2)
    local_s = (tstamps - start_ns) / 1e9 + sc.start_epoch_s % 86400.0 + sc.utc_offset_h * 3600.0
    true_t = ex.temperature_series(trng, local_s, sc.t_mean_c, sc.t_daily_c, sc.t_drift_c)
    t_offset = 0.2 * float(trng.standard_normal())
    measured_t = np.round(true_t + t_offset + 0.05 * trng.standard_normal(true_t.size), 2)
    quakes: dict[int, dict[str, float]] = {}
    qrng = rng_for(sc.seed, 6)
    if sc.earthquake_every_window:
        for i in range(sc.n_windows):
            quakes[i] = {"pga_m_s2": float(qrng.uniform(*sc.pga_range_m_s2)),
                         "onset_s": float(qrng.uniform(0.2, 0.4) * sc.window_s)}
    for q in sc.earthquakes:
        i = int(q["window"])
        quakes[i] = {"pga_m_s2": float(q.get("pga_m_s2", 1.0)), "onset_s": float(q.get("onset_s", 0.3 * sc.window_s))}
    if quakes and not truth.supports_earthquakes:
        able = [c.name for c in TRUTH_KINDS if c.supports_earthquakes]
        raise ValueError(f"scenario: earthquakes need a structure with a base input ({', '.join(able)})")
    return Campaign(scenario=sc, effects=effects, truth_model=truth, sensors=sensors,
                    temperature_stamps_ns=tstamps, temperature_true_c=true_t, temperature_measured_c=measured_t,
                    window_starts_ns=starts, earthquakes=quakes)


def simulate_window(name: str = "girder", *, duration_s: float = 60.0, fs: float = 100.0, seed: int = 0,
                    temperature_c: float | None = None, effects: list[tuple[str, dict]] | None = None,
                    **options: Any) -> SimulatedWindow:
    """One window of a named scenario, for unit tests of other stages.

    ``temperature_c`` fixes the air temperature (no daily cycle); ``effects`` are (key, params) pairs.
    """
    from shm_ros.core.simulate.scenario import EffectRequest

    sc = named_scenario(name, n_windows=1, window_s=duration_s, fs=fs, seed=seed, **options)
    if temperature_c is not None:
        sc.t_mean_c, sc.t_daily_c, sc.t_drift_c = float(temperature_c), 0.0, 0.0
    sc.effects = [EffectRequest(k, dict(p)) for k, p in (effects or [])]
    return simulate_campaign(sc).window(0)
