"""plane_node over real DDS (loopback) with line features, on a rendered low-texture floor."""

from __future__ import annotations

import time

from domplane_ros.core.homography import apply_homography
from domplane_ros.ros.messages import image_msg, stamped_header
from domplane_ros.ros.node import PlaneNode
from domplane_ros.sim.generators import random_scene
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image
from std_msgs.msg import Float64MultiArray
from test_node import _prior_overrides


def _mono8(gray: np.ndarray, stamp_ns: int, frame_id: str):
    return image_msg(gray, stamped_header(stamp_ns, frame_id), 'mono8')


@pytest.fixture(scope='module')
def tiles():
    return random_scene(0, floor='tiles_plain')


def _cyan(msg):
    """Return the number of cyan (inlier-marked) pixels of a debug image."""
    rgb = np.frombuffer(bytes(msg.data), np.uint8).reshape(480, 640, 3)
    return int(np.count_nonzero((rgb[:, :, 0] < 80) & (rgb[:, :, 1] > 150)
                                & (rgb[:, :, 2] > 150)))


@pytest.mark.parametrize('kind', ['lines', 'both'])
def test_node_finds_low_texture_floor_with_lines(ros_context, tiles, kind):
    overrides = _prior_overrides(tiles, Parameter('features.kind', value=kind))
    node = PlaneNode(context=ros_context, parameter_overrides=overrides)
    driver = Node('lines_driver', context=ros_context)
    pub_left = driver.create_publisher(Image, 'left/image_raw', qos_profile_sensor_data)
    pub_right = driver.create_publisher(Image, 'right/image_raw', qos_profile_sensor_data)
    homographies: list[Float64MultiArray] = []
    debug: list[Image] = []
    driver.create_subscription(Float64MultiArray, 'plane/homography', homographies.append, 10)
    driver.create_subscription(Image, 'plane/debug_image', debug.append, 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(driver)
    try:
        assert node.get_parameter('features.kind').value == kind
        assert node.config.features.kind == kind
        deadline = time.monotonic() + 30.0
        stamp = 10_000_000_000

        def planed():
            # The debug image of a frame with a plane (search frames publish none).
            return homographies and debug and _cyan(debug[-1]) > 200

        while time.monotonic() < deadline and not planed():
            if pub_left.get_subscription_count() and pub_right.get_subscription_count():
                pub_left.publish(_mono8(tiles.left, stamp, 'left_cam'))
                pub_right.publish(_mono8(tiles.right, stamp + 1000, 'right_cam'))
                stamp += 100_000_000
            end = time.monotonic() + 0.3
            while time.monotonic() < end and not planed():
                executor.spin_once(timeout_sec=0.02)
        assert homographies and debug, 'timed out waiting for the node'
        est = np.array(homographies[-1].data).reshape(3, 3)
        truth_px = np.argwhere(tiles.plane_left & tiles.visible_in_right)[:, ::-1]
        truth_px = truth_px.astype(np.float64)
        err = np.linalg.norm(apply_homography(est, truth_px)
                             - apply_homography(tiles.homography, truth_px), axis=1)
        assert err.mean() < 1.0, err.mean()
        last = node.session.last_result
        assert last.left_lines.shape[0] > 50
        assert last.estimate.line_inliers.sum() > 40
        assert _cyan(debug[-1]) > 200
        # Switching the features at runtime is validated like any parameter.
        res = node.set_parameters([Parameter('features.kind', value='edges')])[0]
        assert not res.successful and 'features.kind' in res.reason
        res = node.set_parameters([Parameter('features.kind', value='points')])[0]
        assert res.successful and node.pipeline.config.features.kind == 'points'
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()
