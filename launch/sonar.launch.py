"""Sonar localization: base_driver + sonar_localizer.

Same nodes and parameter files as ``landmark_nav pipeline sonar`` (pip install); for a
colcon install::

    ros2 launch landmark_nav sonar.launch.py base_port:=/dev/ttyUSB0 map_file:=/path/map.yaml
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the launch description of the pipeline."""
    config = os.path.join(get_package_share_directory('landmark_nav'), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('base_port', default_value='/dev/ttyUSB0',
                              description='Pioneer serial port or socket:// URL'),
        DeclareLaunchArgument('map_file', default_value='',
                              description='map_server YAML; empty: subscribe to map'),
        Node(package='landmark_nav', executable='base_driver', name='base_driver',
             output='screen', parameters=[
                 os.path.join(config, 'base_driver.yaml'),
                 {'port': LaunchConfiguration('base_port')}]),
        Node(package='landmark_nav', executable='sonar_localizer', name='sonar_localizer',
             output='screen', parameters=[
                 os.path.join(config, 'sonar_localizer.yaml'),
                 {'map_file': LaunchConfiguration('map_file')}]),
    ])
