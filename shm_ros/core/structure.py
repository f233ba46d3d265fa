"""Typed form of a structure file (docs/interfaces.md section 2) and its parameter paths.

A structure file names the structure, its sensors and the nominal model that updating starts from.
:func:`structure_from_dict` validates the plain mapping read from YAML and returns a
:class:`StructureSpec`; every problem raises :class:`StructureError` naming the file and the field.
Reading files (YAML, the ``.npz`` of ``kind: matrices``) is done by ``shm_ros.io.structure``; this
module never touches the file system.

``applies_to`` paths are dotted paths into the file. A list is indexed with zero-based positions in
brackets: ``floors[0,1]``, ``bearings[*]``, or no index, which means every element. Each resolved
location is a tuple of keys and list positions, e.g. ``("girder", "bearings", 2, "k_vertical")``.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from shm_ros.core.drift_limits import DriftLimits, parse_drift_limits
from shm_ros.core.models.registry import MODEL_KINDS, ModelKind, kind_names, model_kind
from shm_ros.core.priors import PARAMETER_PRIORS, PRIOR_ALT_FIELDS, PRIOR_FIELDS, Prior, PriorError, prior_fields
from shm_ros.errors import InputError

DIRECTIONS = ("vertical", "x", "y")
DEFAULT_MAX_DOF = 20_000  # a model larger than this is refused unless the caller raises the limit
DEFAULT_AXIS = {"vertical": "z", "x": "x", "y": "y"}

Location = tuple[str | int, ...]


class StructureError(InputError):
    """A structure file (or spec) is invalid; the message names the file and the field."""

    def __init__(self, message: str, source: str = "<structure>", field_path: str | None = None):
        self.source = source
        self.field_path = field_path
        where = f"{source}: " + (f"field '{field_path}': " if field_path else "")
        super().__init__(where + message)


# ----------------------------------------------------------------------------------------------
# Dataclasses
# ----------------------------------------------------------------------------------------------


@dataclass
class DampingSpec:
    """``rayleigh``: ratios of the first two modes fix C = a0 M + a1 K; ``modal``: ratio per mode
    (the last one repeats for higher modes)."""

    kind: str = "rayleigh"
    ratios: list[float] = field(default_factory=lambda: [0.02, 0.02])


@dataclass
class SourceSpec:
    """Where a sensor's samples come from; defaults already resolved (docs/interfaces.md section 2).

    ``topic``: last element of the ``.../accel/<topic>`` Imu topic (None: not read from an Imu topic);
    ``axis``: x | y | z of ``linear_acceleration``; ``channel``: AccelBlock channel name (None: not
    read from an AccelBlock); ``sign``: multiplies the samples.
    """

    topic: str | None
    axis: str
    sign: float = 1.0
    channel: str | None = None


@dataclass
class SensorSpec:
    """A sensor: ``at`` = ``{x: m}`` (girder), ``{floor: k}`` (building) or ``{dof: i|label}``."""

    id: str
    at: dict[str, Any]
    direction: str
    source: SourceSpec

    @property
    def x(self) -> float | None:
        v = self.at.get("x")
        return None if v is None else float(v)

    @property
    def floor(self) -> int | None:
        v = self.at.get("floor")
        return None if v is None else int(v)


class InputKind(StrEnum):
    """What a measured input record drives (docs/interfaces.md section 2)."""

    BASE = "base"  # ground acceleration under floor 1 (the support of the whole structure)
    FLOOR = "floor"  # the measured acceleration of a location, prescribed: it drives the parts it supports
    FORCE = "force"  # a force [N] = gain x record, applied at ``at``


@dataclass
class InputSpec:
    """One measured input: the sensor recording it, what it drives, where, and a gain.

    ``at`` is the location (``{floor: k}``, ``{x: m}`` or ``{dof: i|label}``): for ``base`` the
    sensor's own location, for ``floor`` the location whose motion is prescribed, for ``force``
    where the force acts. The record (sensor samples x ``gain``) is an acceleration in m/s^2 for
    ``base`` and ``floor``, a force in N for ``force``. ``direction`` is the sensor's.
    """

    sensor: str
    kind: InputKind
    at: dict[str, Any]
    direction: str
    gain: float = 1.0


@dataclass
class PriorSpec:
    """Prior of a multiplicative factor: normal{mean,std}, lognormal{mean,std} (of the factor itself,
    not of its log) or lognormal{mu_ln,sigma_ln} (of its log), weibull{scale,shape}, uniform{low,high}."""

    dist: str
    params: dict[str, float]

    def frozen(self):
        """The prior as a frozen ``scipy.stats`` distribution (:class:`shm_ros.core.priors.Prior`)."""
        return Prior.make(self.dist, self.params).dist


@dataclass
class ParameterSpec:
    """An updatable multiplicative factor; ``targets`` are the resolved locations of ``applies_to``."""

    name: str
    applies_to: str
    prior: PriorSpec
    targets: list[Location] = field(default_factory=list)


@dataclass
class MountSpec:
    """Where a roving sensor sits on its carrier: the transform ``parent -> frame`` (the sensor's tf
    frame), for bags without ``/tf_static``. ``rotation`` is a unit quaternion (x, y, z, w)."""

    parent: str
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass
class RovingSensorSpec:
    """A sensor carried by a robot (docs/interfaces.md section 8): no fixed ``at``; its position in
    the structure's frame at a sample's time is the tf chain from the structure's ``frame`` to
    ``frame``. ``mount``: the last link of that chain when the bag has no ``/tf_static``.
    ``carrier_mass_kg``: the mass of the robot or drone that carries it, which lowers the modes where
    it stands (0: too light to matter; None: fitted from the setups, docs/roving.md)."""

    id: str
    frame: str
    direction: str
    source: SourceSpec
    mount: MountSpec | None = None
    carrier_mass_kg: float | None = None


@dataclass
class MeasurementPoint:
    """Where roving sensors are meant to stop: ``at`` as a fixed sensor's, and optionally ``xyz``, the
    point in the structure's frame (m). A girder point without ``xyz`` is (x, 0, 0) and only its x
    counts (a sensor on the deck is above the axis); a point given by floor needs ``xyz``."""

    id: str
    at: dict[str, Any]
    xyz: tuple[float, float, float] | None = None

    @property
    def position(self) -> tuple[float, float, float] | None:
        if self.xyz is not None:
            return self.xyz
        if "x" in self.at:
            return (float(self.at["x"]), 0.0, 0.0)
        return None

    @property
    def axes(self) -> tuple[bool, bool, bool]:
        """The coordinates that count in the distance to this point."""
        return (True, True, True) if self.xyz is not None else (True, False, False)


DEFAULT_FRAME = "structure"


@dataclass
class StructureSpec:
    """A validated structure file. ``raw`` is the mapping as read; ``source`` names the file.

    ``section`` is the parsed section of the structure's kind (e.g. the girder's spans, sections and
    bearings); ``spec.<kind name>`` reads it too (``spec.girder``), and is None for the other
    registered kinds. ``arrays`` holds the contents of a file the section names (the ``.npz`` of
    ``kind: matrices``).
    """

    name: str
    kind: str
    section: Any
    damping: DampingSpec
    sensors: list[SensorSpec]
    inputs: list[InputSpec]
    parameters: list[ParameterSpec]
    raw: dict = field(default_factory=dict, repr=False)
    source: str = "<structure>"
    description: str | None = None
    arrays: dict[str, np.ndarray] | None = field(default=None, repr=False)
    drift_limits: DriftLimits = field(default_factory=DriftLimits)  # shear buildings: per-story limits
    frame: str = DEFAULT_FRAME
    roving: list[RovingSensorSpec] = field(default_factory=list)
    measurement_points: list[MeasurementPoint] = field(default_factory=list)

    def __getattr__(self, name: str) -> Any:
        # only called for names that are not attributes: ``spec.girder`` and the like
        if name.startswith("_") or "kind" not in self.__dict__ or name not in MODEL_KINDS:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        return self.__dict__["section"] if self.__dict__["kind"] == name else None

    @property
    def model_kind(self) -> ModelKind:
        return model_kind(self.kind)

    # -- look-ups ------------------------------------------------------------------------------
    def sensor(self, sensor_id: str) -> SensorSpec:
        for s in self.sensors:
            if s.id == sensor_id:
                return s
        raise KeyError(f"{self.source}: no sensor {sensor_id!r}")

    @property
    def sensor_ids(self) -> list[str]:
        return [s.id for s in self.sensors]

    @property
    def input_sensor(self) -> str | None:
        """The sensor of the first input (None: no input); see :meth:`input_sensor_ids` for all."""
        return self.inputs[0].sensor if self.inputs else None

    def input_sensor_ids(self) -> list[str]:
        """Sensors that record inputs, in the order of the structure file."""
        return [i.sensor for i in self.inputs]

    @property
    def output_sensor_ids(self) -> list[str]:
        """Sensors other than the input sensors."""
        inputs = set(self.input_sensor_ids())
        return [s.id for s in self.sensors if s.id not in inputs]

    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def parameter(self, name: str) -> ParameterSpec:
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"{self.source}: no parameter {name!r}")

    # -- conversion ----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain mapping in the structure-file form (what ``dump_structure`` writes)."""
        out: dict[str, Any] = {"name": self.name, "kind": self.kind}
        if self.description is not None:
            out["description"] = self.description
        out[self.kind] = self.model_kind.section_to_dict(self.section)
        out["damping"] = {"kind": self.damping.kind, "ratios": [float(r) for r in self.damping.ratios]}
        out["sensors"] = [_sensor_dict(s) for s in self.sensors] + [_roving_dict(r) for r in self.roving]
        if self.frame != DEFAULT_FRAME or self.roving:
            out["frame"] = self.frame
        if self.measurement_points:
            out["measurement_points"] = [{"id": p.id, "at": dict(p.at), **({} if p.xyz is None else
                                          {"xyz": list(p.xyz)})} for p in self.measurement_points]
        if len(self.inputs) == 1 and _is_plain_input(self, self.inputs[0]):
            out["input"] = {"sensor": self.inputs[0].sensor}
        elif self.inputs:
            out["inputs"] = [_input_dict(i) for i in self.inputs]
        out["parameters"] = [
            {"name": p.name, "applies_to": p.applies_to, "prior": {"dist": p.prior.dist, **p.prior.params}}
            for p in self.parameters
        ]
        if self.drift_limits.given:
            out["drift_limits"] = self.drift_limits.to_dict()
        return out

    def scaled(self, factors: Mapping[str, float]) -> StructureSpec:
        """A copy with the values at each ``applies_to``-style path (or parameter name) multiplied.

        ``spec.scaled({"girder.bearings[*].k_vertical": 0.8, "E_scale": 1.05})`` - keys that name a
        parameter of this spec use its ``applies_to``. Handy for truth models with hidden effects.
        """
        data = self.to_dict()
        names = {p.name: p.applies_to for p in self.parameters}
        for key, f in factors.items():
            path = names.get(key, key)
            for loc in resolve_path(data, path, source=self.source):
                parent = _get(data, loc[:-1])
                parent[loc[-1]] = float(parent[loc[-1]]) * float(f)
        return structure_from_dict(data, source=self.source, matrices_arrays=self.arrays)


