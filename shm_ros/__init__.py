"""shm_ros: structural health monitoring from vibration and temperature recordings, on ROS 2."""

__version__ = "0.1.0"
