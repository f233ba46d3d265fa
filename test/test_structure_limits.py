"""Structure files cannot hurt the reader: an alias bomb, an oversized file and a model-size bomb
(> 20,000 degrees of freedom, also declared in an .npz header) fail fast with a clear error - within
3x the time a valid file takes - the limit is raised only by the caller; every numeric field of the
example files refuses a boolean and text; a file the structure names stays in its folder unless
allowed."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from shm_ros.core.structure import StructureError
from shm_ros.io.structure import StructureLimits, load_structure

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
GIRDER = (EXAMPLES / "girder.yaml").read_text()


def _fastest(fn, n=5) -> float:
    best = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        try:
            fn()
        except StructureError:
            pass
        best = min(best, time.perf_counter() - t)
    return best


def _alias_bomb(levels=9, fan=9) -> str:
    lines = ["a0: &a0 [1, 2, 3, 4, 5, 6, 7, 8, 9]"]
    for k in range(1, levels + 1):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * fan) + "]")
    return "\n".join(lines) + "\nname: bomb\nkind: girder\n"


@pytest.fixture
def valid_time(tmp_path):
    p = tmp_path / "valid.yaml"
    p.write_text(GIRDER)
    load_structure(p)  # warm caches and imports
    return _fastest(lambda: load_structure(p))


@pytest.mark.parametrize("bomb", ["alias", "recursive", "girder_dof", "npz_dof", "size"])
def test_bombs_fail_fast_with_a_clear_error(tmp_path, valid_time, bomb):
    p = tmp_path / f"{bomb}.yaml"
    match = {"alias": "expands to more than", "recursive": "refers to a node that contains it",
             "size": "more than the limit", "npz_dof": "degrees of freedom"}.get(bomb, "degrees of freedom")
    if bomb == "alias":
        p.write_text(_alias_bomb())  # 9^10 leaves once expanded
    elif bomb == "recursive":
        p.write_text("name: &n [x, *n]\nkind: girder\n")
    elif bomb == "girder_dof":
        p.write_text(GIRDER.replace("elements_per_span: 10 ", "elements_per_span: 100000000"))
        assert "100000000" in p.read_text()
    elif bomb == "npz_dof":
        # a header declaring a 30000 x 30000 matrix (7 GB) over a few bytes: refused from the header
        shutil.copy(EXAMPLES / "matrices.yaml", p)
        import zipfile

        with zipfile.ZipFile(tmp_path / "matrices.npz", "w") as z:
            with z.open("M.npy", "w") as fh:
                np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False,
                                                          "shape": (30000, 30000)})
                fh.write(b"\0" * 64)
    else:
        p.write_text("name: big\n" + "# padding\n" * 500_000)
    with pytest.raises(StructureError, match=match) as info:
        load_structure(p)
    assert str(p) in str(info.value) and len(str(info.value).replace(str(tmp_path), "")) < 250
    took = _fastest(lambda: load_structure(p), n=3)
    print(f"{bomb}: refused in {took * 1e3:.1f} ms; a valid file loads in {valid_time * 1e3:.1f} ms")
    assert took < 3 * valid_time, f"{bomb}: {took * 1e3:.1f} ms, valid file {valid_time * 1e3:.1f} ms"


def test_limits_are_raised_by_the_caller_only(tmp_path, monkeypatch):
    p = tmp_path / "fine.yaml"
    p.write_text(GIRDER.replace("elements_per_span: 10 ", "elements_per_span: 4000"))
    with pytest.raises(StructureError, match="limit of 20000"):
        load_structure(p)
    assert load_structure(p, StructureLimits(max_dof=30_000)).girder.elements_per_span == 4000
    monkeypatch.setenv("SHM_ROS_MAX_DOF", "30000")
    assert load_structure(p).girder.elements_per_span == 4000
    with pytest.raises(StructureError, match="limit of 5 "):  # every kind counts its degrees of freedom
        load_structure(EXAMPLES / "building.yaml", StructureLimits(max_dof=5))
    # the file cannot raise its own limit: an unknown top-level field is an error
    p.write_text(GIRDER.replace("elements_per_span: 10 ", "elements_per_span: 4000") + "max_dof: 100000\n")
    with pytest.raises(StructureError, match="unknown field 'max_dof'"):
        load_structure(p)


def _numeric_leaves(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numeric_leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numeric_leaves(v, (*path, i))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path


def _set(doc, path, value):
    for k in path[:-1]:
        doc = doc[k]
    doc[path[-1]] = value


def _field(path) -> str:
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else ("." if out else "") + str(k)
    return out


CASES = [(name, path) for name in ("girder.yaml", "building.yaml", "matrices.yaml")
         for path in _numeric_leaves(yaml.load((EXAMPLES / name).read_text(), Loader=yaml.SafeLoader))]


@pytest.mark.parametrize("bad", [True, "12 kg"], ids=["bool", "text"])
def test_every_numeric_field_refuses_bool_and_text(tmp_path, bad):
    from shm_ros.io.structure import read_yaml

    assert len(CASES) > 40
    shutil.copy(EXAMPLES / "matrices.npz", tmp_path / "matrices.npz")
    accepted = []
    for name, path in CASES:
        doc = read_yaml((EXAMPLES / name).read_text(), name)
        _set(doc, path, bad)
        p = tmp_path / name
        p.write_text(yaml.safe_dump(doc))
        try:
            load_structure(p)
        except StructureError as exc:
            assert str(p) in str(exc)
            # the message names the field (or, for a list given as a whole, its parent)
            assert _field(path) in str(exc) or _field(path[:-1]) in str(exc), (str(exc), path)
            continue
        accepted.append(f"{name}: {_field(path)}")
    assert not accepted, f"{len(accepted)} numeric fields accept {bad!r}: {accepted}"


def test_a_named_file_stays_in_the_structure_folder(tmp_path):
    inner = tmp_path / "site"
    inner.mkdir()
    shutil.copy(EXAMPLES / "matrices.npz", tmp_path / "outside.npz")
    text = (EXAMPLES / "matrices.yaml").read_text()
    (inner / "s.yaml").write_text(text.replace("file: matrices.npz", "file: ../outside.npz"))
    with pytest.raises(StructureError, match=r"matrices\.file.*outside the structure file's folder"):
        load_structure(inner / "s.yaml")
    (inner / "abs.yaml").write_text(text.replace("file: matrices.npz", f"file: {tmp_path / 'outside.npz'}"))
    with pytest.raises(StructureError, match="outside"):
        load_structure(inner / "abs.yaml")
    (inner / "link.npz").symlink_to(tmp_path / "outside.npz")
    (inner / "link.yaml").write_text(text.replace("file: matrices.npz", "file: link.npz"))
    with pytest.raises(StructureError, match="outside"):
        load_structure(inner / "link.yaml")
    assert load_structure(inner / "s.yaml", StructureLimits(paths_anywhere=True)).kind == "matrices"