def _is_plain_input(spec: StructureSpec, i: InputSpec) -> bool:
    """Whether ``input: {sensor: ID}`` alone says everything about ``i`` (the defaults hold)."""
    at = spec.sensor(i.sensor).at
    return i.gain == 1.0 and i.at == at and i.kind == default_input_kind(at)


def _input_dict(i: InputSpec) -> dict[str, Any]:
    out: dict[str, Any] = {"sensor": i.sensor, "kind": i.kind.value}
    if i.kind != InputKind.BASE:
        out["at"] = dict(i.at)
    out["gain"] = float(i.gain)
    return out


def _sensor_dict(s: SensorSpec) -> dict[str, Any]:
    src: dict[str, Any] = {}
    if s.source.topic is not None:
        src["topic"] = s.source.topic
    if s.source.channel is not None:
        src["channel"] = s.source.channel
    src["axis"] = s.source.axis
    src["sign"] = float(s.source.sign)
    return {"id": s.id, "at": dict(s.at), "direction": s.direction, "source": src}


def _roving_dict(r: RovingSensorSpec) -> dict[str, Any]:
    out: dict[str, Any] = {"id": r.id, "roving": True, "frame": r.frame, "direction": r.direction,
                           "source": _sensor_dict(SensorSpec(r.id, {}, r.direction, r.source))["source"]}
    if r.mount is not None:
        out["mount"] = {"parent": r.mount.parent, "translation": [float(v) for v in r.mount.translation],
                        "rotation": [float(v) for v in r.mount.rotation]}
    if r.carrier_mass_kg is not None:
        out["carrier_mass_kg"] = float(r.carrier_mass_kg)
    return out


