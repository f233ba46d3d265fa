"""Typed form of a structure file (contracts section 2) and its parameter paths.

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
from typing import Any

import numpy as np

KINDS = ("girder", "shear_building", "matrices")
DIRECTIONS = ("vertical", "x", "y")
DEFAULT_AXIS = {"vertical": "z", "x": "x", "y": "y"}
PRIOR_PARAMS = {
    "normal": ("mean", "std"),
    "lognormal": ("mean", "std"),
    "weibull": ("scale", "shape"),
    "uniform": ("low", "high"),
}
SECTION_FIELDS = ("E", "I", "A", "rho")
BEARING_FIELDS = ("x", "k_vertical", "k_rotation")
FLOOR_FIELDS = ("mass", "stiffness")

Location = tuple[str | int, ...]


class StructureError(ValueError):
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
class SectionSpec:
    """Cross-section and material of a beam span (SI: Pa, m^4, m^2, kg/m^3)."""

    E: float
    I: float  # noqa: E741 - the usual name of the second moment of area
    A: float
    rho: float

    @property
    def EI(self) -> float:
        return self.E * self.I

    @property
    def mass_per_length(self) -> float:
        return self.rho * self.A


@dataclass
class BearingSpec:
    """A support at ``x`` (m from the left end): vertical (N/m) and rotational (N m/rad) springs."""

    x: float
    k_vertical: float
    k_rotation: float = 0.0


@dataclass
class GirderSpec:
    """2-D Euler-Bernoulli girder on bearings. ``sections`` has one entry per span.

    ``section_per_span`` records whether the file gave a list (one per span) or one section for all
    (then ``sections`` holds the same values repeated, and a path ``girder.section.E`` acts on all).
    """

    spans: list[float]
    elements_per_span: int
    sections: list[SectionSpec]
    bearings: list[BearingSpec]
    section_per_span: bool = False

    @property
    def length(self) -> float:
        return float(sum(self.spans))

    def span_ends(self) -> np.ndarray:
        """x of the span boundaries, (n_spans + 1,), starting at 0."""
        return np.concatenate([[0.0], np.cumsum(self.spans)])


@dataclass
class FloorSpec:
    """One floor of a shear building: its lumped mass (kg) and the stiffness of the story below (N/m)."""

    mass: float
    stiffness: float


@dataclass
class ShearBuildingSpec:
    """Floors bottom-up (floor 1 first); floor 0 is the ground and is not listed."""

    floors: list[FloorSpec]

    @property
    def n_floors(self) -> int:
        return len(self.floors)


@dataclass
class MatricesSpec:
    """User matrices: ``K = stiffness + sum factor_i * K_i``, ``M = mass + sum factor_j * M_j``.

    ``file`` is as written in the structure file (relative to it); ``arrays`` holds the loaded
    ``.npz`` contents (filled by ``shm_ros.io.structure.load_structure``). ``terms`` /
    ``mass_terms`` map array names to nominal factors (default 1.0 for every ``K<name>`` array other
    than the constant part). ``dofs`` optionally labels the DOFs.
    """

    file: str
    mass: str = "M"
    stiffness: str = "K0"
    terms: dict[str, float] = field(default_factory=dict)
    mass_terms: dict[str, float] = field(default_factory=dict)
    dofs: list[str] | None = None
    arrays: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def n_dof(self) -> int:
        return int(self.arrays[self.mass].shape[0]) if self.mass in self.arrays else 0


@dataclass
class DampingSpec:
    """``rayleigh``: ratios of the first two modes fix C = a0 M + a1 K; ``modal``: ratio per mode
    (the last one repeats for higher modes)."""

    kind: str = "rayleigh"
    ratios: list[float] = field(default_factory=lambda: [0.02, 0.02])


@dataclass
class SourceSpec:
    """Where a sensor's samples come from; defaults already resolved (contracts section 2).

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


