"""A recorded DiagnosticStatus level decodes as a byte; OK statuses are not listed as problems."""
from types import SimpleNamespace

from shm_ros.ros.graph_run import _level


def test_level_from_byte_and_int():
    assert _level(SimpleNamespace(level=b"\x00")) == 0
    assert _level(SimpleNamespace(level=b"\x02")) == 2
    assert _level(SimpleNamespace(level=1)) == 1
