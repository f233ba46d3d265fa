from setuptools import find_packages, setup

package_name = "shm_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["shm_ros", "shm_ros.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/pipeline.yaml"]),
    ],
    package_data={"shm_ros": ["report/templates/*", "py.typed"]},
    python_requires=">=3.10",
    install_requires=["numpy", "scipy", "PyYAML", "rosbags", "mcap", "zstandard", "emcee",
                      "dynesty", "arviz", "matplotlib", "threadpoolctl", "obspy"],
    zip_safe=True,
    maintainer="shm_ros maintainers",
    maintainer_email="maintainers@shm-ros.invalid",
    description="Structural health monitoring on ROS 2: recordings to a calibrated, uncertainty-aware "
    "structural model that says what physics it is missing.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "shm-ros = shm_ros.cli:main",
            "shm-ros-ingest = shm_ros.ros.ingest_node:main",
            "shm-ros-identify = shm_ros.ros.identify_node:main",
            "shm-ros-update = shm_ros.ros.update_node:main",
            "shm-ros-recorder = shm_ros.ros.recorder_node:main",
        ],
    },
)