@dataclass
class PriorSpec:
    """Prior of a multiplicative factor: normal{mean,std}, lognormal{mean,std} (of the factor itself,
    not of its log), weibull{scale,shape}, uniform{low,high}."""

    dist: str
    params: dict[str, float]

    def frozen(self):
        """The prior as a frozen ``scipy.stats`` distribution."""
        from scipy import stats

        p = self.params
        if self.dist == "normal":
            return stats.norm(loc=p["mean"], scale=p["std"])
        if self.dist == "lognormal":
            s2 = math.log1p((p["std"] / p["mean"]) ** 2)
            return stats.lognorm(s=math.sqrt(s2), scale=p["mean"] * math.exp(-0.5 * s2))
        if self.dist == "weibull":
            return stats.weibull_min(c=p["shape"], scale=p["scale"])
        if self.dist == "uniform":
            return stats.uniform(loc=p["low"], scale=p["high"] - p["low"])
        raise ValueError(f"unknown prior {self.dist!r}")


@dataclass
class ParameterSpec:
    """An updatable multiplicative factor; ``targets`` are the resolved locations of ``applies_to``."""

    name: str
    applies_to: str
    prior: PriorSpec
    targets: list[Location] = field(default_factory=list)


@dataclass
class StructureSpec:
    """A validated structure file. ``raw`` is the mapping as read; ``source`` names the file."""

    name: str
    kind: str
    girder: GirderSpec | None
    shear_building: ShearBuildingSpec | None
    matrices: MatricesSpec | None
    damping: DampingSpec
    sensors: list[SensorSpec]
    input_sensor: str | None
    parameters: list[ParameterSpec]
    raw: dict = field(default_factory=dict, repr=False)
    source: str = "<structure>"
    description: str | None = None

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
    def output_sensor_ids(self) -> list[str]:
        """Sensors other than the input sensor."""
        return [s.id for s in self.sensors if s.id != self.input_sensor]

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
        if self.girder is not None:
            g = self.girder
            secs = [_section_dict(s) for s in g.sections]
            out["girder"] = {
                "spans": [float(v) for v in g.spans],
                "elements_per_span": int(g.elements_per_span),
                # one mapping for all spans unless the file had a list or the spans now differ
                "section": secs if g.section_per_span or any(x != secs[0] for x in secs) else secs[0],
                "bearings": [
                    {"x": float(b.x), "k_vertical": float(b.k_vertical), "k_rotation": float(b.k_rotation)}
                    for b in g.bearings
                ],
            }
        if self.shear_building is not None:
            out["shear_building"] = {
                "floors": [
                    {"mass": float(f.mass), "stiffness": float(f.stiffness)} for f in self.shear_building.floors
                ]
            }
        if self.matrices is not None:
            m = self.matrices
            md: dict[str, Any] = {"file": m.file, "mass": m.mass, "stiffness": m.stiffness}
            md["terms"] = {k: float(v) for k, v in m.terms.items()}
            if m.mass_terms:
                md["mass_terms"] = {k: float(v) for k, v in m.mass_terms.items()}
            if m.dofs is not None:
                md["dofs"] = list(m.dofs)
            out["matrices"] = md
        out["damping"] = {"kind": self.damping.kind, "ratios": [float(r) for r in self.damping.ratios]}
        sensors = []
        for s in self.sensors:
            sd: dict[str, Any] = {"id": s.id, "at": dict(s.at), "direction": s.direction}
            src: dict[str, Any] = {}
            if s.source.topic is not None:
                src["topic"] = s.source.topic
            if s.source.channel is not None:
                src["channel"] = s.source.channel
            src["axis"] = s.source.axis
            src["sign"] = float(s.source.sign)
            sd["source"] = src
            sensors.append(sd)
        out["sensors"] = sensors
        if self.input_sensor is not None:
            out["input"] = {"sensor": self.input_sensor}
        out["parameters"] = [
            {"name": p.name, "applies_to": p.applies_to, "prior": {"dist": p.prior.dist, **p.prior.params}}
            for p in self.parameters
        ]
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
        arrays = self.matrices.arrays if self.matrices is not None else None
        return structure_from_dict(data, source=self.source, matrices_arrays=arrays)


