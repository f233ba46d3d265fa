"""The installed package runs the bundled example: in a fresh virtual environment, ``pip install
<repository>`` (not editable; from a copy of the repository's files, so the checkout is not what
runs), then ``shm-ros example --out out --quick`` in an empty directory writes the report.

ROS 2 comes from the project's environment, the way a sourced ROS installation provides it: its
site-packages on the fresh environment's path (a ``.pth`` line), its libraries on
``LD_LIBRARY_PATH`` and the interface package on ``AMENT_PREFIX_PATH``. pip installs offline
(``--no-index``): every dependency is already there, only shm_ros itself is built and installed
(about 3 s of CPU); the rest is the quick example: two node graphs of six processes each, about 50 s
of CPU in all.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _ros_environment() -> dict[str, str]:
    """What sourcing the project's ROS 2 would set (ROS from the PyPI wheels lives in its venv)."""
    site = Path(sysconfig.get_paths()["purelib"])
    libs = [str(Path(sys.prefix) / "lib"), *sorted(str(p) for p in site.glob("ros_*.libs"))]
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = os.pathsep.join([*libs, env.get("LD_LIBRARY_PATH", "")]).rstrip(os.pathsep)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([sys.prefix, env.get("AMENT_PREFIX_PATH", "")]).rstrip(os.pathsep)
    env.pop("PYTHONPATH", None)
    return env


def test_pip_installed_package_runs_the_quick_example_in_an_empty_directory(tmp_path):
    from test_self_contained import repository_files

    src = tmp_path / "src"
    for path in repository_files():
        rel = path.relative_to(ROOT)
        if rel.parts[0] in ("test", "bench"):
            continue
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, src / rel)

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    fresh_site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                     capture_output=True, text=True, check=True).stdout.strip())
    (fresh_site / "ros_from_project.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = _ros_environment()
    install = subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-index",
                              "--no-build-isolation", str(src)], capture_output=True, text=True, env=env,
                             timeout=600)
    assert install.returncode == 0, install.stdout[-3000:] + install.stderr[-3000:]
    where = subprocess.run([str(py), "-c", "import shm_ros; print(shm_ros.__file__)"], capture_output=True,
                           text=True, env=env, cwd=tmp_path, timeout=60)
    assert where.stdout.strip().startswith(str(fresh_site)), where.stdout + where.stderr  # the installed copy

    empty = tmp_path / "empty"
    empty.mkdir()
    run = subprocess.run([str(venv / "bin" / "shm-ros"), "example", "--out", "out", "--quick"], cwd=empty,
                         capture_output=True, text=True, env=env, timeout=1500)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-4000:]
    out = empty / "out"
    report = (out / "report.html").read_text()
    assert "Posterior (model updating)" in report and "Explanation (missing physics)" in report
    facts = json.loads((out / "example.json").read_text())
    assert facts, facts
    for part, n in (("girder", 6), ("building", 4)):  # the quick profile's campaign sizes
        doc = json.loads((out / part / "modes.json").read_text())
        assert len(doc["windows"]) == n, part
        assert json.loads((out / part / "update" / "posterior.json").read_text())["parameters"], part
    assert (out / "girder" / "explain" / "verdict.json").is_file()
    assert (out / "building" / "prediction" / "prediction.json").is_file()
    assert sorted(p.name for p in empty.iterdir()) == ["out"]  # it needed nothing next to it
