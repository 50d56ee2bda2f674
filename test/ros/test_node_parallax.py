"""plane_node over real DDS (loopback): the residual-parallax image beside the mask."""

from __future__ import annotations

import time

from domplane_ros.core.mask import NOT_MEASURED, PLANE
from domplane_ros.ros.messages import image_msg, stamped_header
from domplane_ros.ros.node import PlaneNode
from domplane_ros.sim.generators import random_scene
from domplane_ros.stream.frame import parallax_image
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image


def _mono8(gray: np.ndarray, stamp_ns: int, frame_id: str):
    return image_msg(gray, stamped_header(stamp_ns, frame_id), 'mono8')


def _decode(msg: Image) -> np.ndarray:
    return np.frombuffer(bytes(msg.data), '<f4').reshape(msg.height, msg.width)


def test_node_publishes_the_parallax_image_while_subscribed(ros_context):
    scene = random_scene(1)
    node = PlaneNode(context=ros_context,
                     parameter_overrides=[Parameter('diagnostics.period_s', value=0.2)])
    driver = Node('parallax_driver', context=ros_context)
    pub_left = driver.create_publisher(Image, 'left/image_raw', qos_profile_sensor_data)
    pub_right = driver.create_publisher(Image, 'right/image_raw', qos_profile_sensor_data)
    parallax: list[Image] = []
    masks: list[Image] = []
    driver.create_subscription(Image, 'plane/parallax', parallax.append, 10)
    driver.create_subscription(Image, 'plane/mask', masks.append, 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(driver)

    def measured() -> bool:
        return bool(parallax) and bool(np.any(_decode(parallax[-1]) >= 0.0))

    try:
        deadline = time.monotonic() + 30.0
        stamp = 20_000_000_000
        while time.monotonic() < deadline and not measured():
            if pub_left.get_subscription_count() and pub_right.get_subscription_count():
                pub_left.publish(_mono8(scene.left, stamp, 'left_cam'))
                pub_right.publish(_mono8(scene.right, stamp + 1000, 'right_cam'))
                stamp += 100_000_000
            end = time.monotonic() + 0.3
            while time.monotonic() < end and not measured():
                executor.spin_once(timeout_sec=0.02)
        assert measured(), 'timed out waiting for a parallax image with a plane'
        # Let the last pairs through, then compare the last image with the node's result.
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.02)
        msg = parallax[-1]
        assert msg.encoding == '32FC1' and msg.is_bigendian == 0
        assert (msg.height, msg.width, msg.step) == (480, 640, 4 * 640)
        assert msg.header.frame_id == 'left_cam'
        stamp_ns = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        mask_stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in masks]
        assert stamp_ns in mask_stamps  # beside the mask of the same pair
        values = _decode(msg)
        assert np.all(np.isfinite(values))
        assert np.all((values >= 0.0) | (values == NOT_MEASURED))
        # Nothing was published since: the last image is the last processed pair's.
        result = node.session.last_result
        assert result.stamp_ns == stamp_ns
        assert np.array_equal(values, parallax_image(result))
        # The last pair with a measured parallax had a plane: the floor, whose plane pixels
        # have small parallax; the mask of the same pair says which.
        shown = [m for m in parallax if np.any(_decode(m) >= 0.0)][-1]
        shown_stamp = shown.header.stamp.sec * 10**9 + shown.header.stamp.nanosec
        mask_msg = [m for m in masks
                    if m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == shown_stamp][0]
        labels = np.frombuffer(bytes(mask_msg.data), np.uint8).reshape(480, 640)
        values = _decode(shown)
        ground = (scene.plane_left & scene.visible_in_right & (labels == PLANE)
                  & (values >= 0.0))
        assert ground.sum() > 10000 and np.median(values[ground]) < 0.5
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()
