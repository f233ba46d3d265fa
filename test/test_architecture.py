"""Issue "architecture a newcomer can live in": the package's layering rules, checked on the source.

* no import cycle between modules of ``shm_ros`` (module-level and function-level imports);
* ``shm_ros.core`` imports neither ROS (rclpy, message packages) nor ``shm_ros.io/ros/report/commands``;
* a new structure kind is one new file: a kind written to a temporary file (loaded explicitly, or
  named by ``SHM_ROS_KINDS``) is found, builds its model through ``build_model`` and is accepted by
  the structure-file loader.

Import graph: nodes are modules (a package is its ``__init__``). ``import a.b.c`` and
``from a.b import c`` (``c`` a submodule) are edges to ``a.b.c``; ``from a.b import name`` (``name``
not a submodule) is an edge to ``a.b``. Imports under ``if TYPE_CHECKING:`` are left out: they never
run, and annotations are how two layers may name each other's types without depending on each other.
"""

from __future__ import annotations

import ast
import functools
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "shm_ros"
ROS_PACKAGES = ("rclpy", "std_msgs", "sensor_msgs", "diagnostic_msgs", "builtin_interfaces", "rcl_interfaces",
                "shm_interfaces")
OUTER_LAYERS = ("shm_ros.io", "shm_ros.ros", "shm_ros.report", "shm_ros.commands")


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (p, is_pkg)
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, at any depth, except those under ``if TYPE_CHECKING:``."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for stmt in node.orelse:
                visit(stmt)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _imported_names(module: str, is_pkg: bool, tree: ast.AST) -> list[str]:
    """Absolute dotted names the module imports (all packages, not only ``shm_ros``)."""
    package = module if is_pkg else module.rpartition(".")[0]
    out = []
    for node in _imports(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
            continue
        if node.level:
            base = package.split(".")
            base = base[: len(base) - (node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module or ""
        # ``from pkg import sub`` names the submodule, ``from pkg import name`` an attribute of pkg
        out += [f"{target}.{a.name}" for a in node.names]
    return out


def _graph() -> dict[str, set[str]]:
    """The package's import graph (parsed once per test process; callers get their own copy)."""
    return {m: set(t) for m, t in _parsed_graph().items()}


@functools.cache
def _parsed_graph() -> dict[str, set[str]]:
    mods = _modules()
    edges: dict[str, set[str]] = {}
    for m, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        targets: set[str] = set()
        for name in _imported_names(m, is_pkg, tree):
            while name and name not in mods:  # an attribute of a module: an import of that module
                name = name.rpartition(".")[0]
            if name and name != m:
                targets.add(name)
        edges[m] = targets
    return edges


def _find_cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One cycle as a path [a, b, ..., a], or None (iterative depth-first search)."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    for start in sorted(edges):
        if start in state:
            continue
        stack: list[tuple[str, list[str]]] = [(start, sorted(edges[start]))]
        path = [start]
        state[start] = 1
        while stack:
            node, todo = stack[-1]
            if not todo:
                state[node] = 2
                stack.pop()
                path.pop()
                continue
            nxt = todo.pop(0)
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                state[nxt] = 1
                path.append(nxt)
                stack.append((nxt, sorted(edges.get(nxt, ()))))
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set()}) is None


def test_type_checking_imports_are_left_out_and_function_imports_kept():
    tree = ast.parse(textwrap.dedent("""
        from typing import TYPE_CHECKING
        if TYPE_CHECKING:
            from shm_ros.core.structure import StructureSpec
        def f():
            from shm_ros.core import modal
    """))
    names = _imported_names("shm_ros.core.x", False, tree)
    assert "shm_ros.core.modal" in names and "shm_ros.core.structure" not in names


def test_no_import_cycle_between_modules():
    edges = _graph()
    assert "shm_ros.core.models.registry" in edges["shm_ros.core.structure"]  # the graph sees imports
    cycle = _find_cycle(edges)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_core_imports_no_ros_and_no_outer_layer():
    bad = []
    for m, (path, is_pkg) in _modules().items():
        if not (m == "shm_ros.core" or m.startswith("shm_ros.core.")):
            continue
        for name in _imported_names(m, is_pkg, ast.parse(path.read_text(encoding="utf-8"))):
            top = name.split(".")[0]
            if top in ROS_PACKAGES or any(name == o or name.startswith(o + ".") for o in OUTER_LAYERS):
                bad.append(f"{path.relative_to(ROOT)}: {name}")
    assert not bad, "shm_ros.core must not import ROS or io/ros/report/commands:\n" + "\n".join(sorted(set(bad)))


# ------------------------------------------------------------------------------------------------
# A new structure kind is one file
# ------------------------------------------------------------------------------------------------

DUMMY_KIND = '''
"""Two masses on springs in a chain (ground - k1 - m1 - k2 - m2): a kind in one file."""

from dataclasses import dataclass

import numpy as np

from shm_ros.core.models.base import assemble_model, damping_factors_of
from shm_ros.core.models.registry import ModelKind, register


@dataclass
class SpringMassSpec:
    masses: list
    springs: list


@register("dummy")
class Dummy(ModelKind):
    title = "two-mass spring chain"

    def parse_section(self, r, value, arrays):
        m = r.mapping(value, "dummy")
        r.keys(m, ("masses", "springs"), ("masses", "springs"), "dummy")
        masses, springs = ([r.number(v, f"dummy.{key}[{i}]", positive=True)
                            for i, v in enumerate(r.seq(m[key], "dummy." + key))] for key in ("masses", "springs"))
        if len(masses) != 2 or len(springs) != 2:
            raise r.err("needs two masses and two springs", "dummy")
        return SpringMassSpec(masses, springs)

    def section_to_dict(self, section):
        return {"masses": list(section.masses), "springs": list(section.springs)}

    def sensor_location(self, r, section, at, direction, fld):
        r.keys(at, ("mass",), ("mass",), fld + ".at")
        k = r.integer(at["mass"], fld + ".at.mass", minimum=1)
        if k > 2:
            raise r.err(f"mass {k} does not exist", fld + ".at.mass")
        return {"mass": k}

    def updatable(self, loc):
        return loc[:2] == ("dummy", "springs") and len(loc) == 3

    def default_sensors(self, section):
        return [{"id": f"m{k}", "at": {"mass": k}, "direction": "x"} for k in (1, 2)]

    def build(self, spec, include_parameters=True):
        s = spec.section
        params = spec.parameters if include_parameters else []
        k1, k2 = s.springs
        parts = [np.array([[k1, 0.0], [0.0, 0.0]]), np.array([[k2, -k2], [-k2, k2]])]
        owner = {int(loc[2]): i for i, p in enumerate(params) for loc in p.targets if loc[:2] == ("dummy", "springs")}
        K0 = sum(parts[j] for j in range(2) if j not in owner)
        K_terms = [sum((parts[j] for j, i in owner.items() if i == n), np.zeros((2, 2))) for n in range(len(params))]
        M0 = np.diag(s.masses)
        sensor_dofs = {x.id: x.at["mass"] - 1 for x in spec.sensors}
        return assemble_model(spec, params, K0 + np.zeros((2, 2)), M0, K_terms, [np.zeros((2, 2))] * len(params),
                              ["m1", "m2"], sensor_dofs, damping_factors_of(params), kind="dummy")
'''


@pytest.fixture
def dummy_kind(tmp_path):
    from shm_ros.core.models.registry import MODEL_KINDS
    from shm_ros.core.plugins import load_kind_module

    path = tmp_path / "dummy_kind.py"
    path.write_text(DUMMY_KIND, encoding="utf-8")
    load_kind_module(path)
    yield path
    MODEL_KINDS.unregister("dummy")


def test_a_new_kind_is_one_file(dummy_kind, tmp_path):
    from shm_ros.core.models import build_model
    from shm_ros.core.models.registry import kind_names, model_kind
    from shm_ros.io.structure import dump_structure, load_structure

    assert "dummy" in kind_names()
    kind = model_kind("dummy")
    section = {"masses": [1000.0, 1000.0], "springs": [4.0e6, 4.0e6]}
    data = {
        "name": "two masses",
        "kind": "dummy",
        "dummy": section,
        "sensors": kind.default_sensors(kind.parse_section(_reader(), section, None)),
        "parameters": [{"name": "k2", "applies_to": "dummy.springs[1]",
                        "prior": {"dist": "lognormal", "mean": 1.0, "std": 0.1}}],
    }
    import yaml

    path = tmp_path / "two_masses.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    spec = load_structure(path)
    assert spec.kind == "dummy" and spec.dummy is spec.section and spec.girder is None
    model = build_model(spec)
    # 2-DOF chain with m1 = m2 = m, k1 = k2 = k: omega^2 = (3 -+ sqrt 5) / 2 * k / m
    k, m = 4.0e6, 1000.0
    expect = np.sqrt((3 - np.sqrt(5)) / 2 * np.array([1.0, 1.0]) * k / m) / (2 * np.pi)
    expect[1] = np.sqrt((3 + np.sqrt(5)) / 2 * k / m) / (2 * np.pi)
    np.testing.assert_allclose(model.modes(n_modes=2).frequencies_hz, expect, rtol=1e-10)
    assert model.parameter_names == ["k2"]
    softer = model.modes(model.theta_vector({"k2": 0.5}), n_modes=2).frequencies_hz
    assert np.all(softer < expect)
    # round trip through the file form, and errors name the file and the field
    dump_structure(spec, tmp_path / "again.yaml")
    assert load_structure(tmp_path / "again.yaml").to_dict() == spec.to_dict()
    from shm_ros.core.structure import StructureError

    bad = dict(data, sensors=[{"id": "x", "at": {"mass": 3}, "direction": "x"}])
    path.write_text(yaml.safe_dump(bad), encoding="utf-8")
    with pytest.raises(StructureError, match=r"two_masses.yaml: field 'sensors\[0\].at.mass'"):
        load_structure(path)


def test_unknown_kind_lists_the_registered_kinds(dummy_kind):
    from shm_ros.core.structure import StructureError, structure_from_dict

    with pytest.raises(StructureError, match="unknown kind 'truss'.*dummy.*girder"):
        structure_from_dict({"name": "x", "kind": "truss", "sensors": []}, source="t.yaml")


def test_builtin_kinds_default_sensors_are_valid():
    from shm_ros.core.models import build_model
    from shm_ros.core.models.registry import model_kind
    from shm_ros.core.structure import structure_from_dict

    sections = {
        "girder": {"spans": [20.0, 30.0], "elements_per_span": 6,
                   "section": {"E": 3.4e10, "I": 0.9, "A": 4.0, "rho": 2500.0},
                   "bearings": [{"x": 0.0, "k_vertical": 5e9}, {"x": 20.0, "k_vertical": 5e9},
                                {"x": 50.0, "k_vertical": 5e9}]},
        "shear_building": {"floors": [{"mass": 2e5, "stiffness": 3e8}] * 3},
    }
    for name, section in sections.items():
        kind = model_kind(name)
        assert kind.title
        sensors = kind.default_sensors(kind.parse_section(_reader(), section, None))
        spec = structure_from_dict({"name": name, "kind": name, name: section, "sensors": sensors})
        model = build_model(spec)
        assert model.kind == name and model.modes(n_modes=2).frequencies_hz[0] > 0


def _reader():
    from shm_ros.core.structure import FieldReader

    return FieldReader("<test>")


def test_a_kind_file_named_in_the_environment_is_found(tmp_path):
    """``SHM_ROS_KINDS`` lets a user add a kind without editing or packaging anything."""
    import os
    import subprocess
    import sys

    (tmp_path / "kinds").mkdir()
    (tmp_path / "kinds" / "dummy_kind.py").write_text(DUMMY_KIND, encoding="utf-8")
    env = dict(os.environ, SHM_ROS_KINDS=str(tmp_path / "kinds"), PYTHONPATH=str(ROOT))
    code = ("from shm_ros.core.models.registry import kind_names, model_kind; "
            "print(kind_names(), model_kind('dummy').title)")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "'dummy'" in out.stdout and "two-mass spring chain" in out.stdout


# ------------------------------------------------------------------------------------------------
# Stage order (docs/architecture.md): imports only go down a partial order of layers
# ------------------------------------------------------------------------------------------------

# module (or package) prefix -> layer; the longest matching prefix decides
LAYER_OF = {
    "shm_ros": "foundation", "shm_ros.errors": "foundation", "shm_ros.core": "foundation",
    "shm_ros.core.types": "foundation", "shm_ros.core.structure": "foundation",
    "shm_ros.core.config": "foundation", "shm_ros.core.plugins": "foundation",
    "shm_ros.core.modal": "foundation", "shm_ros.core.timeutil": "foundation",
    "shm_ros.core.progress": "foundation", "shm_ros.core.provenance": "foundation",
    "shm_ros.core.diagnostics": "foundation", "shm_ros.core.priors": "foundation",
    "shm_ros.core.observations": "foundation", "shm_ros.core.delay": "foundation",
    "shm_ros.core.mode_pairing": "foundation",
    # the kind registry is what the structure loader dispatches on; the kinds themselves are models
    "shm_ros.core.models.registry": "foundation",
    "shm_ros.core.models": "models",
    "shm_ros.core.ingest": "ingest",
    "shm_ros.core.identify": "identify", "shm_ros.core.ssi": "identify", "shm_ros.core.eigen": "identify",
    "shm_ros.core.stabilization": "identify", "shm_ros.core.band": "identify",
    "shm_ros.core.preprocess": "identify", "shm_ros.core.event_analysis": "identify",
    "shm_ros.core.tracking": "tracking",
    "shm_ros.core.roving": "roving",
    "shm_ros.core.response": "response",
    "shm_ros.core.simulate": "simulate",
    "shm_ros.core.bayes": "bayes",
    "shm_ros.core.predict": "predict",
    "shm_ros.core.explain": "explain",
    "shm_ros.io": "io", "shm_ros.report": "report", "shm_ros.batch": "batch",
    "shm_ros.commands": "commands", "shm_ros.ros": "ros", "shm_ros.cli": "cli",
}
# layer -> the layers directly below it (what it may import, with what those may import)
DIRECTLY_BELOW = {
    "foundation": set(),
    "models": {"foundation"},
    "ingest": {"models"}, "tracking": {"models"}, "response": {"models"}, "simulate": {"models"},
    "identify": {"ingest"},
    "roving": {"identify"},  # a robot's roving sensors: setups identified and merged
    "bayes": {"tracking", "response"},
    "predict": {"bayes"},
    "explain": {"predict"},
    "io": {"explain", "identify", "simulate", "roving"},
    "report": {"io"}, "batch": {"io"},
    # the command line and the nodes are the two faces of the same top layer: they may use each other
    "commands": {"report", "batch", "ros"}, "ros": {"report", "batch", "commands"},
    "cli": {"commands"},
}


def _below(layer: str) -> set[str]:
    """Every layer ``layer`` may import (itself included): the closure of DIRECTLY_BELOW."""
    seen, todo = {layer}, [layer]
    while todo:
        for lower in DIRECTLY_BELOW[todo.pop()]:
            if lower not in seen:
                seen.add(lower)
                todo.append(lower)
    return seen


def _layer(module: str) -> str:
    name = module
    while name not in LAYER_OF:
        name = name.rpartition(".")[0]
        assert name, f"module {module} has no layer in LAYER_OF"
    return LAYER_OF[name]


def _order_violations(edges: dict[str, set[str]]) -> list[str]:
    bad = []
    for a, targets in edges.items():
        allowed = _below(_layer(a))
        bad += [f"{a} ({_layer(a)}) imports {b} ({_layer(b)})" for b in sorted(targets)
                if b.startswith("shm_ros") and _layer(b) not in allowed]
    return sorted(bad)


def test_every_module_has_a_layer_and_the_order_is_acyclic():
    assert all(_layer(m) in DIRECTLY_BELOW for m in _modules())
    for layer in DIRECTLY_BELOW:  # a layer is never below a layer it may import, except peers named so
        for lower in _below(layer) - {layer}:
            assert layer not in _below(lower) or {layer, lower} == {"commands", "ros"}, (layer, lower)


def test_imports_follow_the_stage_order():
    bad = _order_violations(_graph())
    assert not bad, "imports against the stage order (docs/architecture.md):\n" + "\n".join(bad)


@pytest.mark.parametrize("planted", [
    "from shm_ros.core.bayes.update import update\n",  # module level
    "def f():\n    from shm_ros.core.predict import batch\n",  # function level, a stage two layers up
])
def test_a_planted_import_against_the_order_is_caught(planted):
    edges = _graph()
    mods = _modules()
    extra = set()
    for name in _imported_names("shm_ros.core.tracking.batch", False, ast.parse(planted)):
        while name not in mods:
            name = name.rpartition(".")[0]
        extra.add(name)
    edges["shm_ros.core.tracking.batch"] = edges["shm_ros.core.tracking.batch"] | extra
    bad = _order_violations(edges)
    assert bad and all(b.startswith("shm_ros.core.tracking.batch (tracking) imports") for b in bad), bad
