"""Launch one friction_ros joint on a robot with ROS 2 Jazzy installed (ros2 launch friction_ros ...).

    ros2 launch friction_ros friction_joint.launch.py preset:=abb_m19s namespace:=joint1
    ros2 launch friction_ros friction_joint.launch.py use_drive:=true drive_params:=/path/drive.yaml

With ``use_drive:=false`` (default) the plant simulator stands in for the drive; with
``use_drive:=true`` the CAN drive interface node talks to the real servo drive. Both publish the same
``joint_states`` and take the same ``joint_commands``, so the controller and estimator do not change.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description():
    share = get_package_share_directory("friction_ros")
    default_params = os.path.join(share, "params", "controller_abb_m19s.yaml")
    ns = LaunchConfiguration("namespace")
    args = [
        DeclareLaunchArgument("namespace", default_value="joint1", description="namespace of the joint"),
        DeclareLaunchArgument("preset", default_value="abb_m19s", description="plant preset (simulation)"),
        DeclareLaunchArgument(
            "mode", default_value="realtime", description="plant mode: realtime or lockstep"
        ),
        DeclareLaunchArgument(
            "params", default_value=default_params, description="controller/estimator YAML"
        ),
        DeclareLaunchArgument(
            "use_drive", default_value="false", description="true: CAN drive, false: simulator"
        ),
        DeclareLaunchArgument(
            "drive_params", default_value=default_params, description="drive_interface YAML"
        ),
    ]
    use_sim_time = PythonExpression(["'", LaunchConfiguration("mode"), "' == 'lockstep'"])
    params = LaunchConfiguration("params")
    nodes = [
        Node(
            package="friction_ros",
            executable="plant_simulator",
            namespace=ns,
            parameters=[{"preset": LaunchConfiguration("preset"), "mode": LaunchConfiguration("mode")}],
            condition=UnlessCondition(LaunchConfiguration("use_drive")),
            output="screen",
        ),
        Node(
            package="friction_ros",
            executable="drive_interface",
            namespace=ns,
            parameters=[LaunchConfiguration("drive_params")],
            condition=IfCondition(LaunchConfiguration("use_drive")),
            output="screen",
        ),
        Node(
            package="friction_ros",
            executable="compensating_controller",
            namespace=ns,
            parameters=[params, {"use_sim_time": use_sim_time}],
            output="screen",
        ),
        Node(
            package="friction_ros",
            executable="friction_estimator",
            namespace=ns,
            parameters=[params, {"use_sim_time": use_sim_time}],
            output="screen",
        ),
    ]
    return LaunchDescription(args + nodes)