# ----------------------------------------------------------------------------------------------
# Paths
# ----------------------------------------------------------------------------------------------

_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[([^\]]*)\])?$")


def parse_path(path: str, source: str = "<structure>", field_path: str = "applies_to") -> list[tuple[str, Any]]:
    """Split ``a.b[0,1].c`` into ``[(a, None), (b, [0, 1]), (c, None)]``; ``[*]`` gives ``"*"``."""
    if not isinstance(path, str) or not path.strip():
        raise StructureError("must be a non-empty dotted path", source, field_path)
    out: list[tuple[str, Any]] = []
    for seg in path.strip().split("."):
        m = _SEGMENT.match(seg.strip())
        if m is None:
            raise StructureError(f"bad path segment {seg!r} in {path!r}", source, field_path)
        name, idx = m.group(1), m.group(2)
        if idx is None:
            out.append((name, None))
        elif idx.strip() == "*":
            out.append((name, "*"))
        else:
            try:
                positions = [int(v) for v in idx.split(",")]
            except ValueError:
                raise StructureError(
                    f"bad index [{idx}] in {path!r}: use zero-based positions like [0,1] or [*]", source, field_path
                ) from None
            out.append((name, positions))
    return out


def resolve_path(
    data: Mapping, path: str, source: str = "<structure>", field_path: str = "applies_to"
) -> list[Location]:
    """Every concrete numeric location that ``path`` names in ``data`` (see module doc)."""
    segments = parse_path(path, source, field_path)
    current: list[tuple[Location, Any]] = [((), data)]
    for name, idx in segments:
        nxt: list[tuple[Location, Any]] = []
        for loc, node in current:
            if not isinstance(node, Mapping) or name not in node:
                where = location_str(loc) or "the top level"
                have = sorted(node.keys()) if isinstance(node, Mapping) else type(node).__name__
                raise StructureError(f"{path!r}: no field {name!r} under {where} (has {have})", source, field_path)
            child = node[name]
            cloc = loc + (name,)
            if isinstance(child, list):
                n = len(child)
                if idx is None or idx == "*":
                    positions = list(range(n))
                else:
                    for p in idx:
                        if not 0 <= p < n:
                            raise StructureError(
                                f"{path!r}: index {p} out of range, {location_str(cloc)} has {n} entries",
                                source,
                                field_path,
                            )
                    positions = list(dict.fromkeys(idx))
                nxt.extend((cloc + (p,), child[p]) for p in positions)
            else:
                if idx is not None:
                    raise StructureError(
                        f"{path!r}: {location_str(cloc)} is not a list and cannot be indexed", source, field_path
                    )
                nxt.append((cloc, child))
        current = nxt
    out: list[Location] = []
    for loc, node in current:
        if isinstance(node, bool) or not isinstance(node, (int, float)):
            raise StructureError(f"{path!r} leads to a non-numeric value at {location_str(loc)}", source, field_path)
        out.append(loc)
    if not out:
        raise StructureError(f"{path!r} selects nothing", source, field_path)
    return out


