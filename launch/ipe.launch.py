"""Launch ipe_node with the shipped parameters (needs a full ROS 2 install with launch_ros):

    ros2 launch ipe_ros ipe.launch.py                      # config/ipe.yaml as installed
    ros2 launch ipe_ros ipe.launch.py params_file:=my.yaml namespace:=robot1 discovery_range:=SUBNET
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory("ipe_ros"), "config", "ipe.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="parameters of ipe_node (see config/ipe.yaml)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the node"),
        DeclareLaunchArgument("discovery_range", default_value="LOCALHOST",
                              description="ROS_AUTOMATIC_DISCOVERY_RANGE of the node: LOCALHOST keeps DDS on "
                                          "this machine; SUBNET to reach the rest of a robot"),
        Node(
            package="ipe_ros",
            executable="ipe_node",
            name="ipe",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("params_file")],
            additional_env={"ROS_AUTOMATIC_DISCOVERY_RANGE": LaunchConfiguration("discovery_range")},
            output="screen",
            emulate_tty=True,
        ),
    ])
