"""`ros2 launch shm_ros pipeline.launch.py [params_file:=FILE] [namespace:=/bridge_a] [autostart:=false]`

The node graph of a ROS 2 parameters file (default: the installed config/pipeline.yaml) on a ROS 2
installation: exactly what `shm-ros run FILE [--namespace NS] [--no-autostart]` starts without
one. Both take the nodes, executables, parameters and respawn policy from
`shm_ros.ros.graph_config.launch_plan` (which reads the node registry, shm_ros/ros/registry.py):
one node per section of the file, respawned when it dies. The nodes are managed (lifecycle) nodes;
with autostart:=false they wait unconfigured for a lifecycle manager.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from shm_ros.ros.graph_config import launch_plan, load_graph_config


def _nodes(context):
    params_file = LaunchConfiguration("params_file").perform(context)
    namespace = LaunchConfiguration("namespace").perform(context)
    autostart = LaunchConfiguration("autostart").perform(context).lower() in ("true", "1", "yes")
    config = load_graph_config(params_file, namespace=namespace)
    return [Node(package="shm_ros", executable=n.executable, name=n.name, namespace=n.namespace,
                 parameters=[n.parameters], respawn=n.respawn, respawn_delay=n.respawn_delay_s,
                 output="screen")
            for n in launch_plan(config, autostart)]


def generate_launch_description():
    default = os.path.join(get_package_share_directory("shm_ros"), "config", "pipeline.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default,
                              description="ROS 2 parameters file of the graph (see config/pipeline.yaml)"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of every node, topic and service (e.g. /bridge_a)"),
        DeclareLaunchArgument("autostart", default_value="true",
                              description="nodes configure and activate themselves (false: a lifecycle "
                              "manager drives them through the lifecycle_msgs services)"),
        OpaqueFunction(function=_nodes),
    ])
