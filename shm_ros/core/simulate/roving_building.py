"""A drone that perches on a building's floors with one accelerometer (``shm-ros simulate
building-roving``).

The truth is the simulator's building truth model (3-D floors with eccentric masses, scattered
properties, non-proportional damping: richer than the planar analysis model) under wind and
microtremor, with output at the fixed references and at every measurement point (a floor, at the
point's plan position). The drone visits the points in the order of the structure file: it perches
``dwell_s`` on each, then flies to the next at ``speed_m_s`` (climbing or descending the floors
between), its rotors shaking the sensor (a tone at ``rotor_hz`` and broadband buffeting of
``flight_rms_m_s2``). A perched drone of a few kilograms is 10^-5 of a floor's modal mass: its mass
is not simulated (the girder scenario's robot is, where it matters).

What the drone records: its sensor's three axes in its own frame, mounted as the structure file
says (a tilted perch), gravity included, stamped ``clock_offset_s`` late against the references;
``structure -> odom -> drone/base_link`` at ``tf_hz`` with ``localisation_noise_m`` noise, odometry
drifting 1 % of the distance flown and the localiser removing the drift once a second (REP-105
map -> odom jumps); the mount on ``/tf_static`` or only in the structure file. The truth: the
building's modes at every point and reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import scipy.signal as sig
from scipy.spatial.transform import Rotation

from shm_ros.core.delay import shift
from shm_ros.core.simulate.campaign import rng_for
from shm_ros.core.simulate.effects import Conditions
from shm_ros.core.simulate.roving import CarrierOptions, G, RovingRecording, _truth_structure, carried_sensor, tf_stream
from shm_ros.core.simulate.truth import ModalTruth, build_truth
from shm_ros.core.structure import StructureSpec

__all__ = ["DroneOptions", "simulate_building_roving"]

AXES = {"x": 0, "y": 1, "vertical": 2}


@dataclass
class DroneOptions(CarrierOptions):
    fs: float = 50.0
    rotor_hz: float = 18.0
    flight_rms_m_s2: float = 0.5
    noise_rms_m_s2: float = 1.0e-4
    wind_rms_n: float = 1.5e3
    microtremor_rms_m_s2: float = 5.0e-4
    warmup_s: float = 30.0


def simulate_building_roving(spec: StructureSpec, options: DroneOptions | None = None) -> RovingRecording:
    o = options or DroneOptions()
    sensor = carried_sensor(spec, "shear_building", "building-roving")
    if any(p.position is None for p in spec.measurement_points):
        raise ValueError("the building-roving scenario needs every measurement point's xyz")
    points = list(spec.measurement_points)
    tm = build_truth(_truth_structure(spec), [], rng_for(o.seed, 0), misplacement_std_m=0.0, fs=o.fs,
                     model_form=o.model_form)
    system, truth = tm.system({})
    col = {sid: k for k, sid in enumerate(tm.sensor_ids)}
    dt = 1.0 / o.fs
    n_dwell = int(round(o.dwell_s * o.fs))
    pos = [np.array(p.position, dtype=float) for p in points]
    n_fly = [int(round(np.linalg.norm(pos[k + 1] - pos[k]) / o.speed_m_s * o.fs)) for k in range(len(points) - 1)] + [0]
    n_all = len(points) * n_dwell + sum(n_fly)
    n_warm = int(round(o.warmup_s * o.fs))
    scenario = SimpleNamespace(fs=o.fs, wind_rms_n=o.wind_rms_n, microtremor_rms_m_s2=o.microtremor_rms_m_s2)
    u, _ = tm.loads(rng_for(o.seed, 100), n_all + n_warm, Conditions(t_s=0.0, temperature_c=17.0, local_hour=12.0),
                    scenario, system, None)
    y = system.simulate(u, dt)[n_warm:]  # absolute accelerations x, y, z at every sensor
    refs = [s.id for s in spec.sensors if s.id in col]
    ref_all = np.column_stack([y[:, 3 * col[r] + AXES.get(s.direction, 0)]
                               for r, s in ((s.id, s) for s in spec.sensors if s.id in col)])
    frng, nrng = rng_for(o.seed, 11), rng_for(o.seed, 12)
    rotor = sig.butter(2, [max(0.5, o.rotor_hz - 2.0), min(o.rotor_hz + 2.0, 0.45 * o.fs)], btype="bandpass",
                       fs=o.fs, output="sos")
    buffet = sig.butter(2, [1.0, 0.4 * o.fs], btype="bandpass", fs=o.fs, output="sos")
    acc = np.zeros((n_all, 3))
    where = np.zeros((n_all, 3))
    phases: list[tuple[str, float, float, str]] = []
    i = 0
    for k, p in enumerate(points):
        acc[i:i + n_dwell] = y[i:i + n_dwell, 3 * col[p.id]: 3 * col[p.id] + 3]
        where[i:i + n_dwell] = pos[k]
        phases.append(("dwell", i * dt, (i + n_dwell - 1) * dt, p.id))
        i += n_dwell
        if n_fly[k]:
            m = n_fly[k]
            e = frng.standard_normal((m, 3))
            acc[i:i + m] = o.flight_rms_m_s2 * (sig.sosfilt(rotor, e, axis=0) + sig.sosfilt(buffet, e[::-1], axis=0))
            where[i:i + m] = pos[k] + (pos[k + 1] - pos[k]) * (np.arange(1, m + 1) / m)[:, None]
            phases.append(("drive", i * dt, (i + m - 1) * dt, p.id))
            i += m
    acc[:, 2] += G
    rov = Rotation.from_quat(sensor.mount.rotation).inv().apply(acc)  # the sensor reads in its own (tilted) axes
    ref_all = ref_all + o.noise_rms_m_s2 * nrng.standard_normal(ref_all.shape)
    rov = rov + o.noise_rms_m_s2 * nrng.standard_normal(rov.shape)
    rov = shift(rov, o.fs, -o.clock_offset_s)  # stamped late by the offset
    times = np.round(np.arange(n_all) * dt * 1e9).astype(np.int64)
    tf, static = tf_stream(sensor, where, times, o, rng_for(o.seed, 13))
    truth_out = ModalTruth(truth.frequencies_hz, truth.damping_ratios, truth.shapes, list(truth.sensor_ids),
                           truth.families, truth.in_plane_family)
    return RovingRecording(spec, times, {r: ref_all[:, k] for k, r in enumerate(refs)}, {sensor.id: rov},
                           tf, static, truth_out, phases, o.clock_offset_s, {})
