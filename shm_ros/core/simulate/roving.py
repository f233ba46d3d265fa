"""A robot carrying one accelerometer along a girder (``shm-ros simulate girder-roving``).

The truth is the simulator's girder truth model (finer mesh, Timoshenko deck with torsion and
lateral families, scattered properties: richer than the analysis model) with output at the two fixed
references and at every measurement point. The robot visits the points in order of x: at each it
dwells ``dwell_s`` while its mass (``robot_mass_kg``, on the deck's vertical DOF nearest to it) is part
of the structure, then drives to the next point at ``speed_m_s`` with its ride vibration on the
sensor. Each stop is simulated as its own linear system under traffic and wind (the response does
not run on across stops: the drive samples between them are excluded anyway).

What the robot records: its sensor's three axes in its own frame, mounted pitched by
``mount_pitch_deg`` (gravity included), stamped ``clock_offset_s`` late against the references;
``structure -> odom -> rover/base_link`` at ``tf_hz`` with ``localisation_noise_m`` noise, odometry
drifting 1 % of the distance driven and the localiser removing the drift once a second (REP-105
map -> odom jumps); the mount ``rover/base_link -> rover/accel_link`` on ``/tf_static`` or only in the
structure file. The truth: the modes of the structure without the robot at every point and reference.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
import scipy.signal as sig
from scipy.spatial.transform import Rotation

from shm_ros.core.delay import shift
from shm_ros.core.simulate.campaign import rng_for
from shm_ros.core.simulate.effects import Conditions
from shm_ros.core.simulate.truth import ModalTruth, build_truth
from shm_ros.core.structure import StructureSpec

__all__ = ["CarrierOptions", "RovingOptions", "RovingRecording", "simulate_roving", "TfSample", "G", "tf_stream"]

G = 9.81
IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)
DECK_Z = 0.3  # the girder robot's sensor height above the deck axis (m)


@dataclass
class CarrierOptions:
    """What a roving scenario's carrier (a robot, a drone) and its recording share."""

    seed: int = 0
    fs: float = 100.0
    dwell_s: float = 120.0
    speed_m_s: float = 1.0
    clock_offset_s: float = 0.012
    tf_hz: float = 10.0
    localisation_noise_m: float = 0.02
    noise_rms_m_s2: float = 2.0e-4
    model_form: bool = True
    tf_static: bool = False  # publish the mount on /tf_static (else only the structure file has it)
    warmup_s: float = 20.0


@dataclass
class RovingOptions(CarrierOptions):
    robot_mass_kg: float = 2000.0
    mount_pitch_deg: float = 20.0
    ride_rms_m_s2: float = 0.5
    n_points: int | None = None  # the first N measurement points (by x); None: all
    refine: int = 2  # truth elements per nominal element


@dataclass(frozen=True)
class TfSample:
    parent: str
    child: str
    stamp_ns: int
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


@dataclass
class RovingRecording:
    """What the bag holds (as arrays) and the truth."""

    spec: StructureSpec
    times_ns: np.ndarray
    references: dict[str, np.ndarray]  # fixed sensor id -> vertical acceleration (n,)
    roving: dict[str, np.ndarray]  # roving sensor id -> (n, 3) accelerations in its own frame
    tf: list[TfSample]
    tf_static: list[TfSample]
    truth: ModalTruth  # without the robot, over references + points
    phases: list[tuple[str, float, float, str]]  # (dwell|drive, t0, t1, point id)
    clock_offset_s: float
    robot_modal_mass_fraction: dict[str, float] = field(default_factory=dict)  # point -> mode 1


def _truth_structure(spec: StructureSpec) -> dict[str, Any]:
    """The structure mapping for the truth: the roving sensor's points as fixed sensors along its
    direction."""
    d = copy.deepcopy(spec.raw)
    d.pop("frame", None)
    d.pop("measurement_points", None)
    direction = spec.roving[0].direction if spec.roving else "vertical"
    d["sensors"] = [s for s in d["sensors"] if not s.get("roving", False)] + [
        {"id": p.id, "at": dict(p.at), "direction": direction} for p in spec.measurement_points]
    d.pop("parameters", None)
    return d


def carried_sensor(spec: StructureSpec, kind: str, scenario: str):
    """The one roving sensor of a ``kind`` structure file, with its mount (the scenarios need both)."""
    if spec.kind != kind or len(spec.roving) != 1:
        raise ValueError(f"the {scenario} scenario needs a {kind} structure file with one roving sensor")
    sensor = spec.roving[0]
    if sensor.mount is None:
        raise ValueError(f"roving sensor {sensor.id!r}: the scenario needs its mount in the structure file")
    return sensor


