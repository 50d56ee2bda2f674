"""Which command lines ask plane_node for its help (no node is started for them)."""

from __future__ import annotations

from domplane_ros.ros.usage import usage, wants_help
import pytest


@pytest.mark.parametrize('argv,expected', [
    (['plane_node', '--help'], True),
    (['plane_node', '-h', '--ros-args', '-p', 'qos.depth:=3'], True),
    (['plane_node', '--ros-args', '-r', '__node:=x', '--', '--help'], True),
    (['plane_node'], False),
    (['plane_node', '--ros-args', '--help'], False),  # a ROS argument, rcl's to judge
    (['--help'], False),  # the program name is not an argument
])
def test_help_is_asked_only_outside_the_ros_arguments(argv, expected):
    assert wants_help(argv) is expected


def test_usage_lines_fit_the_terminal_width():
    assert max(len(line) for line in usage().splitlines()) <= 99
