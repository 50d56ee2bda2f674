"""plane_node in-process over real DDS (loopback), fed a rendered stereo pair with truth."""

from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.config import ConfigError
from domplane_ros.core.homography import apply_homography
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

_SCENE_SEED = 7


@pytest.fixture(scope='module')
def scene():
    return random_scene(_SCENE_SEED, floor='random', n_boxes=3, gain=1.15, offset=-10.0)


def _image(gray: np.ndarray, stamp_ns: int, frame_id: str, encoding: str = 'mono8') -> Image:
    msg = Image()
    msg.header.stamp.sec = stamp_ns // 1_000_000_000
    msg.header.stamp.nanosec = stamp_ns % 1_000_000_000
    msg.header.frame_id = frame_id
    msg.height, msg.width = gray.shape
    msg.encoding = encoding
    msg.step = gray.shape[1]
    msg.data = gray.tobytes()
    return msg


class Harness:
    """A node under test plus a driver node that publishes images and records outputs."""

    def __init__(self, context, overrides):
        self.node = PlaneNode(context=context, parameter_overrides=overrides)
        self.driver = Node('test_driver', context=context)
        self.pub_left = self.driver.create_publisher(Image, 'left/image_raw',
                                                     qos_profile_sensor_data)
        self.pub_right = self.driver.create_publisher(Image, 'right/image_raw',
                                                      qos_profile_sensor_data)
        self.homographies: list[Float64MultiArray] = []
        self.masks: list[Image] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.driver.create_subscription(Float64MultiArray, 'plane/homography',
                                        self.homographies.append, 10)
        self.driver.create_subscription(Image, 'plane/mask', self.masks.append, 10)
        self.driver.create_subscription(DiagnosticArray, '/diagnostics',
                                        self.diagnostics.append, 10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.driver)

    def wait_for_subscribers(self, timeout=10.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if (self.pub_left.get_subscription_count() and self.pub_right.get_subscription_count()
                    and self.node._pub_mask.get_subscription_count()):
                return
            self.executor.spin_once(timeout_sec=0.05)
        raise AssertionError('discovery did not complete')

    def send_until(self, left, right, predicate, stamp0_ns, timeout=30.0, encoding='mono8'):
        deadline = time.monotonic() + timeout
        stamp = stamp0_ns
        while time.monotonic() < deadline:
            self.pub_left.publish(_image(left, stamp, 'left_cam', encoding))
            self.pub_right.publish(_image(right, stamp + 1000, 'right_cam', encoding))
            stamp += 100_000_000
            end = time.monotonic() + 0.3
            while time.monotonic() < end:
                self.executor.spin_once(timeout_sec=0.02)
                if predicate():
                    return stamp
        raise AssertionError('timed out waiting for the node')

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.driver.destroy_node()


def _prior_overrides(scene, *extra: Parameter) -> list[Parameter]:
    """Return the node's test overrides: the documented default prior, fast diagnostics.

    The prior is not set from the scene's set-up (a prior around the truth would put a
    candidate on the answer); ``scene`` is kept so callers read alike. ``extra`` overrides
    replace same names.
    """
    del scene
    base = [Parameter('diagnostics.period_s', value=0.2)]
    names = {p.name for p in extra}
    return [p for p in base if p.name not in names] + list(extra)


def test_node_publishes_homography_and_mask_matching_truth(ros_context, scene):
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        h.wait_for_subscribers()
        # While the prior search runs (spread over frames) the node publishes all-unknown
        # masks; wait for the mask of a frame with a plane.
        h.send_until(scene.left, scene.right, lambda: h.homographies and h.masks
                     and np.frombuffer(bytes(h.masks[-1].data), np.uint8).any()
                     and h.diagnostics, 10_000_000_000)
        msg = h.homographies[-1]
        assert [d.label for d in msg.layout.dim] == ['rows', 'cols']
        assert [d.size for d in msg.layout.dim] == [3, 3]
        est = np.array(msg.data).reshape(3, 3)
        assert est[2, 2] == pytest.approx(1.0)
        truth_px = np.argwhere(scene.plane_left & scene.visible_in_right)[:, ::-1].astype(float)
        err = np.linalg.norm(apply_homography(est, truth_px)
                             - apply_homography(scene.homography, truth_px), axis=1)
        assert err.mean() < 1.0, err.mean()

        mask_msg = h.masks[-1]
        assert (mask_msg.height, mask_msg.width) == scene.left.shape
        assert mask_msg.encoding == 'mono8'
        assert mask_msg.header.frame_id == 'left_cam'
        mask = np.frombuffer(bytes(mask_msg.data), np.uint8).reshape(scene.left.shape)
        assert set(np.unique(mask)) <= {0, 127, 255}
        plane_truth = scene.plane_left & scene.visible_in_right
        pred_plane = mask == 255
        iou = (pred_plane & plane_truth).sum() / (pred_plane | plane_truth).sum()
        assert iou > 0.6, iou
        obstacle_recall = np.mean(mask[scene.obstacle_left] == 127)
        assert obstacle_recall > 0.5, obstacle_recall

        diag = h.diagnostics[-1].status[0]
        keys = {kv.key for kv in diag.values}
        for key in ('input rate [pairs/s]', 'processing latency median [ms]', 'inliers',
                    'final energy', 'converged', 're-initialisations', 'dropped pairs (busy)'):
            assert key in keys
    finally:
        h.close()


def test_bad_encoding_is_rejected_and_node_recovers(ros_context, scene):
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        h.wait_for_subscribers()
        h.send_until(scene.left, scene.right, lambda: h.node.session.counters.decode_errors >= 2,
                     20_000_000_000, encoding='yuv444_bogus')
        assert not h.homographies
        assert 'yuv444_bogus' in h.node.session.last_error
        h.send_until(scene.left, scene.right, lambda: bool(h.homographies), 30_000_000_000)
        assert np.all(np.isfinite(h.homographies[-1].data))
    finally:
        h.close()


def test_runtime_parameter_changes_are_validated(ros_context, scene):
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        node = h.node
        res = node.set_parameters([Parameter('estimator.potential', value='tukey')])[0]
        assert not res.successful and 'estimator.potential' in res.reason
        res = node.set_parameters([Parameter('prior.tilt_deg', value=[40.0, 10.0])])[0]
        assert not res.successful and 'inverted' in res.reason
        res = node.set_parameters([Parameter('features.roi', value=[0.5, 0.0, 0.2, 1.0])])[0]
        assert not res.successful and 'features.roi' in res.reason
        res = node.set_parameters([Parameter('qos.depth', value=3)])[0]
        assert not res.successful
        assert node.config.estimator.potential == 'truncated_quadratic'
        assert node.get_parameter('estimator.potential').value == 'truncated_quadratic'
        assert node.config.prior.tilt_deg[0] < node.config.prior.tilt_deg[1]
        res = node.set_parameters([Parameter('estimator.potential', value='huber'),
                                   Parameter('sync.slop_s', value=0.02)])
        assert all(r.successful for r in res)
        assert node.config.estimator.potential == 'huber'
        assert node.pipeline.config.estimator.potential == 'huber'
        assert node.session.sync.slop_s == pytest.approx(0.02)
    finally:
        h.close()


@pytest.mark.parametrize('override,needle', [
    (Parameter('estimator.lambda_weight', value=1.5), 'estimator.lambda_weight'),
    (Parameter('prior.focal_px', value=[900.0, 400.0]), 'inverted'),
    (Parameter('estimator.threshold_px', value='three'), 'estimator.threshold_px'),
    (Parameter('no_such.parameter', value=1), 'no_such.parameter'),
    (Parameter('initial_homography', value=[1.0, 0.0, 0.0]), 'initial_homography'),
])
def test_invalid_startup_parameter_fails_with_its_name(ros_context, override, needle):
    with pytest.raises(ConfigError, match=needle.replace('.', r'\.')):
        PlaneNode(context=ros_context, parameter_overrides=[override])


def test_incompatible_publisher_qos_is_warned_once(ros_context, scene):
    overrides = _prior_overrides(scene) + [Parameter('qos.reliable', value=True)]
    h = Harness(ros_context, overrides)  # the driver publishes best effort: incompatible
    try:
        deadline = time.monotonic() + 10.0
        while len(h.node._qos_warned) < 2 and time.monotonic() < deadline:
            h.executor.spin_once(timeout_sec=0.05)
        assert {'left', 'right'} <= h.node._qos_warned
    finally:
        h.close()


def test_slow_processing_keeps_newest_pair_and_counts_drops(ros_context, scene):
    h = Harness(ros_context, _prior_overrides(scene))
    processed_stamps = []
    real_process = h.node.pipeline.process

    def slow_process(left, right, stamp_ns, reset=False, joint_speed=None, stream_gap_ns=None):
        time.sleep(0.25)
        processed_stamps.append(stamp_ns)
        return real_process(left, right, stamp_ns, reset, joint_speed, stream_gap_ns)

    h.node.pipeline.process = slow_process
    try:
        h.wait_for_subscribers()
        stamp = 50_000_000_000
        for _ in range(12):
            h.pub_left.publish(_image(scene.left, stamp, 'left_cam'))
            h.pub_right.publish(_image(scene.right, stamp, 'right_cam'))
            stamp += 33_000_000
            end = time.monotonic() + 0.033
            while time.monotonic() < end:
                h.executor.spin_once(timeout_sec=0.005)
        last_sent = stamp - 33_000_000
        deadline = time.monotonic() + 10.0
        counters = h.node.session.counters
        slot = h.node.slot

        def settled():
            return (processed_stamps and processed_stamps[-1] == last_sent
                    and counters.processed + slot.dropped == counters.pairs)

        while time.monotonic() < deadline and not settled():
            h.executor.spin_once(timeout_sec=0.05)
        assert processed_stamps[-1] == last_sent  # the newest pair was processed
        assert slot.dropped > 0
        assert counters.processed + slot.dropped == counters.pairs
        assert len(processed_stamps) < 12
    finally:
        h.close()