def _get(data: Any, loc: Location) -> Any:
    for k in loc:
        data = data[k]
    return data


def location_str(loc: Location) -> str:
    """``("girder", "bearings", 2, "k_vertical")`` -> ``girder.bearings[2].k_vertical``."""
    s = ""
    for k in loc:
        s += f"[{k}]" if isinstance(k, int) else (("." if s else "") + k)
    return s


def updatable(kind: str, loc: Location) -> bool:
    """Whether a resolved location is a model quantity that a factor may scale for this kind."""
    if loc[:2] == ("damping", "ratios") and len(loc) == 3:
        return True
    return loc[:1] == (kind,) and model_kind(kind).updatable(loc)


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------


_EXPONENT_NUMBER = re.compile(r"^[-+]?[0-9]+(?:\.[0-9]*)?[eE][-+]?[0-9]+$")


def short(v: Any, limit: int = 60) -> str:
    """``repr(v)`` cut to ``limit`` characters: an error message never echoes a whole input."""
    if isinstance(v, (list, dict)):
        return f"a {type(v).__name__} of {len(v)} entries"
    text = repr(v)
    return text if len(text) <= limit else text[:limit] + "..."


def _kind_of(v: Any) -> str:
    return "text " if isinstance(v, str) else "a boolean, " if isinstance(v, (bool, np.bool_)) else ""


class FieldReader:
    """Checks values of one structure file; every error names the file and the field path."""

    def __init__(self, source: str):
        self.source = source

    def err(self, msg: str, fld: str | None = None) -> StructureError:
        return StructureError(msg, self.source, fld)

    def mapping(self, v: Any, fld: str) -> Mapping:
        if not isinstance(v, Mapping):
            raise self.err(f"must be a mapping, got {type(v).__name__}", fld)
        return v

    def seq(self, v: Any, fld: str) -> list:
        if not isinstance(v, (list, tuple)):
            raise self.err(f"must be a list, got {type(v).__name__}", fld)
        return list(v)

    def number(self, v: Any, fld: str, positive: bool = False, nonneg: bool = False) -> float:
        # text is refused, except a number in exponent form ("5e9", "3.4e10"): YAML 1.1 readers (PyYAML's
        # safe_load) leave those as text, YAML 1.2 and the structure loader read them as numbers
        if isinstance(v, str) and _EXPONENT_NUMBER.match(v):
            v = float(v)
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise self.err(f"must be a number, got {_kind_of(v)}{short(v)}", fld)
        v = float(v)
        if not math.isfinite(v):
            raise self.err(f"must be finite, got {v!r}", fld)
        if positive and v <= 0:
            raise self.err(f"must be > 0, got {v!r}", fld)
        if nonneg and v < 0:
            raise self.err(f"must be >= 0, got {v!r}", fld)
        return v

    def integer(self, v: Any, fld: str, minimum: int | None = None) -> int:
        integral = isinstance(v, (int, np.integer)) or (isinstance(v, float) and v.is_integer())
        if isinstance(v, bool) or not integral:
            raise self.err(f"must be an integer, got {_kind_of(v)}{short(v)}", fld)
        v = int(v)
        if minimum is not None and v < minimum:
            raise self.err(f"must be >= {minimum}, got {v}", fld)
        return v

    def string(self, v: Any, fld: str) -> str:
        if not isinstance(v, str) or not v:
            raise self.err(f"must be a non-empty string, got {short(v)}", fld)
        return v

    def keys(self, m: Mapping, allowed: tuple[str, ...], required: tuple[str, ...], fld: str) -> None:
        for k in m:
            if k not in allowed:
                where = f"{fld}.{k}" if fld else str(k)
                raise self.err(f"unknown field {k!r} (allowed: {', '.join(allowed)})", where)
        for k in required:
            if k not in m:
                raise self.err("missing required field", f"{fld}.{k}" if fld else k)


