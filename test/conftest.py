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
os.environ.setdefault("ROS_DOMAIN_ID", str(100 + os.getpid() % 100))
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