def simulate_roving(spec: StructureSpec, options: RovingOptions | None = None) -> RovingRecording:
    o = options or RovingOptions()
    sensor = carried_sensor(spec, "girder", "girder-roving")
    points = sorted(spec.measurement_points, key=lambda p: float(p.at["x"]))[: o.n_points]
    tm = build_truth(_truth_structure(spec), [], rng_for(o.seed, 0), refine=o.refine, misplacement_std_m=0.0,
                     fs=o.fs, model_form=o.model_form)
    _, truth = tm.system({})
    refs = [s.id for s in spec.sensors]
    col = {sid: k for k, sid in enumerate(tm.sensor_ids)}
    node_x = np.asarray(tm.model.node_x)
    m0 = tm.model.M0.copy()
    dt = 1.0 / o.fs
    n_dwell = int(round(o.dwell_s * o.fs))
    n_warm = int(round(o.warmup_s * o.fs))
    lrng, nrng = rng_for(o.seed, 11), rng_for(o.seed, 12)
    scenario = SimpleNamespace(fs=o.fs, vehicles_per_hour=400.0, wind_rms_n=1.0e2)
    r_mount = Rotation.from_quat(sensor.mount.rotation)
    ref_parts: list[np.ndarray] = []
    rov_parts: list[np.ndarray] = []
    phases: list[tuple[str, float, float, str]] = []
    x_parts: list[np.ndarray] = []
    fractions: dict[str, float] = {}
    sol = tm.model.modes(n_modes=1)  # mode 1 without the robot: the robot's share of its modal mass
    v1 = sol.shapes[:, 0]
    m1 = float(v1 @ tm.model.mass() @ v1)
    t = 0.0
    ride = sig.butter(2, [2.0, 20.0], btype="bandpass", fs=o.fs, output="sos")
    for k, p in enumerate(points):
        x = float(p.at["x"])
        n_drive = 0 if k + 1 == len(points) else int(round(abs(float(points[k + 1].at["x"]) - x) / o.speed_m_s * o.fs))
        n = n_dwell + n_drive
        node = int(np.argmin(np.abs(node_x - x)))
        tm.model.M0 = m0.copy()
        tm.model.M0[2 * node, 2 * node] += o.robot_mass_kg
        system, with_robot = tm.system({})
        tm.model.M0 = m0
        fractions[p.id] = float(o.robot_mass_kg * (tm.model.sensor_matrix([p.id])[0] @ v1) ** 2 / m1)
        cond = Conditions(t_s=t, temperature_c=10.0, local_hour=12.0)
        pm, _ = tm.loads(rng_for(o.seed, 100 + k), n + n_warm, cond, scenario, system, None)
        y = system.simulate_modal(pm, dt)[n_warm:]
        z = y[:, 2::3]
        ref_parts.append(np.column_stack([z[:, col[r]] for r in refs]))
        acc = y[:, 3 * col[p.id]: 3 * col[p.id] + 3].copy()
        acc[:, 2] += G
        if n_drive:
            acc[n_dwell:] += o.ride_rms_m_s2 * sig.sosfilt(ride, lrng.standard_normal((n_drive, 3)), axis=0) / 0.55
        rov_parts.append(r_mount.inv().apply(acc))  # the sensor reads in its own (tilted) axes
        xs = np.full(n, x)
        if n_drive:
            xs[n_dwell:] = x + (float(points[k + 1].at["x"]) - x) * np.arange(1, n_drive + 1) / n_drive
        x_parts.append(xs)
        phases.append(("dwell", t, t + (n_dwell - 1) * dt, p.id))
        if n_drive:
            phases.append(("drive", t + n_dwell * dt, t + (n - 1) * dt, p.id))
        t += n * dt
        del with_robot
    ref_all = np.vstack(ref_parts)
    rov_all = np.vstack(rov_parts)
    n_all = ref_all.shape[0]
    ref_all = ref_all + o.noise_rms_m_s2 * nrng.standard_normal(ref_all.shape)
    rov_all = rov_all + o.noise_rms_m_s2 * nrng.standard_normal(rov_all.shape)
    rov_all = shift(rov_all, o.fs, -o.clock_offset_s)  # stamped late by the offset
    times = np.round(np.arange(n_all) * dt * 1e9).astype(np.int64)
    xs = np.concatenate(x_parts)
    where = np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, DECK_Z)])
    tf, static = tf_stream(sensor, where, times, o, rng_for(o.seed, 13))
    truth_out = ModalTruth(truth.frequencies_hz, truth.damping_ratios, truth.shapes, list(truth.sensor_ids),
                           truth.families, truth.in_plane_family)
    return RovingRecording(spec, times, {r: ref_all[:, k] for k, r in enumerate(refs)}, {sensor.id: rov_all},
                           tf, static, truth_out, phases, o.clock_offset_s, fractions)


def tf_stream(sensor, where: np.ndarray, times: np.ndarray, o: CarrierOptions, rng: np.random.Generator
              ) -> tuple[list[TfSample], list[TfSample]]:
    """``structure -> odom`` (the localiser's corrections, once a second) and ``odom -> <base>``
    (odometry drifting 1 % of the distance travelled, with noise) at ``tf_hz`` for a sensor at
    ``where`` (n, 3) in the structure's frame; the base frame is the mount's parent."""
    mount = np.array(sensor.mount.translation)
    step = int(round(o.fs / o.tf_hz))
    out: list[TfSample] = []
    drift = np.zeros(3)
    correction = np.zeros(3)
    last = np.array(where[0], dtype=float)
    next_fix = 0
    for i in sorted(set(range(0, times.size, step)) | {times.size - 1}):  # the last sample localised too
        x = np.array(where[i], dtype=float)
        drift += 0.01 * np.abs(x - last)
        last = x
        if times[i] >= next_fix:
            correction = -drift.copy()
            next_fix += 1_000_000_000
        out.append(TfSample("structure", "odom", int(times[i]), _xyz(correction), IDENTITY_Q))
        base = x - mount + drift + rng.normal(0, o.localisation_noise_m, 3)
        out.append(TfSample("odom", sensor.mount.parent, int(times[i]), _xyz(base), IDENTITY_Q))
    static = [TfSample(sensor.mount.parent, sensor.frame, 0, sensor.mount.translation, sensor.mount.rotation)
              ] if o.tf_static else []
    return out, static


def _xyz(v: np.ndarray) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])