_COMMON = ("name", "kind", "description", "damping", "sensors", "input", "inputs", "parameters", "drift_limits",
           "frame", "measurement_points")
INPUT_FIELDS = ("sensor", "kind", "at", "gain")


def structure_from_dict(
    data: Mapping, source: str = "<structure>", matrices_arrays: Mapping[str, np.ndarray] | None = None,
    max_dof: int = DEFAULT_MAX_DOF,
) -> StructureSpec:
    """Validate a structure-file mapping. ``matrices_arrays``: the contents of the file the kind's
    section names (the ``.npz`` of ``kind: matrices``). A model of more than ``max_dof`` degrees of
    freedom is refused before anything is built."""
    c = FieldReader(source)
    data = c.mapping(data, "")
    kinds = kind_names()
    c.keys(data, (*_COMMON, *kinds), ("name", "kind", "sensors"), "")
    name = c.string(data["name"], "name")
    kind = data["kind"]
    if kind not in kinds:
        raise c.err(f"unknown kind {short(kind)} (expected one of: {', '.join(kinds)})", "kind")
    if kind not in data:
        raise c.err(f"kind is {kind!r} but the section {kind!r} is missing", kind)
    # Sections of the other kinds may be present (a file may carry both a girder and a building
    # description, docs/interfaces.md section 2); only the one named by ``kind`` is read, the rest
    # stays in ``raw``.
    mk = model_kind(kind)
    section = mk.parse_section(c, data[kind], matrices_arrays)
    n_dof = mk.n_dof(section)
    if n_dof > max_dof:
        raise c.err(f"the model would have about {n_dof} degrees of freedom, more than the limit of {max_dof} "
                    "(raise it with SHM_ROS_MAX_DOF)", kind)

    damping = _damping(c, data.get("damping", {"kind": "rayleigh", "ratios": [0.02, 0.02]}))
    fixed_entries, roving = _roving_sensors(c, data["sensors"])
    if roving and not fixed_entries:
        raise c.err("roving sensors need at least one fixed sensor: the references that glue the setups "
                    "together", "sensors")
    sensors = _sensors(c, fixed_entries, mk, section)
    frame = c.string(data.get("frame", DEFAULT_FRAME), "frame")
    points = _measurement_points(c, data.get("measurement_points"), roving, sensors, mk, section)
    inputs = _inputs(c, data, sensors, mk, section)

    description = data.get("description")
    spec = StructureSpec(
        name=name,
        kind=kind,
        section=section,
        damping=damping,
        sensors=sensors,
        inputs=inputs,
        parameters=[],
        raw=copy.deepcopy(dict(data)),
        source=source,
        description=None if description is None else str(description),
        arrays=None if matrices_arrays is None else dict(matrices_arrays),
        frame=frame,
        roving=[r for _, r in roving],
        measurement_points=points,
    )
    spec.parameters = _parameters(c, data.get("parameters") or [], spec)
    if data.get("drift_limits") is not None:
        floors = getattr(section, "floors", None)
        spec.drift_limits = parse_drift_limits(c, data["drift_limits"], len(floors) if floors is not None else None)
    return spec


def _damping(c: FieldReader, v: Any) -> DampingSpec:
    d = c.mapping(v, "damping")
    c.keys(d, ("kind", "ratios"), ("ratios",), "damping")
    kind = d.get("kind", "rayleigh")
    if kind not in ("rayleigh", "modal"):
        raise c.err(f"unknown damping kind {kind!r} (expected rayleigh or modal)", "damping.kind")
    ratios = [
        c.number(r, f"damping.ratios[{i}]", nonneg=True) for i, r in enumerate(c.seq(d["ratios"], "damping.ratios"))
    ]
    if kind == "rayleigh" and len(ratios) != 2:
        raise c.err(f"rayleigh damping needs exactly two ratios, got {len(ratios)}", "damping.ratios")
    if not ratios:
        raise c.err("needs at least one ratio", "damping.ratios")
    return DampingSpec(kind=kind, ratios=ratios)


ROVING_FIELDS = ("id", "roving", "frame", "direction", "source", "mount", "carrier_mass_kg")


