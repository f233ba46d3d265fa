"""Static checks of the package: ruff (rules in pyproject.toml) and mypy (check_untyped_defs),
both with zero findings."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_finds_nothing():
    out = _run("ruff", "check", "--no-cache", "shm_ros")
    assert out.returncode == 0, out.stdout + out.stderr


def test_mypy_finds_nothing():
    out = _run("mypy", "--no-incremental", "--cache-dir", "/dev/null")
    assert out.returncode == 0, out.stdout[-20000:] + out.stderr


def test_type_ignores_say_why():
    """Every ``# type: ignore[code]`` names its code and gives a reason after it."""
    bad = []
    for path in sorted((ROOT / "shm_ros").rglob("*.py")):
        for no, line in enumerate(path.read_text().splitlines(), 1):
            if "type: ignore" not in line:
                continue
            tail = line.split("type: ignore", 1)[1]
            if not tail.startswith("[") or "#" not in tail.split("]", 1)[1]:
                bad.append(f"{path.relative_to(ROOT)}:{no}: {line.strip()}")
    assert not bad, "type: ignore without a code or a reason:\n" + "\n".join(bad)


def test_pyproject_has_no_blanket_ignores():
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    lint = cfg["tool"]["ruff"]["lint"]
    assert set(lint["select"]) >= {"E", "F", "W", "I", "B", "UP"}
    assert not lint.get("ignore") and not lint.get("per-file-ignores")
    mypy = cfg["tool"]["mypy"]
    assert mypy["check_untyped_defs"] is True and "ignore_errors" not in str(cfg)
