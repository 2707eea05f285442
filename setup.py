"""Build script for the landmark_nav ament_python package."""

from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'landmark_nav'

# One console script per ROS executable; `ros2 run landmark_nav <exe>` finds them in
# lib/landmark_nav (see setup.cfg), a pip install puts them on PATH.
EXECUTABLES = {
    'landmark_nav': 'landmark_nav.tools.cli:main',
    'bag_player': 'landmark_nav.nodes.bag_player:main',
    'base_driver': 'landmark_nav.nodes.base_driver:main',
    'corner_extractor': 'landmark_nav.nodes.corner_extractor:main',
    'corridor_follower': 'landmark_nav.nodes.corridor_follower:main',
    'road_classifier': 'landmark_nav.nodes.road_classifier:main',
    'ekf_slam': 'landmark_nav.nodes.ekf_slam:main',
    'graph_slam': 'landmark_nav.nodes.graph_slam:main',
    'landmark_detector': 'landmark_nav.nodes.landmark_detector:main',
    'laser_driver': 'landmark_nav.nodes.laser_driver:main',
    'line_extractor': 'landmark_nav.nodes.line_extractor:main',
    'model_localizer': 'landmark_nav.nodes.model_localizer:main',
    'sonar_localizer': 'landmark_nav.nodes.sonar_localizer:main',
}

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    package_data={'landmark_nav.monocular': ['hallway_model.yaml'],
                  'landmark_nav.road': ['road_model.npz', 'road_cnn.npz']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        (os.path.join('share', PACKAGE, 'config'), glob('config/*.yaml')),
        (os.path.join('share', PACKAGE, 'launch'), glob('launch/*.launch.py')),
        (os.path.join('share', PACKAGE, 'viewer'), glob('viewer/*.json')),
        (os.path.join('share', PACKAGE, 'rviz'), glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools'],
    # training the road CNN only (landmark_nav train-road-outline --kind cnn); inference is numpy
    extras_require={'train': ['torch==2.13.0']},
    zip_safe=True,
    maintainer='landmark_nav maintainers',
    maintainer_email='maintainers@landmark-nav.invalid',
    description='Landmark-based navigation for a differential-drive robot (ROS 2 Jazzy).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in EXECUTABLES.items()],
    },
)
