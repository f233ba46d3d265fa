"""The truth generator stays independent of the code it tests: no import of explain, simulate or the
project's models (directly, through a string given to importlib, or relative imports leaving it)."""

from __future__ import annotations

import ast
from pathlib import Path

FORBIDDEN = ("shm_ros.core.explain", "shm_ros.core.simulate", "shm_ros.core.models")
GENERATOR = Path(__file__).parent / "truths"


def _imports(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level > 1:
                found.append((node.lineno, "." * node.level + (node.module or "")))
            base = node.module or ""
            found += [(node.lineno, f"{base}.{a.name}" if base else a.name) for a in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            found.append((node.lineno, node.value))
    return found


def _offending(name: str) -> bool:
    if name.startswith(".."):
        return True  # a relative import out of the generator package
    return any(name == f or name.startswith(f + ".") or f in name for f in FORBIDDEN)


def test_the_generator_imports_nothing_under_test():
    files = sorted(GENERATOR.glob("*.py"))
    assert len(files) >= 10, files
    bad = [f"{p.name}:{line}: {name}" for p in files for line, name in _imports(ast.parse(p.read_text()))
           if _offending(name)]
    assert not bad, bad


def test_the_checker_catches_each_form():
    for src in ("import shm_ros.core.explain.engine", "from shm_ros.core.models import build_model",
                "from shm_ros.core import simulate", "from .. import explain_cases",
                "importlib.import_module('shm_ros.core.models.girder')"):
        assert any(_offending(n) for _, n in _imports(ast.parse(src))), src
    assert not any(_offending(n) for _, n in _imports(ast.parse("from shm_ros.io.importers import write_bag")))
