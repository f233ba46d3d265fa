"""The science of shm_ros: numpy/scipy only, no ROS import, typed dataclasses in and out.

Nothing in this package imports from ``shm_ros.io``, ``shm_ros.ros`` or ``shm_ros.report``.
"""
