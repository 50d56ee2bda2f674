"""Fixtures shared by every test tier; nothing here imports rclpy.

The ROS tests' own fixtures (private rclpy contexts) live in ``test/ros/conftest.py``, so the
core, stream, replay, sim and tools tests run where rclpy is not installed.
"""

from __future__ import annotations

from bag_helpers import make_frames
import pytest


@pytest.fixture(scope='module')
def frames():
    """Return the short rendered sequence that the bag tests write and replay."""
    return make_frames()
