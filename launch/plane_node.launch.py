r"""Start plane_node: ``ros2 launch domplane_ros plane_node.launch.py [name:=value ...]``.

Arguments (``ros2 launch domplane_ros plane_node.launch.py --show-args`` lists them):
``params_file`` (default: the package's ``config/plane_node.yaml``, keyed ``/**`` so it
applies under any node name), ``namespace``, ``node_name``, ``left_image`` and
``right_image`` (the image topics; with ``image_transport:=compressed`` the node subscribes
to ``<topic>/compressed``) and ``image_transport`` (``raw`` or ``compressed``).

Two heads on one robot::

    ros2 launch domplane_ros plane_node.launch.py namespace:=front node_name:=front_plane \
        left_image:=/front/left/image_raw right_image:=/front/right/image_raw
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'domplane_ros'

# name, default, description; the default of params_file is filled in below.
ARGUMENTS = (
    ('params_file', None, 'ROS 2 parameters file of the node (keyed /** or by node name).'),
    ('namespace', '', 'Namespace of the node and of its relative topics.'),
    ('node_name', 'plane_node', 'Name of the node.'),
    ('left_image', 'left/image_raw', 'Left image topic (the base topic when compressed).'),
    ('right_image', 'right/image_raw', 'Right image topic (the base topic when compressed).'),
    ('image_transport', 'raw', 'raw (sensor_msgs/Image) or compressed (<topic>/compressed).'),
)


def generate_launch_description():
    """Return the launch description: the arguments and one plane_node."""
    default_params = PathJoinSubstitution(
        [FindPackageShare(PACKAGE), 'config', 'plane_node.yaml'])
    declared = [
        DeclareLaunchArgument(name, default_value=default_params if default is None else default,
                              description=description)
        for name, default, description in ARGUMENTS]
    node = Node(
        package=PACKAGE,
        executable='plane_node',
        name=LaunchConfiguration('node_name'),
        namespace=LaunchConfiguration('namespace'),
        parameters=[LaunchConfiguration('params_file'),
                    {'image_transport': LaunchConfiguration('image_transport')}],
        remappings=[('left/image_raw', LaunchConfiguration('left_image')),
                    ('right/image_raw', LaunchConfiguration('right_image'))],
        output='screen',
        emulate_tty=True,
    )
    return LaunchDescription(declared + [node])