def _section_dict(s: SectionSpec) -> dict[str, float]:
    return {"E": float(s.E), "I": float(s.I), "A": float(s.A), "rho": float(s.rho)}


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
    if kind == "girder":
        if loc[:2] == ("girder", "section"):
            return loc[-1] in SECTION_FIELDS and len(loc) in (3, 4)
        if loc[:2] == ("girder", "bearings") and len(loc) == 4:
            return loc[-1] in ("k_vertical", "k_rotation")
    if kind == "shear_building":
        return loc[:2] == ("shear_building", "floors") and len(loc) == 4 and loc[-1] in FLOOR_FIELDS
    if kind == "matrices":
        return loc[:2] in (("matrices", "terms"), ("matrices", "mass_terms")) and len(loc) == 3
    return False


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------


class _Ctx:
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
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            try:
                v = float(v)  # YAML 1.1 reads "5.0e9" without a dot as a string
            except (TypeError, ValueError):
                raise self.err(f"must be a number, got {v!r}", fld) from None
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
            raise self.err(f"must be an integer, got {v!r}", fld)
        v = int(v)
        if minimum is not None and v < minimum:
            raise self.err(f"must be >= {minimum}, got {v}", fld)
        return v

    def string(self, v: Any, fld: str) -> str:
        if not isinstance(v, str) or not v:
            raise self.err(f"must be a non-empty string, got {v!r}", fld)
        return v

    def keys(self, m: Mapping, allowed: tuple[str, ...], required: tuple[str, ...], fld: str) -> None:
        for k in m:
            if k not in allowed:
                where = f"{fld}.{k}" if fld else str(k)
                raise self.err(f"unknown field {k!r} (allowed: {', '.join(allowed)})", where)
        for k in required:
            if k not in m:
                raise self.err("missing required field", f"{fld}.{k}" if fld else k)


_TOP = (
    "name", "kind", "description", "girder", "shear_building", "matrices", "damping", "sensors", "input", "parameters",
)


def structure_from_dict(
    data: Mapping, source: str = "<structure>", matrices_arrays: Mapping[str, np.ndarray] | None = None
) -> StructureSpec:
    """Validate a structure-file mapping. ``matrices_arrays``: the ``.npz`` contents for ``kind: matrices``."""
    c = _Ctx(source)
    data = c.mapping(data, "")
    c.keys(data, _TOP, ("name", "kind", "sensors"), "")
    name = c.string(data["name"], "name")
    kind = data["kind"]
    if kind not in KINDS:
        raise c.err(f"unknown kind {kind!r} (expected one of: {', '.join(KINDS)})", "kind")
    if kind not in data:
        raise c.err(f"kind is {kind!r} but the section {kind!r} is missing", kind)
    # Sections of the other kinds may be present (a file may carry both a girder and a building
    # description, contracts section 2); only the one named by ``kind`` is read, the rest stays in
    # ``raw``.

    girder = _girder(c, data["girder"]) if kind == "girder" else None
    building = _building(c, data["shear_building"]) if kind == "shear_building" else None
    matrices = _matrices(c, data["matrices"], matrices_arrays) if kind == "matrices" else None

    damping = _damping(c, data.get("damping", {"kind": "rayleigh", "ratios": [0.02, 0.02]}))
    sensors = _sensors(c, data["sensors"], kind, girder, building, matrices)
    input_sensor = None
    if "input" in data and data["input"] is not None:
        inp = c.mapping(data["input"], "input")
        c.keys(inp, ("sensor",), ("sensor",), "input")
        input_sensor = c.string(inp["sensor"], "input.sensor")
        if input_sensor not in {s.id for s in sensors}:
            raise c.err(f"names sensor {input_sensor!r}, which is not in sensors", "input.sensor")

    description = data.get("description")
    spec = StructureSpec(
        name=name,
        kind=kind,
        girder=girder,
        shear_building=building,
        matrices=matrices,
        damping=damping,
        sensors=sensors,
        input_sensor=input_sensor,
        parameters=[],
        raw=copy.deepcopy(dict(data)),
        source=source,
        description=None if description is None else str(description),
    )
    spec.parameters = _parameters(c, data.get("parameters") or [], spec)
    return spec


