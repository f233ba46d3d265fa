"""The identify node's parameters reach the identification configuration; a bad choice stops the
node with a message naming the parameter (real rclpy, own process)."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = r"""
import sys, rclpy
from shm_ros.ros.identify_node import IdentifyNode
rclpy.init()
try:
    node = IdentifyNode(parameters={"method": "ssi-data", "weighting": sys.argv[1], "max_order": 40})
    print("CONFIG", node.config.method, node.config.weighting, node.config.max_order)
    node.destroy_node()
except SystemExit as exc:
    print("EXIT", exc)
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
