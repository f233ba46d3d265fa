"""The ROS 2 side: thin nodes over ``shm_ros.core``; ``convert`` is the only module that knows both
the messages and the core dataclasses."""
