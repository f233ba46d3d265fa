"""Packaging: what the sdist and the wheel carry, the console scripts, the declared dependencies.

The distributions are built from a copy of the repository (test data included, so that leaving
them out is the build's doing): no test data and no GPL-licensed file may travel inside this
Apache-2.0 package. Every node module has a console script. Every third-party module that
``shm_ros`` imports is declared for both installers: as a rosdep key in ``package.xml`` and as a
requirement for pip (``setup.py`` and ``requirements/base.txt``).
"""

from __future__ import annotations

import ast
import configparser
import io
import re
import shutil
import subprocess
import sys
import tarfile
import xml.etree.ElementTree as ET
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NODES = sorted(p.name[: -len("_node.py")] for p in (ROOT / "shm_ros" / "ros").glob("*_node.py"))
GPL_MARK = b"GNU GENERAL " + b"PUBLIC LICENSE"  # in pieces: this file travels in the sdist

# import name -> (rosdep key, PyPI distribution or None for ROS packages)
DEPENDENCIES: dict[str, tuple[str, str | None]] = {
    "numpy": ("python3-numpy", "numpy"),
    "scipy": ("python3-scipy", "scipy"),
    "yaml": ("python3-yaml", "PyYAML"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "numba": ("python3-numba", "numba"),
    "llvmlite": ("python3-llvmlite-pip", "llvmlite"),  # numba's own back end (a compiled kernel binds a LAPACK symbol)
    "rosbags": ("python3-rosbags-pip", "rosbags"),
    "mcap": ("python3-mcap-pip", "mcap"),
    "zstandard": ("python3-zstandard-pip", "zstandard"),
    "lz4": ("python3-lz4-pip", "lz4"),
    "emcee": ("python3-emcee-pip", "emcee"),
    "dynesty": ("python3-dynesty-pip", "dynesty"),
    "arviz": ("python3-arviz-pip", "arviz"),
    "arviz_stats": ("python3-arviz-stats-pip", "arviz-stats"),
    "threadpoolctl": ("python3-threadpoolctl-pip", "threadpoolctl"),
    "obspy": ("python3-obspy-pip", "obspy"),
    "dask": ("python3-dask-distributed-pip", "dask"),
    "apsw": ("python3-rosbags-pip", "rosbags"),  # rosbags' sqlite3 back end (only its error type is used)
    "rclpy": ("rclpy", None),
    "std_msgs": ("std_msgs", None),
    "sensor_msgs": ("sensor_msgs", None),
    "diagnostic_msgs": ("diagnostic_msgs", None),
    "builtin_interfaces": ("builtin_interfaces", None),
    "rcl_interfaces": ("rcl_interfaces", None),
    "rosgraph_msgs": ("rosgraph_msgs", None),
    "shm_interfaces": ("shm_interfaces", None),
    "lifecycle_msgs": ("lifecycle_msgs", None),
    "geometry_msgs": ("geometry_msgs", None),
    "tf2_msgs": ("tf2_msgs", None),
}


def _repository_files() -> list[str]:
    """The repository's files (one definition, shared with the self-contained check)."""
    from test_self_contained import repository_files

    return [p.relative_to(ROOT).as_posix() for p in repository_files()]


@pytest.fixture(scope="module")
def dists(tmp_path_factory) -> dict[str, dict[str, bytes]]:
    """{"sdist": {member: bytes}, "wheel": {member: bytes}} built from a copy of the repository."""
    tmp = tmp_path_factory.mktemp("packaging")
    src = tmp / "src"
    for name in _repository_files():
        dest = src / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, dest)
    assert list((src / "test" / "data").rglob("*.npy")), "the copy should hold the test data"
    out = tmp / "dist"
    sdist = subprocess.run([sys.executable, "setup.py", "-q", "sdist", "-d", str(out)], cwd=src,
                           capture_output=True, text=True, timeout=300)
    assert sdist.returncode == 0, sdist.stderr[-3000:]
    wheel = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                            "--no-index", "-w", str(out), str(src)], capture_output=True, text=True, timeout=300)
    assert wheel.returncode == 0, wheel.stdout[-3000:] + wheel.stderr[-3000:]
    (sd,) = out.glob("*.tar.gz")
    (wh,) = out.glob("*.whl")
    sdist_files = {}
    with tarfile.open(sd) as t:
        for m in t.getmembers():
            f = t.extractfile(m) if m.isfile() else None
            if f is not None:
                sdist_files[m.name] = f.read()
    with zipfile.ZipFile(wh) as z:
        wheel_files = {n: z.read(n) for n in z.namelist() if not n.endswith("/")}
    return {"sdist": sdist_files, "wheel": wheel_files}


@pytest.mark.parametrize("kind", ["sdist", "wheel"])
def test_no_test_data_and_no_gpl_file_inside(dists, kind):
    files = dists[kind]
    assert any(n.endswith("shm_ros/__init__.py") for n in files), sorted(files)[:20]
    data = [n for n in files if "test/data" in n or "test/truths" in n or n.endswith((".npy", ".V2", ".zip"))]
    assert not data, data
    gpl = [n for n, b in files.items() if GPL_MARK in b]
    assert not gpl, gpl


