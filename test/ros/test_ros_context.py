"""Checks that the ``ros_context`` fixture gives a working private rclpy context."""

from __future__ import annotations

import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String


def test_context_is_private_and_uses_session_domain(ros_context, ros_domain_id):
    assert ros_context.ok()
    assert ros_context.get_domain_id() == ros_domain_id
    assert 1 <= ros_domain_id <= 200
    assert ros_context is not rclpy.utilities.get_default_context()


def test_publish_and_receive_over_dds_in_private_context(ros_context):
    talker = rclpy.create_node('fixture_talker', context=ros_context)
    listener = rclpy.create_node('fixture_listener', context=ros_context)
    received = []
    listener.create_subscription(String, 'fixture_chatter', received.append, 10)
    publisher = talker.create_publisher(String, 'fixture_chatter', 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(talker)
    executor.add_node(listener)
    try:
        deadline = time.monotonic() + 10.0
        while not received and time.monotonic() < deadline:
            publisher.publish(String(data='hello'))
            executor.spin_once(timeout_sec=0.1)
        assert received, 'no message arrived within 10 s'
        assert received[0].data == 'hello'
    finally:
        executor.shutdown()
        talker.destroy_node()
        listener.destroy_node()
