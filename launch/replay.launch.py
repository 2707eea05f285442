"""Replay a bag through SLAM: bag_player (/scan, /odom) + corner_extractor + ekf_slam.

Same nodes and parameter files as ``landmark_nav pipeline replay`` (pip install); for a
colcon install::

    ros2 launch landmark_nav replay.launch.py bag:=/path/bag rate:=2.0
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
        DeclareLaunchArgument('bag', description='rosbag2 directory to replay'),
        DeclareLaunchArgument('rate', default_value='1.0', description='playback speed factor'),
        Node(package='landmark_nav', executable='bag_player', name='bag_player', output='screen',
             arguments=[LaunchConfiguration('bag'), '--rate', LaunchConfiguration('rate'),
                        '--topics', '/scan', '/odom', '--wait-for-subscribers', '30']),
        Node(package='landmark_nav', executable='corner_extractor', name='corner_extractor',
             output='screen', parameters=[os.path.join(config, 'corner_extractor.yaml')]),
        Node(package='landmark_nav', executable='ekf_slam', name='ekf_slam',
             output='screen', parameters=[
                 os.path.join(config, 'ekf_slam.yaml')]),
    ])
