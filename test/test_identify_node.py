"""The identify node's parameters reach the identification configuration; a bad choice fails its
configure transition with a message naming the parameter (real rclpy, own process)."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = r"""
import sys, rclpy
from shm_ros.ros.identify_node import IdentifyNode
rclpy.init()
try:
    node = IdentifyNode(parameters={"method": "ssi-data", "weighting": sys.argv[1], "max_order": 40})
    if node.configured:
        print("CONFIG", node.config.method, node.config.weighting, node.config.max_order)
    else:
        print("EXIT", node.config_error)
    node.destroy_node()
finally:
    rclpy.shutdown()
"""


def _run(weighting: str) -> str:
    out = subprocess.run([sys.executable, "-c", SCRIPT, weighting], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_identify_node_weighting_parameter():
    assert "CONFIG ssi-data upc 40" in _run("upc")
    assert "CONFIG ssi-data cva 40" in _run("cva")
    bad = _run("pca")
    assert "EXIT" in bad and "'weighting'" in bad and "pca" in bad


BAND_SCRIPT = r"""
import sys, rclpy
from shm_ros.ros.identify_node import IdentifyNode
rclpy.init()
try:
    params = {"structure": sys.argv[1]} if sys.argv[1] != "-" else {}
    node = IdentifyNode(parameters=params)
    print("BAND", node.config.nominal_frequencies_hz) if node.configured else print("EXIT", node.config_error)
    node.destroy_node()
finally:
    rclpy.shutdown()
"""


def test_identify_node_takes_the_band_from_the_structure_file(tmp_path):
    """As `shm-ros identify` does: the structure's nominal model sets the band of interest (without
    it each window's spectrum does, and a quasi-static peak can pick 100 block rows)."""
    import ast
    from pathlib import Path

    from shm_ros.core.band import nominal_frequencies
    from shm_ros.io.structure import load_structure

    girder = str(Path(__file__).resolve().parents[1] / "examples" / "girder.yaml")

    def band(arg: str) -> str:
        out = subprocess.run([sys.executable, "-c", BAND_SCRIPT, arg], capture_output=True, text=True,
                             timeout=120)
        assert out.returncode == 0, out.stderr
        return out.stdout

    line = [s for s in band(girder).splitlines() if s.startswith("BAND")][0]
    got = ast.literal_eval(line.split(" ", 1)[1])
    assert got == nominal_frequencies(load_structure(girder), 6)
    assert "BAND None" in band("-")
    missing = band(str(tmp_path / "nope.yaml"))
    assert "EXIT" in missing and "'structure'" in missing and "nope.yaml" in missing