def test_wheel_has_a_console_script_for_every_node(dists):
    (ep,) = [b for n, b in dists["wheel"].items() if n.endswith(".dist-info/entry_points.txt")]
    cfg = configparser.ConfigParser()
    cfg.read_string(ep.decode())
    scripts = dict(cfg["console_scripts"])
    assert NODES and {"ingest", "identify", "track", "update", "recorder"} <= set(NODES)
    assert scripts["shm-ros"] == "shm_ros.cli:main"
    for node in NODES:
        assert scripts.get(f"shm-ros-{node}") == f"shm_ros.ros.{node}_node:main", node
        tree = ast.parse((ROOT / "shm_ros" / "ros" / f"{node}_node.py").read_text())
        assert any(isinstance(d, ast.FunctionDef) and d.name == "main" for d in tree.body), node
    # every node module is in the node registry (which names the console scripts, the launch file's
    # executables and the docs' table), and no shell wrapper travels as data
    from shm_ros.ros.registry import KINDS

    assert sorted(KINDS) == NODES
    assert not [n for n in dists["wheel"] if "/data/lib/shm_ros/" in n]


def test_wheel_ships_the_example_inputs_and_true_metadata(dists):
    """`shm-ros example` runs from an installed package: its inputs are package data; the package
    says the Python it needs (3.11: StrEnum, datetime.UTC)."""
    for kind in ("sdist", "wheel"):
        assert any(n.endswith("shm_ros/examples_data/main_job.yaml") for n in dists[kind]), kind
    (meta,) = [b for n, b in dists["wheel"].items() if n.endswith(".dist-info/METADATA")]
    assert Parser().parsestr(meta.decode())["Requires-Python"] == ">=3.11"


def test_wheel_installs_the_ros_package_metadata(dists):
    names = set(dists["wheel"])
    for path in ("share/ament_index/resource_index/packages/shm_ros", "share/shm_ros/package.xml",
                 "share/shm_ros/config/pipeline.yaml"):
        assert any(n.endswith(".data/data/" + path) for n in names), path


def test_setup_cfg_puts_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == "$base/lib/shm_ros"
    assert cfg["install"]["install_scripts"] == "$base/lib/shm_ros"


# -- dependencies -----------------------------------------------------------------------------

def _optional(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    """An import inside the body of ``try: ... except ImportError`` is an optional fallback."""
    child, cur = node, parents.get(node)
    while cur is not None:
        if isinstance(cur, ast.Try) and child in cur.body:
            caught: list[ast.expr] = []
            for h in cur.handlers:
                if isinstance(h.type, ast.Tuple):
                    caught += h.type.elts
                elif h.type is not None:
                    caught.append(h.type)
            if any(isinstance(e, ast.Name) and e.id in ("ImportError", "ModuleNotFoundError") for e in caught):
                return True
        child, cur = cur, parents.get(cur)
    return False


def third_party_imports() -> dict[str, set[str]]:
    """Top-level module -> files, for every absolute import in shm_ros/ outside the standard library."""
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / "shm_ros").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        parents = {c: p for p in ast.walk(tree) for c in ast.iter_child_nodes(p)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            if _optional(node, parents):
                continue
            for name in names:
                top = name.split(".")[0]
                if top != "shm_ros" and top not in sys.stdlib_module_names:
                    found.setdefault(top, set()).add(str(path.relative_to(ROOT)))
    return found


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_the_import_scan_sees_lazy_and_optional_imports():
    found = third_party_imports()
    assert {"numpy", "rclpy", "yaml", "dynesty"} <= set(found)  # dynesty only inside a function
    assert "backports" not in found and "compression" not in found  # try/except ImportError fallbacks


def test_package_xml_declares_every_imported_module():
    declared = {e.text.strip() for e in ET.parse(ROOT / "package.xml").getroot().iter("exec_depend") if e.text}
    missing = []
    for top, files in sorted(third_party_imports().items()):
        if top not in DEPENDENCIES:
            missing.append(f"{top} (imported by {sorted(files)}): add it to DEPENDENCIES with its rosdep key")
        elif DEPENDENCIES[top][0] not in declared:
            missing.append(f"{top}: <exec_depend>{DEPENDENCIES[top][0]}</exec_depend> missing in package.xml")
    assert not missing, "\n".join(missing)
    assert "sensor_msgs" in declared  # message types resolved by name at run time


def test_pip_requirements_cover_every_imported_python_module(dists):
    (meta,) = [b for n, b in dists["wheel"].items() if n.endswith(".dist-info/METADATA")]
    requires = {_normal(re.split(r"[\s;<>=!~\[]", r, maxsplit=1)[0])
                for r in Parser().parsestr(meta.decode()).get_all("Requires-Dist", [])}
    base = {_normal(re.split(r"[\s;<>=!~\[]", ln.strip(), maxsplit=1)[0])
            for ln in (ROOT / "requirements" / "base.txt").read_text().splitlines()
            if ln.strip() and not ln.lstrip().startswith("#")}
    missing = []
    for top in sorted(third_party_imports()):
        dist = DEPENDENCIES.get(top, (None, top))[1]
        if dist is None:
            continue  # ROS packages come from ROS (or the ROS wheels of requirements/ros-kilted.txt)
        if _normal(dist) not in requires:
            missing.append(f"{dist}: not in setup.py install_requires")
        if _normal(dist) not in base:
            missing.append(f"{dist}: not in requirements/base.txt")
    assert not missing, "\n".join(missing)


def test_rosdep_keys_outside_the_rosdep_database_are_defined_here():
    """The "-pip" keys the rosdep database lacks are defined in rosdep/shm_ros.yaml."""
    import yaml

    defined = yaml.safe_load(io.StringIO((ROOT / "rosdep" / "shm_ros.yaml").read_text()))
    in_database = {"python3-rosbags-pip"}
    for key, dist in DEPENDENCIES.values():
        if key.endswith("-pip") and key not in in_database:
            packages = defined[key]["ubuntu"]["pip"]["packages"]
            assert [re.split(r"\[", p, maxsplit=1)[0] for p in packages] == [dist], key