def _section(c: _Ctx, v: Any, fld: str) -> SectionSpec:
    m = c.mapping(v, fld)
    c.keys(m, SECTION_FIELDS, SECTION_FIELDS, fld)
    return SectionSpec(**{k: c.number(m[k], f"{fld}.{k}", positive=True) for k in SECTION_FIELDS})


def _girder(c: _Ctx, v: Any) -> GirderSpec:
    g = c.mapping(v, "girder")
    c.keys(g, ("spans", "elements_per_span", "section", "bearings"), ("spans", "section", "bearings"), "girder")
    spans = [
        c.number(s, f"girder.spans[{i}]", positive=True) for i, s in enumerate(c.seq(g["spans"], "girder.spans"))
    ]
    if not spans:
        raise c.err("needs at least one span", "girder.spans")
    eps = c.integer(g.get("elements_per_span", 10), "girder.elements_per_span", minimum=1)
    sec = g["section"]
    if isinstance(sec, list):
        if len(sec) != len(spans):
            raise c.err(f"has {len(sec)} entries but there are {len(spans)} spans", "girder.section")
        sections = [_section(c, s, f"girder.section[{i}]") for i, s in enumerate(sec)]
        per_span = True
    else:
        one = _section(c, sec, "girder.section")
        sections = [copy.copy(one) for _ in spans]
        per_span = False
    length = sum(spans)
    bearings = []
    for i, b in enumerate(c.seq(g["bearings"], "girder.bearings")):
        fld = f"girder.bearings[{i}]"
        b = c.mapping(b, fld)
        c.keys(b, BEARING_FIELDS, ("x", "k_vertical"), fld)
        x = c.number(b["x"], f"{fld}.x")
        if not -1e-9 * length <= x <= length * (1 + 1e-9):
            raise c.err(f"x = {x} is outside the girder [0, {length}]", f"{fld}.x")
        bearings.append(
            BearingSpec(
                x=min(max(x, 0.0), length),
                k_vertical=c.number(b["k_vertical"], f"{fld}.k_vertical", nonneg=True),
                k_rotation=c.number(b.get("k_rotation", 0.0), f"{fld}.k_rotation", nonneg=True),
            )
        )
    if sum(1 for b in bearings if b.k_vertical > 0) < 1 or (
        sum(1 for b in bearings if b.k_vertical > 0) < 2 and not any(b.k_rotation > 0 for b in bearings)
    ):
        raise c.err(
            "the girder needs at least two vertical bearings (or one with rotational stiffness)", "girder.bearings"
        )
    return GirderSpec(
        spans=spans, elements_per_span=eps, sections=sections, bearings=bearings, section_per_span=per_span
    )


def _building(c: _Ctx, v: Any) -> ShearBuildingSpec:
    b = c.mapping(v, "shear_building")
    c.keys(b, ("floors",), ("floors",), "shear_building")
    floors = []
    for i, f in enumerate(c.seq(b["floors"], "shear_building.floors")):
        fld = f"shear_building.floors[{i}]"
        f = c.mapping(f, fld)
        c.keys(f, FLOOR_FIELDS, FLOOR_FIELDS, fld)
        floors.append(
            FloorSpec(
                mass=c.number(f["mass"], f"{fld}.mass", positive=True),
                stiffness=c.number(f["stiffness"], f"{fld}.stiffness", positive=True),
            )
        )
    if not floors:
        raise c.err("needs at least one floor", "shear_building.floors")
    return ShearBuildingSpec(floors=floors)


