"""Test-wide settings: every run gets its own ROS domain, discovery stays on this host."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Real recordings the tests read, with their provenance and licence (test/data/*/README.md).
TEST_DATA = ROOT / "test" / "data"

# Each test run talks DDS only to itself: a domain of its own (from the process id) and localhost
# discovery. Subprocesses inherit both.
# With pytest-xdist (`-n 2`, what ./dev test runs) every worker gets a domain of its own: the
# controller picks an even base and worker gwK takes base + K, so parallel graph tests never meet.
if "PYTEST_XDIST_WORKER" in os.environ:
    _worker = int(os.environ["PYTEST_XDIST_WORKER"].removeprefix("gw") or 0)
    _base = os.environ.get("SHM_TEST_DOMAIN_BASE") or str(100 + 2 * (os.getppid() % 50))
    os.environ["ROS_DOMAIN_ID"] = str(int(_base) + _worker)
else:
    os.environ.setdefault("ROS_DOMAIN_ID", str(100 + 2 * (os.getpid() % 50)))
    os.environ["SHM_TEST_DOMAIN_BASE"] = os.environ["ROS_DOMAIN_ID"]
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("MPLBACKEND", "Agg")
# The science works on many small matrices, where a multi-threaded BLAS only contends (and on a
# shared 2-core machine can be 25x slower); node processes started by tests inherit this too.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))


def full_size() -> bool:
    """SHM_FULL=1 runs acceptance tests at their full size instead of the reduced CI size."""
    return os.environ.get("SHM_FULL", "") not in ("", "0")


@pytest.fixture
def test_data() -> Path:
    """The repository's own test-data folder, test/data/."""
    return TEST_DATA


@pytest.fixture(autouse=True)
def _two_a_scope_check(request, monkeypatch):
    """In the identify tests, every identification with the default two-A scope (stable columns,
    each until its verdict is settled) is redone with the all-orders check and must pick the same modes
    (test/two_a_scope_check.py; ``SHM_TWO_A_CHECK=0`` leaves it out, to time the tests alone)."""
    name = request.module.__name__.rsplit(".", 1)[-1]
    if not name.startswith("test_identify_") or os.environ.get("SHM_TWO_A_CHECK", "1") == "0":
        yield None
        return
    import two_a_scope_check

    check = two_a_scope_check.install(monkeypatch)
    yield check
    two_a_scope_check.add_to_total(check)
    assert not check.differences, "the two-A check on stable candidates changed the picks: " + \
        "; ".join(check.differences)


def pytest_terminal_summary(terminalreporter):
    checker = sys.modules.get("two_a_scope_check")
    if checker is not None and checker.TOTAL.compared:
        t = checker.TOTAL
        terminalreporter.write_line(f"two-A scope check: {t.compared} identifications compared with the "
                                    f"all-orders check, {len(t.differences)} differences, {t.cpu_s:.1f} s CPU"
                                    + (f"; candidates checked: {t.checked} of {t.candidates}"
                                       if t.candidates else ""))
