"""Friction compensation for a whole arm (ros2 launch friction_ros friction_arm.launch.py ...).

    # the 7-joint example arm, simulated: plant, plain PD, friction add-on
    ros2 launch friction_ros friction_arm.launch.py

    # a robot with its own controller (ros2_control + topic_based_ros2_control): only the add-on,
    # between the controller's command topic and the hardware's command topic
    ros2 launch friction_ros friction_arm.launch.py simulate:=false \\
        addon_params:=/path/friction_params.yaml joint_states:=/joint_states \\
        base_command:=/robot_joint_commands_raw joint_commands:=/robot_joint_commands

``addon_params``: a multi-joint parameter file for the add-on (``friction-fit BAG --joint all``
writes one; set ``mode: compensation_only`` and ``sum_base_command: true`` in it, or use the
example's ``arm7_controllers.yaml``). The add-on node is named ``friction_addon``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    share = get_package_share_directory("friction_ros")
    params = os.path.join(share, "params")
    arg = LaunchConfiguration
    args = [
        DeclareLaunchArgument("namespace", default_value="arm", description="namespace of the arm"),
        DeclareLaunchArgument("simulate", default_value="true", description="true: plant + PD + add-on"),
        DeclareLaunchArgument("plant_params", default_value=os.path.join(params, "arm7_plant.yaml")),
        DeclareLaunchArgument("addon_params", default_value=os.path.join(params, "arm7_controllers.yaml")),
        DeclareLaunchArgument("joint_states", default_value="joint_states", description="measured states"),
        DeclareLaunchArgument(
            "base_command", default_value="pd_command", description="the arm controller's command"
        ),
        DeclareLaunchArgument(
            "joint_commands", default_value="joint_commands", description="command + compensation"
        ),
        DeclareLaunchArgument(
            "use_sim_time", default_value="false", description="true with a lockstep plant"
        ),
    ]
    sim = IfCondition(arg("simulate"))
    nodes = [
        Node(
            package="friction_ros",
            executable="plant_simulator",
            namespace=arg("namespace"),
            parameters=[arg("plant_params")],
            remappings=[("joint_states", arg("joint_states")), ("joint_commands", arg("joint_commands"))],
            condition=sim,
            output="screen",
        ),
        Node(
            package="friction_ros",
            executable="compensating_controller",
            name="pd_controller",
            namespace=arg("namespace"),
            parameters=[arg("addon_params"), {"use_sim_time": arg("use_sim_time")}],
            remappings=[("joint_states", arg("joint_states")), ("joint_commands", arg("base_command"))],
            condition=sim,
            output="screen",
        ),
        Node(
            package="friction_ros",
            executable="compensating_controller",
            name="friction_addon",
            namespace=arg("namespace"),
            parameters=[arg("addon_params"), {"use_sim_time": arg("use_sim_time")}],
            remappings=[
                ("joint_states", arg("joint_states")),
                ("base_command", arg("base_command")),
                ("joint_commands", arg("joint_commands")),
                ("controller_state", "compensation_state"),
            ],
            output="screen",
        ),
    ]
    return LaunchDescription(args + nodes)
