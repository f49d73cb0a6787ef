"""Start the estimator node: ``ros2 launch rls_uncertainty estimator.launch.py
[namespace:=/ns] [log_level:=debug] [params_file:=/path/to/config.yaml] [use_sim_time:=true]``.

Under a namespace the node is ``/ns/rls_estimator`` and its outputs ``/ns/rls_estimator/M/...``
(the inputs ``/ns/imu``, ...); ``rls-uncertainty dashboard|status --node /ns/rls_estimator``
follow it."""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.launch_description import LaunchDescription  # ruff sorts a bare `launch` as ./launch/
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    default = os.path.join(get_package_share_directory("rls_uncertainty"), "config", "t2.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the node (default: none)"),
        DeclareLaunchArgument("log_level", default_value="info",
                              description="logging level: debug, info, warn, error or fatal"),
        DeclareLaunchArgument("params_file", default_value=default, description="ROS parameter file"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="follow /clock (bag replay)"),
        Node(
            package="rls_uncertainty",
            executable="estimator_node",
            name="rls_estimator",
            namespace=LaunchConfiguration("namespace"),
            output="screen",
            parameters=[LaunchConfiguration("params_file"), {"use_sim_time": LaunchConfiguration("use_sim_time")}],
            ros_arguments=["--log-level", LaunchConfiguration("log_level")],
        ),
    ])