def _matrices(c: _Ctx, v: Any, arrays: Mapping[str, np.ndarray] | None) -> MatricesSpec:
    m = c.mapping(v, "matrices")
    c.keys(m, ("file", "mass", "stiffness", "terms", "mass_terms", "dofs"), ("file",), "matrices")
    spec = MatricesSpec(
        file=c.string(m["file"], "matrices.file"),
        mass=c.string(m.get("mass", "M"), "matrices.mass"),
        stiffness=c.string(m.get("stiffness", "K0"), "matrices.stiffness"),
    )
    arrays = {k: np.asarray(a, dtype=float) for k, a in (arrays or {}).items()}
    if not arrays:
        raise c.err(
            f"no matrices loaded from {spec.file!r} (load the file with shm_ros.io.structure)", "matrices.file"
        )
    where = f"{spec.file}"
    for key in (spec.mass, spec.stiffness):
        if key not in arrays:
            fld = "matrices.mass" if key == spec.mass else "matrices.stiffness"
            raise c.err(f"array {key!r} not found in {where} (has {sorted(arrays)})", fld)
    n = arrays[spec.mass].shape[0] if arrays[spec.mass].ndim == 2 else -1
    if "terms" in m:
        spec.terms = {
            str(k): c.number(f, f"matrices.terms.{k}") for k, f in c.mapping(m["terms"], "matrices.terms").items()
        }
    else:
        spec.terms = {k: 1.0 for k in sorted(arrays) if k.startswith("K") and k != spec.stiffness}
    if "mass_terms" in m:
        spec.mass_terms = {
            str(k): c.number(f, f"matrices.mass_terms.{k}")
            for k, f in c.mapping(m["mass_terms"], "matrices.mass_terms").items()
        }
    for key in [spec.mass, spec.stiffness, *spec.terms, *spec.mass_terms]:
        fld = "matrices.mass" if key == spec.mass else "matrices.stiffness" if key == spec.stiffness else (
            f"matrices.terms.{key}" if key in spec.terms else f"matrices.mass_terms.{key}"
        )
        if key not in arrays:
            raise c.err(f"array {key!r} not found in {where} (has {sorted(arrays)})", fld)
        a = arrays[key]
        if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] != n:
            raise c.err(f"array {key!r} in {where} must be square {n}x{n}, got shape {a.shape}", fld)
        if not np.all(np.isfinite(a)):
            raise c.err(f"array {key!r} in {where} has non-finite entries", fld)
        if not np.allclose(a, a.T, rtol=1e-9, atol=1e-12 * max(1.0, float(np.abs(a).max()))):
            raise c.err(f"array {key!r} in {where} is not symmetric", fld)
    try:
        np.linalg.cholesky(arrays[spec.mass])
    except np.linalg.LinAlgError:
        raise c.err(
            f"mass matrix {spec.mass!r} in {where} is not positive definite (massless DOFs must be condensed "
            "out before export)",
            "matrices.mass",
        ) from None
    if "dofs" in m:
        dofs = [str(d) for d in c.seq(m["dofs"], "matrices.dofs")]
        if len(dofs) != n:
            raise c.err(f"has {len(dofs)} labels but the matrices have {n} DOFs", "matrices.dofs")
        spec.dofs = dofs
    spec.arrays = arrays
    return spec


def _damping(c: _Ctx, v: Any) -> DampingSpec:
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