def _roving_sensors(c: FieldReader, v: Any) -> tuple[list[tuple[int, Any]], list[tuple[int, RovingSensorSpec]]]:
    """Split ``sensors`` into fixed entries (position, raw entry) and parsed roving sensors."""
    fixed: list[tuple[int, Any]] = []
    roving: list[tuple[int, RovingSensorSpec]] = []
    for i, s in enumerate(c.seq(v, "sensors")):
        fld = f"sensors[{i}]"
        s = c.mapping(s, fld)
        flag = s.get("roving", False)
        if not isinstance(flag, bool):
            raise c.err(f"must be true or false, got {flag!r}", f"{fld}.roving")
        if not flag:
            if "frame" in s or "mount" in s:
                key = "frame" if "frame" in s else "mount"
                raise c.err("only a roving sensor (roving: true) has a tf frame or a mount; a fixed "
                            "sensor's position is its 'at'", f"{fld}.{key}")
            fixed.append((i, {k: val for k, val in s.items() if k != "roving"}))
            continue
        if "at" in s:
            raise c.err("a roving sensor's position comes from tf (its 'frame'): it takes no 'at'", f"{fld}.at")
        c.keys(s, ROVING_FIELDS, ("id", "frame", "direction"), fld)
        sid = c.string(str(s["id"]) if isinstance(s["id"], (int, str)) else s["id"], f"{fld}.id")
        direction = s["direction"]
        if direction not in DIRECTIONS:
            raise c.err(f"unknown direction {direction!r} (expected one of: {', '.join(DIRECTIONS)})",
                        f"{fld}.direction")
        mount = None if s.get("mount") is None else _mount(c, s["mount"], f"{fld}.mount")
        carrier = None if s.get("carrier_mass_kg") is None else \
            c.number(s["carrier_mass_kg"], f"{fld}.carrier_mass_kg", nonneg=True)
        roving.append((i, RovingSensorSpec(id=sid, frame=c.string(s["frame"], f"{fld}.frame"),
                                           direction=direction, source=_source(c, s.get("source"), sid,
                                                                               direction, fld),
                                           mount=mount, carrier_mass_kg=carrier)))
    return fixed, roving


def _mount(c: FieldReader, v: Any, fld: str) -> MountSpec:
    """``{parent: FRAME, translation: [x, y, z], rotation: [x, y, z, w] | rpy_deg: [roll, pitch, yaw]}``."""
    m = c.mapping(v, fld)
    c.keys(m, ("parent", "translation", "rotation", "rpy_deg"), ("parent",), fld)
    if "rotation" in m and "rpy_deg" in m:
        raise c.err("give either 'rotation' (quaternion x, y, z, w) or 'rpy_deg', not both", fld)

    def vector(key: str, n: int, default: list[float]) -> list[float]:
        vals = c.seq(m.get(key, default), f"{fld}.{key}")
        if len(vals) != n:
            raise c.err(f"needs {n} numbers, got {len(vals)}", f"{fld}.{key}")
        return [c.number(x, f"{fld}.{key}[{k}]") for k, x in enumerate(vals)]

    t = vector("translation", 3, [0.0, 0.0, 0.0])
    if "rpy_deg" in m:
        # fixed-axis roll, pitch, yaw (REP-103): extrinsic x-y-z; scipy's quaternion is (x, y, z, w) as in ROS
        q = [float(v) for v in Rotation.from_euler("xyz", vector("rpy_deg", 3, [0.0, 0.0, 0.0]),
                                                     degrees=True).as_quat()]
    else:
        q = vector("rotation", 4, [0.0, 0.0, 0.0, 1.0])
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-3:
        raise c.err(f"a rotation quaternion (x, y, z, w) must have unit length, got |q| = {norm:.6g}",
                    f"{fld}.rotation")
    return MountSpec(parent=c.string(m["parent"], f"{fld}.parent"), translation=(t[0], t[1], t[2]),
                     rotation=(q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm))


def _measurement_points(c: FieldReader, v: Any, roving: list[tuple[int, RovingSensorSpec]],
                        sensors: list[SensorSpec], mk: ModelKind, section: Any) -> list[MeasurementPoint]:
    if v is None:
        if roving:
            raise c.err("roving sensors need measurement_points: the places where they stop", "measurement_points")
        return []
    if not roving:
        raise c.err("measurement points are where roving sensors stop, but no sensor is roving: true",
                    "measurement_points")
    direction = roving[0][1].direction
    taken = {s.id: "a fixed sensor" for s in sensors}
    for i, r in roving:
        if r.id in taken:
            raise c.err(f"duplicate sensor id {r.id!r}", f"sensors[{i}].id")
        taken[r.id] = "a roving sensor"
    out: list[MeasurementPoint] = []
    for k, p in enumerate(c.seq(v, "measurement_points")):
        fld = f"measurement_points[{k}]"
        p = c.mapping(p, fld)
        c.keys(p, ("id", "at", "xyz"), ("id", "at"), fld)
        xyz = None
        if "xyz" in p:
            vals = c.seq(p["xyz"], f"{fld}.xyz")
            if len(vals) != 3:
                raise c.err(f"needs 3 numbers (x, y, z in the structure's frame), got {len(vals)}", f"{fld}.xyz")
            x, y, z = (c.number(v, f"{fld}.xyz[{k}]") for k, v in enumerate(vals))
            xyz = (x, y, z)
        pid = c.string(str(p["id"]) if isinstance(p["id"], (int, str)) else p["id"], f"{fld}.id")
        if pid in taken:
            raise c.err(f"id {pid!r} is taken by {taken[pid]} (global shapes are keyed by these ids)", f"{fld}.id")
        taken[pid] = "another measurement point"
        at = mk.sensor_location(c, section, c.mapping(p["at"], f"{fld}.at"), direction, fld)
        if xyz is None and "x" not in at:
            raise c.err("a point not given by x along a girder needs xyz: where it is in the structure's "
                        "frame (m), to compare with the tf positions", f"{fld}.xyz")
        out.append(MeasurementPoint(pid, at, xyz))
    if not out:
        raise c.err("needs at least one point", "measurement_points")
    return out


