"""Live robot SLAM: laser_driver + base_driver + corner_extractor + ekf_slam.

Same nodes and parameter files as ``landmark_nav pipeline slam`` (pip install); for a
colcon install::

    ros2 launch landmark_nav slam.launch.py laser_port:=/dev/ttyACM0 base_port:=/dev/ttyUSB0
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
        DeclareLaunchArgument('laser_port', default_value='/dev/ttyACM0',
                              description='laser serial port or socket:// URL'),
        DeclareLaunchArgument('base_port', default_value='/dev/ttyUSB0',
                              description='Pioneer serial port or socket:// URL'),
        Node(package='landmark_nav', executable='laser_driver', name='laser_driver',
             output='screen', parameters=[
                 os.path.join(config, 'laser_driver.yaml'),
                 {'port': LaunchConfiguration('laser_port')}]),
        Node(package='landmark_nav', executable='base_driver', name='base_driver',
             output='screen', parameters=[
                 os.path.join(config, 'base_driver.yaml'),
                 {'port': LaunchConfiguration('base_port')}]),
        Node(package='landmark_nav', executable='corner_extractor', name='corner_extractor',
             output='screen', parameters=[
                 os.path.join(config, 'corner_extractor.yaml')]),
        Node(package='landmark_nav', executable='ekf_slam', name='ekf_slam',
             output='screen', parameters=[
                 os.path.join(config, 'ekf_slam.yaml')]),
    ])