def _sensors(c: _Ctx, v: Any, kind: str, girder, building, matrices) -> list[SensorSpec]:
    out: list[SensorSpec] = []
    seen: set[str] = set()
    for i, s in enumerate(c.seq(v, "sensors")):
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
        at = dict(c.mapping(s["at"], f"{fld}.at"))
        if kind == "girder":
            c.keys(at, ("x",), ("x",), f"{fld}.at")
            x = c.number(at["x"], f"{fld}.at.x")
            if not -1e-9 <= x <= girder.length * (1 + 1e-9):
                raise c.err(f"x = {x} is outside the girder [0, {girder.length}]", f"{fld}.at.x")
            if direction != "vertical":
                raise c.err("a girder sensor must be vertical", f"{fld}.direction")
            at = {"x": x}
        elif kind == "shear_building":
            c.keys(at, ("floor",), ("floor",), f"{fld}.at")
            fl = c.integer(at["floor"], f"{fld}.at.floor", minimum=0)
            if fl > building.n_floors:
                raise c.err(
                    f"floor {fl} does not exist (the building has {building.n_floors} floors)", f"{fld}.at.floor"
                )
            if direction == "vertical":
                raise c.err("a shear-building sensor must be horizontal (x or y)", f"{fld}.direction")
            at = {"floor": fl}
        else:
            c.keys(at, ("dof",), ("dof",), f"{fld}.at")
            d = at["dof"]
            if isinstance(d, str):
                if matrices.dofs is None or d not in matrices.dofs:
                    raise c.err(f"DOF label {d!r} is not in matrices.dofs", f"{fld}.at.dof")
            else:
                d = c.integer(d, f"{fld}.at.dof", minimum=0)
                if d >= matrices.n_dof:
                    raise c.err(f"DOF {d} does not exist (the matrices have {matrices.n_dof} DOFs)", f"{fld}.at.dof")
            at = {"dof": d}
        source = _source(c, s.get("source"), sid, direction, fld)
        out.append(SensorSpec(id=sid, at=at, direction=direction, source=source))
    if not out:
        raise c.err("needs at least one sensor", "sensors")
    return out


def _source(c: _Ctx, v: Any, sid: str, direction: str, fld: str) -> SourceSpec:
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


def _prior(c: _Ctx, v: Any, fld: str) -> PriorSpec:
    m = c.mapping(v, fld)
    if "dist" not in m:
        raise c.err("missing required field", f"{fld}.dist")
    dist = m["dist"]
    if dist not in PRIOR_PARAMS:
        raise c.err(f"unknown prior {dist!r} (expected one of: {', '.join(PRIOR_PARAMS)})", f"{fld}.dist")
    need = PRIOR_PARAMS[dist]
    c.keys(m, ("dist", *need), need, fld)
    p = {k: c.number(m[k], f"{fld}.{k}") for k in need}
    if dist in ("normal", "lognormal") and p["std"] <= 0:
        raise c.err(f"must be > 0, got {p['std']}", f"{fld}.std")
    if dist == "lognormal" and p["mean"] <= 0:
        raise c.err(f"must be > 0 for a lognormal prior, got {p['mean']}", f"{fld}.mean")
    if dist == "weibull":
        for k in need:
            if p[k] <= 0:
                raise c.err(f"must be > 0, got {p[k]}", f"{fld}.{k}")
    if dist == "uniform" and not p["low"] < p["high"]:
        raise c.err(f"low ({p['low']}) must be below high ({p['high']})", f"{fld}.high")
    return PriorSpec(dist=dist, params=p)


def _parameters(c: _Ctx, v: Any, spec: StructureSpec) -> list[ParameterSpec]:
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
    """Model terms a location multiplies: E and I share the bending stiffness of a span, rho and A
    share its mass, so two factors on them would make the model non-affine."""
    if spec.kind == "girder" and loc[:2] == ("girder", "section"):
        spans = [loc[2]] if len(loc) == 4 else list(range(len(spec.girder.spans)))
        term = "EI" if loc[-1] in ("E", "I") else "rhoA"
        return [("girder", term, k) for k in spans]
    return [loc]
