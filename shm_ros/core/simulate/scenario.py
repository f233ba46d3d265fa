"""Scenarios: what to simulate, by name plus options, or from a mapping (a YAML scenario file).

Named scenarios:

* ``girder`` - three-span girder (24 + 30 + 24 m) on four bearings, nine vertical sensors, traffic and
  wind, a daily temperature cycle around 5 degC (early March), 10-minute bursts.
* ``building`` - eight-story shear building, ground sensor ``g0`` plus floors 1, 4, 6 and 8 (x);
  microtremor at the base (measured by ``g0``) and wind on the floors.
* ``building-earthquake`` - the building with one earthquake per window (PGA 0.3-1.5 m/s^2).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from shm_ros.core.simulate.sensors import FaultSpec
from shm_ros.core.simulate.truth_kinds import TRUTH_KINDS

GIRDER_STRUCTURE: dict[str, Any] = {
    "name": "three-span-girder",
    "kind": "girder",
    "girder": {
        "spans": [24.0, 30.0, 24.0],
        "elements_per_span": 10,
        "section": {"E": 3.4e10, "I": 2.1, "A": 5.2, "rho": 2500.0},
        "bearings": [
            {"x": 0.0, "k_vertical": 5.0e9, "k_rotation": 0.0},
            {"x": 24.0, "k_vertical": 5.0e9, "k_rotation": 0.0},
            {"x": 54.0, "k_vertical": 5.0e9, "k_rotation": 0.0},
            {"x": 78.0, "k_vertical": 5.0e9, "k_rotation": 0.0},
        ],
    },
    "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]},
    "sensors": [{"id": f"s{i + 1}", "at": {"x": x}, "direction": "vertical"}
                for i, x in enumerate([6.0, 12.0, 18.0, 31.5, 39.0, 46.5, 60.0, 66.0, 72.0])],
    "parameters": [
        {"name": "E_scale", "applies_to": "girder.section.E", "prior": {"dist": "normal", "mean": 1.0, "std": 0.1}},
        {"name": "bearing_scale", "applies_to": "girder.bearings[*].k_vertical",
         "prior": {"dist": "lognormal", "mean": 1.0, "std": 0.3}},
    ],
}

def shear_building_structure(n_floors: int = 8) -> dict[str, Any]:
    """Nominal n-story shear building: 6e5 kg floors (5e5 kg roof), story stiffness tapering from
    1.0 GN/m to 0.5 GN/m, sensors on the ground (input) and on floors 1, n/2, 3n/4 and n (x)."""
    if n_floors < 2:
        raise ValueError(f"a shear building needs at least 2 floors, got {n_floors}")
    masses = [6.0e5] * (n_floors - 1) + [5.0e5]
    stiff = ([1.00e9, 9.5e8, 9.0e8, 8.5e8, 8.0e8, 7.0e8, 6.0e8, 5.0e8] if n_floors == 8
             else [float(v) for v in np.linspace(1.0e9, 5.0e8, n_floors)])
    floors = sorted({1, max(2, n_floors // 2), max(2, (3 * n_floors) // 4), n_floors})
    half = n_floors // 2
    return {
        "name": f"{n_floors}-story-building" if n_floors != 8 else "eight-story-building",
        "kind": "shear_building",
        "shear_building": {"floors": [{"mass": m, "stiffness": k} for m, k in zip(masses, stiff, strict=True)]},
        "damping": {"kind": "rayleigh", "ratios": [0.02, 0.02]},
        "sensors": [{"id": "g0", "at": {"floor": 0}, "direction": "x"}]
        + [{"id": f"f{k}", "at": {"floor": k}, "direction": "x"} for k in floors],
        "input": {"sensor": "g0"},
        "parameters": [
            {"name": "k_lower",
             "applies_to": f"shear_building.floors[{','.join(str(i) for i in range(half))}].stiffness",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.1}},
            {"name": "k_upper",
             "applies_to": f"shear_building.floors[{','.join(str(i) for i in range(half, n_floors))}].stiffness",
             "prior": {"dist": "normal", "mean": 1.0, "std": 0.1}},
        ],
    }


BUILDING_STRUCTURE: dict[str, Any] = shear_building_structure(8)


@dataclass
class EffectRequest:
    key: str
    params: dict[str, Any] = field(default_factory=dict)


@dataclass
class Scenario:
    """Everything that defines a simulated campaign; the same scenario and seed give the same bytes.

    Windows are bursts of ``window_s`` seconds starting every ``window_s + pause_s`` seconds (the
    pause > 1 s makes each burst one window for ``ingest``). ``earthquakes`` lists
    ``{"window": i, "pga_m_s2": a, "onset_s": t}``; ``earthquake_every_window`` adds one to each window.
    """

    name: str = "girder"
    kind: str = "girder"  # a structure kind the simulator has a truth model for (truth_kinds)
    structure: dict[str, Any] = field(default_factory=lambda: copy.deepcopy(GIRDER_STRUCTURE))
    n_windows: int = 3
    window_s: float = 600.0
    pause_s: float = 2.0
    fs: float = 100.0
    start: str = "2024-03-01T00:00:00Z"
    utc_offset_h: float = 9.0
    seed: int = 0
    effects: list[EffectRequest] = field(default_factory=list)
    faults: list[FaultSpec] = field(default_factory=list)
    output: str = "block"  # "block" (AccelBlock) | "imu" (one Imu per sample per sensor)
    storage: str = "mcap"  # "mcap" | "sqlite3"
    compress: bool = True
    prefix: str = "/shm"
    block_s: float = 1.0  # AccelBlock length
    unrelated_topics: bool = False  # also write a std_msgs/String status topic (to be ignored)
    temperature_period_s: float = 60.0
    # truth model versus nominal model (no inverse crime)
    refine: int = 4  # girder: elements per span x refine
    property_scatter: float = 0.03  # relative std of stiffness / mass of the truth model
    misplacement_std_m: float = 0.15  # girder sensors
    truth_damping: tuple[float, float] = (0.012, 0.025)  # range of the truth's modal damping ratios
    n_truth_modes: int = 6  # in-plane modes in truth.json; out-of-plane modes among them come in addition
    # the truth is richer than any analysis model of its kind (out-of-plane modes, shear deformation,
    # non-classical damping, imperfect sensors; core/simulate/truths/*): off for tests of other things
    model_form: bool = True
    # building: mass centres this fraction of the plan off the stiffness centre (None: 1-2 %); 0.02-0.06
    # reaches the codes' 5 % accidental eccentricity (out of a planar model's class)
    eccentricity: tuple[float, float] | None = None
    # climate and loads
    t_mean_c: float = 5.0
    t_daily_c: float = 6.0
    t_drift_c: float = 2.5
    vehicles_per_hour: float = 400.0
    wind_rms_n: float = 1.0e2
    microtremor_rms_m_s2: float = 5.0e-4
    earthquakes: list[dict[str, float]] = field(default_factory=list)
    earthquake_every_window: bool = False
    pga_range_m_s2: tuple[float, float] = (0.3, 1.5)
    # sensors
    noise_rms_m_s2: float = 1e-4

    @property
    def interval_s(self) -> float:
        return self.window_s + self.pause_s

    @property
    def start_epoch_s(self) -> float:
        t = datetime.fromisoformat(self.start.replace("Z", "+00:00"))
        if t.tzinfo is None:
            t = t.replace(tzinfo=timezone.utc)
        return t.timestamp()

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("structure")
        d["structure_name"] = self.structure.get("name")
        return d


NAMED = ("girder", "building", "building-earthquake")


def named_scenario(name: str, n_floors: int | None = None, **options: Any) -> Scenario:
    """A named scenario (see module doc) with ``options`` overriding its fields; ``n_floors`` gives
    the building scenarios an n-story building (:func:`shear_building_structure`)."""
    if name == "girder":
        base = Scenario()
    elif name in ("building", "building-earthquake"):
        base = Scenario(name=name, kind="shear_building", structure=copy.deepcopy(BUILDING_STRUCTURE),
                        start="2024-05-01T00:00:00Z", t_mean_c=17.0, t_daily_c=4.0, wind_rms_n=1.5e3,
                        microtremor_rms_m_s2=5e-4,
                        window_s=600.0 if name == "building" else 300.0, utc_offset_h=9.0,
                        earthquake_every_window=name == "building-earthquake")
    else:
        raise ValueError(f"unknown scenario {name!r} (known: {', '.join(NAMED)})")
    if n_floors is not None:
        if name not in ("building", "building-earthquake"):
            raise ValueError(f"scenario {name}: n_floors applies to the building scenarios")
        base.structure = shear_building_structure(int(n_floors))
    for k, v in options.items():
        if not hasattr(base, k):
            raise ValueError(f"scenario {name}: unknown option {k!r}")
        setattr(base, k, v)
    return base


def scenario_from_dict(data: dict[str, Any], source: str = "<scenario>") -> Scenario:
    """A scenario file: ``{scenario: NAME, <field>: value, effects: [{key, ...params}], faults: [...]}``."""
    data = dict(data)
    name = data.pop("scenario", data.pop("name", "girder"))
    n_floors = data.pop("n_floors", None)
    effects = []
    for i, e in enumerate(data.pop("effects", []) or []):
        if isinstance(e, str):
            effects.append(EffectRequest(e))
        elif isinstance(e, dict) and "key" in e:
            e = dict(e)
            effects.append(EffectRequest(str(e.pop("key")), e))
        else:
            raise ValueError(f"{source}: effects[{i}]: expected a name or a mapping with 'key'")
    faults = []
    for i, f in enumerate(data.pop("faults", []) or []):
        try:
            faults.append(FaultSpec(**(f if isinstance(f, dict) else {"kind": str(f)})))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: faults[{i}]: {exc}") from None
    for k in ("truth_damping", "pga_range_m_s2"):
        if k in data:
            data[k] = tuple(data[k])
    if "structure" in data:  # validate here so that errors name the scenario file
        from shm_ros.core.structure import structure_from_dict

        if not isinstance(data["structure"], dict):
            raise ValueError(f"{source}: structure: expected a mapping (a structure file's content)")
        kind = structure_from_dict(copy.deepcopy(data["structure"]), source=f"{source} (structure)").kind
        if kind not in TRUTH_KINDS:
            raise ValueError(f"{source}: structure: kind {kind!r} cannot be simulated "
                             f"({' or '.join(TRUTH_KINDS.names())})")
    try:
        sc = named_scenario(name, n_floors=n_floors, **data)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
    sc.effects, sc.faults = effects, faults
    return sc
