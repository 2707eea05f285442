"""Replay a bag through SLAM: bag_player (/scan, /odom) + corner_extractor + ekf_slam.

Same nodes and parameter files as ``landmark_nav pipeline replay`` (pip install), and each
node gets what the bag states (laser mount and noise, odometry noise model) on top of its
file, as the replay and ``landmark_nav evaluate`` give them
(:func:`landmark_nav.tools.pipeline.stated_parameters`); for a colcon install::

    ros2 launch landmark_nav replay.launch.py bag:=/path/bag rate:=2.0
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context):
    """Return the nodes, each with what the bag (known at launch) states for it."""
    from landmark_nav.tools.pipeline import stated_parameters
    config = os.path.join(get_package_share_directory('landmark_nav'), 'config')
    stated = stated_parameters(LaunchConfiguration('bag').perform(context))
    return [
        Node(package='landmark_nav', executable='bag_player', name='bag_player', output='screen',
             arguments=[LaunchConfiguration('bag'), '--rate', LaunchConfiguration('rate'),
                        '--topics', '/scan', '/odom', '--wait-for-subscribers', '30']),
        Node(package='landmark_nav', executable='corner_extractor', name='corner_extractor',
             output='screen', parameters=[os.path.join(config, 'corner_extractor.yaml'),
                                          stated['corner_extractor']]),
        Node(package='landmark_nav', executable='ekf_slam', name='ekf_slam',
             output='screen', parameters=[os.path.join(config, 'ekf_slam.yaml'),
                                          stated['ekf_slam']]),
    ]


def generate_launch_description():
    """Return the launch description of the pipeline."""
    return LaunchDescription([
        DeclareLaunchArgument('bag', description='rosbag2 directory to replay'),
        DeclareLaunchArgument('rate', default_value='1.0', description='playback speed factor'),
        OpaqueFunction(function=_nodes),
    ])
