"""``plane_node --help``: the usage, the topics and the parameter table (no ROS import)."""

from __future__ import annotations

import textwrap
from typing import Sequence

from domplane_ros.parameters import PARAMETERS, ParamSpec

_USAGE = """\
usage: plane_node [-h] [--ros-args [-p NAME:=VALUE] [--params-file FILE] [-r FROM:=TO]]

Dominant ground plane homography and obstacle mask from an uncalibrated stereo pair.

topics (relative: -r __ns:=/robot puts them under /robot):
  in   left/image_raw, right/image_raw   sensor_msgs/Image (image_transport raw), or
       <topic>/compressed                sensor_msgs/CompressedImage (image_transport compressed)
  in   camera_info.topic (optional)      sensor_msgs/CameraInfo: K narrows the prior
  in   head.joint_states_topic (opt.)    sensor_msgs/JointState
  out  plane/result                      diagnostic_msgs/DiagnosticArray, every pair, stamped
                                         as the left image: state, confidence, homography
  out  plane/homography                  std_msgs/Float64MultiArray, only with a plane
  out  plane/mask, plane/debug_image     sensor_msgs/Image, left image's header
  out  plane/parallax                    sensor_msgs/Image 32FC1, residual parallax [px]
  out  /diagnostics                      diagnostic_msgs/DiagnosticArray

examples:
  plane_node --ros-args --params-file config/plane_node.yaml \\
      -r left/image_raw:=/stereo/left/image_raw -r right/image_raw:=/stereo/right/image_raw
  plane_node --ros-args -r __node:=front_plane -r __ns:=/robot -p image_transport:=compressed
  ros2 launch domplane_ros plane_node.launch.py namespace:=robot image_transport:=compressed

parameters (name = default  [range]):"""


def wants_help(argv: Sequence[str]) -> bool:
    """Return whether ``-h`` or ``--help`` is among the program's own arguments.

    Args:
        argv: The command line, program name first; ROS arguments (from ``--ros-args`` to
            ``--`` or the end) are not the program's.

    Returns:
        True if help was asked for.

    """
    in_ros_args = False
    for arg in list(argv)[1:]:
        if arg == '--ros-args':
            in_ros_args = True
        elif arg == '--' and in_ros_args:
            in_ros_args = False
        elif not in_ros_args and arg in ('-h', '--help'):
            return True
    return False


def _range(spec: ParamSpec) -> str:
    if spec.choices:
        return ' | '.join(spec.choices)
    if spec.low is not None and spec.high is not None:
        return f'{spec.low:g} .. {spec.high:g}'
    return ''


def usage(width: int = 99) -> str:
    """Return the ``--help`` text: usage, topics, examples and every parameter.

    Args:
        width: Column at which descriptions are wrapped.

    Returns:
        The text, generated from :data:`~domplane_ros.parameters.PARAMETERS`.

    """
    lines = [_USAGE]
    for spec in PARAMETERS:
        head, bounds = f'  {spec.name} = {spec.default!r}', _range(spec)
        if bounds and len(head) + len(bounds) + 4 <= width:
            lines.append(f'{head}  [{bounds}]')
        else:
            lines.extend([head, f'      [{bounds}]'] if bounds else [head])
        lines.extend(textwrap.wrap(spec.description, width=width, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 6, break_on_hyphens=False))
    return '\n'.join(lines)
