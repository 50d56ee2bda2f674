"""Packaging for domplane_ros (ament_python; also installable with plain pip)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE_NAME = 'domplane_ros'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(include=[PACKAGE_NAME, PACKAGE_NAME + '.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE_NAME]),
        ('share/' + PACKAGE_NAME, ['package.xml']),
        ('share/' + PACKAGE_NAME + '/config',
         sorted(glob('config/*.yaml') + glob('config/*.xml'))),
        ('share/' + PACKAGE_NAME + '/launch', sorted(glob('launch/*.launch.py'))),
        # `ros2 run` looks for executables in <prefix>/lib/<package>/. These launchers are
        # data files, so pip (wheel and editable) and colcon both install them there; the console
        # scripts below stay in <prefix>/bin. See the comment in setup.cfg.
        ('lib/' + PACKAGE_NAME,
         ['scripts/plane_node', 'scripts/plane_replay', 'scripts/plane_pair']),
    ],
    # colcon does not install install_requires; runtime dependencies are rosdep keys in
    # package.xml and pip requirements in requirements.txt.
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='domplane_ros maintainers',
    maintainer_email='domplane@example.com',
    description=(
        'Dominant ground plane homography from a stereo pair without correspondences.'),
    license='Apache-2.0',
    python_requires='>=3.10',
    extras_require={'test': ['pytest', 'hypothesis']},
    entry_points={
        'console_scripts': [
            'plane_node = domplane_ros.ros.node:main',
            'plane_replay = domplane_ros.replay.cli:main',
            'plane_pair = domplane_ros.pair.cli:main',
        ],
    },
)