def _sensors(c: FieldReader, v: list[tuple[int, Any]], mk: ModelKind, section: Any) -> list[SensorSpec]:
    out: list[SensorSpec] = []
    seen: set[str] = set()
    for i, s in v:
        fld = f"sensors[{i}]"
        s = c.mapping(s, fld)
        c.keys(s, ("id", "at", "direction", "source"), ("id", "at", "direction"), fld)
        sid = c.string(str(s["id"]) if isinstance(s["id"], (int, str)) else s["id"], f"{fld}.id")
        if sid in seen:
            raise c.err(f"duplicate sensor id {sid!r}", f"{fld}.id")
        seen.add(sid)
        direction = s["direction"]
        if direction not in DIRECTIONS:
            raise c.err(
                f"unknown direction {direction!r} (expected one of: {', '.join(DIRECTIONS)})", f"{fld}.direction"
            )
        at = mk.sensor_location(c, section, c.mapping(s["at"], f"{fld}.at"), direction, fld)
        source = _source(c, s.get("source"), sid, direction, fld)
        out.append(SensorSpec(id=sid, at=at, direction=direction, source=source))
    if not out:
        raise c.err("needs at least one sensor", "sensors")
    return out


def default_input_kind(at: Mapping[str, Any]) -> InputKind:
    """``base`` unless the sensor sits on a floor above the ground: a floor sensor cannot record the
    ground, so its record is that floor's prescribed motion (``floor``)."""
    fl = at.get("floor")
    return InputKind.FLOOR if fl is not None and int(fl) >= 1 else InputKind.BASE


def _inputs(c: FieldReader, data: Mapping, sensors: list[SensorSpec], mk: ModelKind, section: Any
            ) -> list[InputSpec]:
    """``input: {...}`` (one input) or ``inputs: [...]`` (several); both together is an error."""
    has_one = data.get("input") is not None
    has_many = data.get("inputs") is not None
    if has_one and has_many:
        raise c.err("give either 'input' (one input) or 'inputs' (a list), not both", "inputs")
    if has_one:
        entries = [("input", data["input"])]
    elif has_many:
        entries = [(f"inputs[{i}]", v) for i, v in enumerate(c.seq(data["inputs"], "inputs"))]
    else:
        return []
    by_id = {s.id: s for s in sensors}
    out: list[InputSpec] = []
    for fld, v in entries:
        m = c.mapping(v, fld)
        c.keys(m, INPUT_FIELDS, ("sensor",), fld)
        sid = c.string(str(m["sensor"]) if isinstance(m["sensor"], int) else m["sensor"], f"{fld}.sensor")
        if sid not in by_id:
            raise c.err(f"names sensor {sid!r}, which is not in sensors", f"{fld}.sensor")
        if any(i.sensor == sid for i in out):
            raise c.err(f"sensor {sid!r} records another input already", f"{fld}.sensor")
        sensor = by_id[sid]
        default = default_input_kind(sensor.at)
        kind_v = m.get("kind", default.value)
        try:
            kind = InputKind(kind_v)
        except ValueError:
            raise c.err(f"unknown input kind {kind_v!r} (expected one of: "
                        f"{', '.join(k.value for k in InputKind)})", f"{fld}.kind") from None
        gain = c.number(m.get("gain", 1.0), f"{fld}.gain")
        if gain == 0:
            raise c.err("must not be 0", f"{fld}.gain")
        if kind == InputKind.BASE:
            if "at" in m:
                raise c.err("a base input acts under the whole structure: it takes no 'at'", f"{fld}.at")
            if default != InputKind.BASE:
                raise c.err(f"a base input is the ground acceleration, but sensor {sid!r} is at "
                            f"floor {sensor.floor}: use kind floor (the floor's motion drives the "
                            "floors above it) or a sensor at floor 0", f"{fld}.kind")
            at = dict(sensor.at)
        else:
            at = sensor.at if "at" not in m else mk.sensor_location(
                c, section, c.mapping(m["at"], f"{fld}.at"), sensor.direction, fld)
            at = dict(at)
            if at.get("floor") == 0:
                raise c.err(f"floor 0 is the ground: a {kind.value} input acts on a floor >= 1 "
                            "(use kind base for the ground acceleration)", f"{fld}.at.floor")
        for other in out:
            if other.direction != sensor.direction:
                continue
            if kind == other.kind == InputKind.BASE:
                raise c.err(f"a second base input in direction {sensor.direction!r} "
                            f"(sensor {other.sensor!r} is one already)", f"{fld}.kind")
            if kind == other.kind == InputKind.FLOOR and at == other.at:
                raise c.err(f"the motion at {at} is prescribed by input {other.sensor!r} already", f"{fld}.at")
        out.append(InputSpec(sensor=sid, kind=kind, at=at, direction=sensor.direction, gain=gain))
    return out


