"""Landmark navigation: base_driver + landmark_detector (with your camera driver).

Same nodes and parameter files as ``landmark_nav pipeline landmarks`` (pip install); for a
colcon install::

    ros2 launch landmark_nav landmarks.launch.py landmark_map:=/path/landmarks.yaml
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
        DeclareLaunchArgument('landmark_map', default_value='',
                              description='YAML landmark map; empty: no robot fixes'),
        Node(package='landmark_nav', executable='base_driver', name='base_driver',
             output='screen', parameters=[
                 os.path.join(config, 'base_driver.yaml'),
                 {'port': LaunchConfiguration('base_port')}]),
        Node(package='landmark_nav', executable='landmark_detector', name='landmark_detector',
             output='screen', parameters=[
                 os.path.join(config, 'landmark_detector.yaml'),
                 {'landmark_map': LaunchConfiguration('landmark_map')}]),
    ])
