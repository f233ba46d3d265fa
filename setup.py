"""Packaging of shm_ros: a pip-installable Python package and an ament_python ROS 2 package.

Console scripts: ``shm-ros`` (the command line) and ``shm-ros-<node>`` for every node of the node
registry (``shm_ros/ros/registry.py``, read here without importing the package). pip puts them on
the environment's ``bin/``; in a colcon workspace ``setup.cfg`` puts them in ``lib/shm_ros``, where
``ros2 run shm_ros shm-ros-ingest`` and the launch file look. The bundled example's inputs
(``shm_ros/examples_data``) are package data, so ``shm-ros example`` runs from an installed package.
Runtime dependencies are listed twice on purpose: here for pip, in ``package.xml`` as rosdep keys
(``test/test_packaging.py`` checks that both cover every import).
"""

import runpy
from pathlib import Path

from setuptools import find_packages, setup

package_name = "shm_ros"
REGISTRY = runpy.run_path(str(Path(__file__).resolve().parent / "shm_ros" / "ros" / "registry.py"))

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["shm_ros", "shm_ros.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/pipeline.yaml"]),
        ("share/" + package_name + "/launch", ["launch/pipeline.launch.py"]),
    ],
    package_data={"shm_ros": ["py.typed", "core/explain/*.json", "examples_data/*.yaml"]},
    python_requires=">=3.11",
    install_requires=["numpy", "scipy", "PyYAML", "rosbags", "mcap", "zstandard", "lz4", "emcee",
                      "dynesty", "arviz", "arviz-stats", "matplotlib", "threadpoolctl", "obspy", "numba", "llvmlite",
                      "dask[distributed]"],
    zip_safe=True,
    maintainer="shm_ros maintainers",
    maintainer_email="maintainers@shm-ros.invalid",
    description="Structural health monitoring on ROS 2: recordings to a calibrated, uncertainty-aware "
    "structural model that says what physics it is missing.",
    license="Apache-2.0",
    extras_require={"test": ["pytest"], "opensees": ["openseespy<3.8"]},
    entry_points={"console_scripts": REGISTRY["entry_points"]()},
)