def _source(c: FieldReader, v: Any, sid: str, direction: str, fld: str) -> SourceSpec:
    if v is None:
        return SourceSpec(topic=sid, axis=DEFAULT_AXIS[direction], sign=1.0, channel=sid)
    m = c.mapping(v, f"{fld}.source")
    c.keys(m, ("topic", "axis", "sign", "channel"), (), f"{fld}.source")
    has_topic, has_channel = "topic" in m, "channel" in m
    topic = c.string(str(m["topic"]), f"{fld}.source.topic") if has_topic else (None if has_channel else sid)
    channel = c.string(str(m["channel"]), f"{fld}.source.channel") if has_channel else (None if has_topic else sid)
    axis = m.get("axis", DEFAULT_AXIS[direction])
    if axis not in ("x", "y", "z"):
        raise c.err(f"unknown axis {axis!r} (expected x, y or z)", f"{fld}.source.axis")
    sign = c.number(m.get("sign", 1.0), f"{fld}.source.sign")
    if sign == 0:
        raise c.err("must not be 0", f"{fld}.source.sign")
    return SourceSpec(topic=topic, axis=axis, sign=sign, channel=channel)


def _prior(c: FieldReader, v: Any, fld: str) -> PriorSpec:
    m = c.mapping(v, fld)
    if "dist" not in m:
        raise c.err("missing required field", f"{fld}.dist")
    dist = m["dist"]
    if dist not in PARAMETER_PRIORS:
        raise c.err(f"unknown prior {dist!r} (expected one of: {', '.join(PARAMETER_PRIORS)})", f"{fld}.dist")
    alt = PRIOR_ALT_FIELDS.get(dist, ())
    c.keys(m, ("dist", *PRIOR_FIELDS[dist], *alt), (), fld)
    try:
        need = prior_fields(dist, m)
    except PriorError:
        both = [k for k in (*PRIOR_FIELDS[dist], *alt) if k in m]
        raise c.err(f"a {dist} prior is either {{{', '.join(PRIOR_FIELDS[dist])}}} or {{{', '.join(alt)}}}, "
                    f"not both (found {', '.join(both)})", fld) from None
    for k in need:
        if k not in m:
            raise c.err("missing required field", f"{fld}.{k}")
    p = {k: c.number(m[k], f"{fld}.{k}") for k in need}
    for k in ("std", "sigma_ln"):
        if k in p and p[k] <= 0:
            raise c.err(f"must be > 0, got {p[k]}", f"{fld}.{k}")
    if dist == "lognormal" and "mean" in p and p["mean"] <= 0:
        raise c.err(f"must be > 0 for a lognormal prior, got {p['mean']}", f"{fld}.mean")
    if dist == "weibull":
        for k in need:
            if p[k] <= 0:
                raise c.err(f"must be > 0, got {p[k]}", f"{fld}.{k}")
    if dist == "uniform" and not p["low"] < p["high"]:
        raise c.err(f"low ({p['low']}) must be below high ({p['high']})", f"{fld}.high")
    return PriorSpec(dist=dist, params=p)


def _parameters(c: FieldReader, v: Any, spec: StructureSpec) -> list[ParameterSpec]:
    view = spec.to_dict()
    out: list[ParameterSpec] = []
    owner: dict[tuple, str] = {}
    for i, p in enumerate(c.seq(v, "parameters")):
        fld = f"parameters[{i}]"
        p = c.mapping(p, fld)
        c.keys(p, ("name", "applies_to", "prior"), ("name", "applies_to", "prior"), fld)
        name = c.string(p["name"], f"{fld}.name")
        if any(q.name == name for q in out):
            raise c.err(f"duplicate parameter name {name!r}", f"{fld}.name")
        path = c.string(p["applies_to"], f"{fld}.applies_to")
        targets = resolve_path(view, path, spec.source, f"{fld}.applies_to")
        for loc in targets:
            if not updatable(spec.kind, loc):
                raise c.err(
                    f"{location_str(loc)} is not a quantity a parameter can scale for kind {spec.kind!r}",
                    f"{fld}.applies_to",
                )
            for key in _product_keys(spec, loc):
                if key in owner:
                    raise c.err(
                        f"{location_str(loc)} scales the same model term as parameter {owner[key]!r}; "
                        "each term may carry one factor only (the model must stay affine)",
                        f"{fld}.applies_to",
                    )
            for key in _product_keys(spec, loc):
                owner[key] = name
        prior = _prior(c, p["prior"], f"{fld}.prior")
        out.append(ParameterSpec(name=name, applies_to=path, prior=prior, targets=targets))
    return out


def _product_keys(spec: StructureSpec, loc: Location) -> list[tuple]:
    """Model terms a location multiplies (see ``ModelKind.product_keys``)."""
    if loc[:1] == (spec.kind,):
        return spec.model_kind.product_keys(spec.section, loc)
    return [loc]
