"""`ros2 launch shm_ros pipeline.launch.py [params_file:=FILE]`: the node graph of
config/pipeline.yaml on a ROS 2 installation (what `shm-ros run config/pipeline.yaml` starts
without one). Every node reads its parameters from the same ROS 2 parameters file."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    default = os.path.join(get_package_share_directory("shm_ros"), "config", "pipeline.yaml")
    params_file = LaunchConfiguration("params_file")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default,
                              description="ROS 2 parameters file of the graph (see config/pipeline.yaml)"),
        Node(package="shm_ros", executable="ingest", name="ingest", parameters=[params_file], output="screen"),
        Node(package="shm_ros", executable="identify", name="identify", parameters=[params_file], output="screen"),
        Node(package="shm_ros", executable="track", name="track", parameters=[params_file], output="screen"),
        Node(package="shm_ros", executable="update", name="update", parameters=[params_file], output="screen"),
        Node(package="shm_ros", executable="predict", name="predict", parameters=[params_file], output="screen"),
        Node(package="shm_ros", executable="recorder", name="recorder", parameters=[params_file],
             output="screen"),
    ])
