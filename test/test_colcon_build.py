"""msg_defs builds the ROS-workspace way with colcon (from PyPI) and the result imports.

colcon stops descending at a folder holding a package.xml, so the repository root (the ament_python
package shm_ros) hides msg_defs/ unless it is named as a base path too.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COPY = ["package.xml", "setup.py", "setup.cfg", "resource", "config", "launch", "shm_ros", "msg_defs",
        "README.md", "LICENSE"]


def test_colcon_builds_both_packages_and_the_messages_import(tmp_path):
    ws = tmp_path / "ws"
    ws.mkdir()
    for name in COPY:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, ws / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        elif src.exists():
            shutil.copy2(src, ws / name)
    venv = Path(sys.prefix)
    env = dict(os.environ, AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv),
               PATH=f"{venv / 'bin'}{os.pathsep}{os.environ['PATH']}")
    build = subprocess.run(
        [str(venv / "bin" / "colcon"), "build", "--base-paths", ".", "msg_defs",
         "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
        cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    assert "Finished <<< shm_interfaces" in build.stdout
    assert "Finished <<< shm_ros" in build.stdout
    lib = ws / "install" / "shm_ros" / "lib" / "shm_ros"  # where `ros2 run shm_ros <node>` looks
    # the console scripts of the node registry, where the launch file's executables are looked up
    from shm_ros.ros.registry import NODES

    assert {n.executable for n in NODES} <= {p.name for p in lib.iterdir()}

    check = (
        "import shm_interfaces.msg as m, rclpy\n"
        "print(m.__file__)\n"
        "rclpy.init(); n = rclpy.create_node('colcon_check')\n"
        "p = n.create_publisher(m.Window, '/colcon_check', 10)\n"
        "p.publish(m.Window(window_id='w', samples=[1.0, 2.0]))\n"
        "n.destroy_node(); rclpy.shutdown(); print('published')\n"
    )
    run = subprocess.run(
        ["bash", "-c", f'. "{ws}/install/setup.sh" && "{sys.executable}" -c "$CHECK"'],
        cwd=tmp_path, env=dict(env, CHECK=check), capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.split()
    assert lines[0].startswith(str(ws / "install" / "shm_interfaces")), lines
    assert lines[-1] == "published"
    assert (ws / "install" / "shm_interfaces" / "share" / "shm_interfaces" / "msg" / "Window.msg").exists()
