"""plane_node as a ROS 2 user runs it, over real DDS (loopback).

Compressed input (PNG and JPEG payloads of a rendered stereo pair with truth, and KITTI
000046's PNG files as they are), the stamped result on every pair (``plane/result`` carries
the mask's stamp, searching and failed pairs included), a ``/**`` params file under another
node name, and ``camera_info`` (KITTI's calibration for the real pair).
"""

from __future__ import annotations

import json
from pathlib import Path
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from domplane_ros.config import PARAMETERS
from domplane_ros.core.homography import apply_homography
from domplane_ros.ros.node import PlaneNode
from domplane_ros.sim.generators import random_scene
from domplane_ros.stream.pipeline import PlanePipeline
from domplane_ros.tools.evaluation.references import kitti_reference
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from std_msgs.msg import Float64MultiArray
import yaml

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_PARAMS = ROOT / 'config' / 'plane_node.yaml'
_SCENE_SEED = 7  # as test_node.py: a rendered floor with three boxes


@pytest.fixture(scope='module')
def scene():
    return random_scene(_SCENE_SEED, floor='random', n_boxes=3, gain=1.15, offset=-10.0)


def stamp_key(header) -> tuple[int, int]:
    return int(header.stamp.sec), int(header.stamp.nanosec)


def fill_header(msg, stamp_ns: int, frame_id: str):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = frame_id
    return msg


def compressed_msg(gray: np.ndarray, fmt: str, stamp_ns: int, frame_id: str) -> CompressedImage:
    ok, data = cv2.imencode('.png' if fmt == 'png' else '.jpg', gray,
                            [] if fmt == 'png' else [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    msg = fill_header(CompressedImage(), stamp_ns, frame_id)
    msg.format = 'mono8; png compressed mono8' if fmt == 'png' else 'jpeg'
    msg.data = data.tobytes()
    return msg


def raw_msg(gray: np.ndarray, stamp_ns: int, frame_id: str) -> Image:
    msg = fill_header(Image(), stamp_ns, frame_id)
    msg.height, msg.width = gray.shape
    msg.encoding = 'mono8'
    msg.step = gray.shape[1]
    msg.data = gray.tobytes()
    return msg


def result_values(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for kv in msg.status[0].values}


def truth_error_px(scene, homography: np.ndarray) -> float:
    """Mean transfer distance to the true homography over the floor pixels seen by both."""
    px = np.argwhere(scene.plane_left & scene.visible_in_right)[:, ::-1].astype(float)
    return float(np.linalg.norm(apply_homography(homography, px)
                                - apply_homography(scene.homography, px), axis=1).mean())


class Driver:
    """A node that publishes stereo pairs and records what plane_node publishes."""

    def __init__(self, context, nodes, left_topic, right_topic, kind=CompressedImage,
                 namespace=''):
        self.node = Node('interface_driver', context=context)
        self.pub_left = self.node.create_publisher(kind, left_topic, qos_profile_sensor_data)
        self.pub_right = self.node.create_publisher(kind, right_topic, qos_profile_sensor_data)
        self.results: list[DiagnosticArray] = []
        self.masks: list[Image] = []
        self.homographies: list[Float64MultiArray] = []
        self.results_topic = f'{namespace}/plane/result'
        self.node.create_subscription(DiagnosticArray, self.results_topic,
                                      self.results.append, 50)
        self.node.create_subscription(Image, f'{namespace}/plane/mask', self.masks.append, 50)
        self.node.create_subscription(Float64MultiArray, f'{namespace}/plane/homography',
                                      self.homographies.append, 50)
        self.executor = SingleThreadedExecutor(context=context)
        for node in [self.node, *nodes]:
            self.executor.add_node(node)

    def spin_until(self, predicate, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)
            if predicate():
                return
        raise AssertionError('timed out waiting for the node')

    def wait_for_discovery(self, timeout: float = 10.0) -> None:
        self.spin_until(lambda: self.pub_left.get_subscription_count()
                        and self.pub_right.get_subscription_count()
                        and self.node.count_publishers(self.results_topic) > 0, timeout)

    def send_pair(self, left_msg, right_msg, wait_s: float = 0.3) -> None:
        self.pub_left.publish(left_msg)
        self.pub_right.publish(right_msg)
        end = time.monotonic() + wait_s
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def close(self, *nodes) -> None:
        self.executor.shutdown()
        for node in nodes:
            node.destroy_node()
        self.node.destroy_node()


def send_black_then_scene(driver, scene, make_msg, n_black=2, max_pairs=40):
    """Send refused (black) pairs, then scene pairs until one gives a plane; return stamps."""
    black = np.zeros_like(scene.left)
    stamps = []
    stamp = 20_000_000_000
    for i in range(n_black + max_pairs):
        left, right = (black, black) if i < n_black else (scene.left, scene.right)
        driver.send_pair(make_msg(left, stamp, 'left_cam'),
                         make_msg(right, stamp + 1000, 'right_cam'))
        stamps.append(stamp)
        stamp += 100_000_000
        if i >= n_black and any(result_values(r)['plane'] == 'true' for r in driver.results):
            break
    return stamps


def check_results_match_masks(driver, sent_stamps, node):
    """Every processed pair gave one mask and one result with the same stamp; return them."""
    driver.spin_until(lambda: len(driver.results) == node.session.counters.processed
                      and len(driver.masks) == len(driver.results), 10.0)
    result_stamps = [stamp_key(r.header) for r in driver.results]
    mask_stamps = [stamp_key(m.header) for m in driver.masks]
    assert result_stamps == mask_stamps
    assert len(set(result_stamps)) == len(result_stamps)
    sent = {divmod(s, 1_000_000_000) for s in sent_stamps}
    assert set(result_stamps) <= sent
    assert all(r.header.frame_id == 'left_cam' for r in driver.results)
    return dict(zip(result_stamps, driver.results)), dict(zip(mask_stamps, driver.masks))


@pytest.mark.parametrize('fmt', ['png', 'jpeg'])
def test_compressed_pairs_give_the_plane_and_a_result_stamped_like_the_mask(
        ros_context, scene, fmt):
    # The documented default prior: nothing here is set from the scene's set-up.
    node = PlaneNode(context=ros_context, parameter_overrides=[
        Parameter('image_transport', value='compressed')])
    driver = Driver(ros_context, [node], 'left/image_raw/compressed',
                    'right/image_raw/compressed')
    try:
        assert [s.topic_name for s in node._subs] == ['/left/image_raw/compressed',
                                                      '/right/image_raw/compressed']
        driver.wait_for_discovery()
        # A payload that is not an image: one decode error, no output for it, the node goes on.
        garbage = compressed_msg(scene.left, fmt, 1_000_000_000, 'left_cam')
        garbage.data = bytes(range(256)) * 4
        driver.send_pair(garbage, compressed_msg(scene.right, fmt, 1_000_001_000, 'right_cam'))
        driver.spin_until(lambda: node.session.counters.decode_errors == 1, 5.0)
        assert fmt in node.session.last_error and not driver.results and not driver.masks
        stamps = send_black_then_scene(
            driver, scene, lambda gray, stamp, frame: compressed_msg(gray, fmt, stamp, frame))
        results, masks = check_results_match_masks(driver, stamps, node)
        assert node.session.counters.decode_errors == 1

        first = [results[divmod(s, 1_000_000_000)] for s in stamps[:2]]
        for msg in first:  # the black pairs: refused, no plane, an all-unknown mask
            values = result_values(msg)
            assert values['plane'] == 'false' and values['homography'] == '[]'
            assert values['state'] == 'searching' and values['reason']
            assert float(values['confidence']) == 0.0
            assert msg.status[0].level == DiagnosticStatus.WARN
            assert not np.frombuffer(bytes(masks[stamp_key(msg.header)].data), np.uint8).any()

        planes = [r for r in driver.results if result_values(r)['plane'] == 'true']
        assert planes, [result_values(r)['reason'] for r in driver.results]
        values = result_values(planes[-1])
        h = np.array(json.loads(values['homography'])).reshape(3, 3)
        assert np.all(np.isfinite(h)) and h[2, 2] == pytest.approx(1.0)
        assert truth_error_px(scene, h) < 1.0
        assert float(values['confidence']) >= 0.5
        assert values['state'] in ('locked', 'tracking') and values['reason'] == ''
        assert planes[-1].status[0].level == DiagnosticStatus.OK
        # The compatibility topic carries the same matrix (published only with a plane).
        driver.spin_until(lambda: len(driver.homographies) >= len(planes), 5.0)
        assert len(driver.homographies) == len(planes)
        assert np.array_equal(np.array(driver.homographies[-1].data), h.ravel())
        mask = np.frombuffer(bytes(masks[stamp_key(planes[-1].header)].data), np.uint8)
        assert (mask == 255).any()
    finally:
        driver.close(node)


def _edited_params_file(tmp_path: Path, **extra) -> Path:
    """Write the shipped params file with ``extra`` set."""
    document = yaml.safe_load(SHIPPED_PARAMS.read_text(encoding='utf-8'))
    assert list(document) == ['/**']
    params = document['/**']['ros__parameters']
    params.update(extra)
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump(document), encoding='utf-8')
    return path


def test_shipped_params_file_applies_to_a_renamed_node(ros_context, tmp_path):
    node = PlaneNode(context=ros_context, cli_args=[
        '--ros-args', '-r', '__node:=front_plane', '--params-file', str(SHIPPED_PARAMS)])
    try:
        assert node.get_fully_qualified_name() == '/front_plane'
        # Every parameter of the shipped file reached the renamed node.
        assert set(node._parameter_overrides) == {spec.name for spec in PARAMETERS}
    finally:
        node.destroy_node()
    path = _edited_params_file(tmp_path, **{'features.max_points': 123,
                                            'prior.tilt_deg': [5.0, 40.0]})
    node = PlaneNode(context=ros_context, cli_args=[
        '--ros-args', '-r', '__node:=front_plane', '-r', '__ns:=/robot', '--params-file',
        str(path)])
    try:
        assert node.get_fully_qualified_name() == '/robot/front_plane'
        assert node.config.features.max_points == 123
        assert node.get_parameter('features.max_points').value == 123
        assert node.config.prior.tilt_deg == (5.0, 40.0)
    finally:
        node.destroy_node()


def _camera_info(focal: float, cx: float, cy: float, width: int, height: int,
                 stamp_ns: int) -> CameraInfo:
    msg = fill_header(CameraInfo(), stamp_ns, 'left_cam')
    msg.width, msg.height = width, height
    msg.k = [focal, 0.0, cx, 0.0, focal, cy, 0.0, 0.0, 1.0]
    return msg


def test_camera_info_narrows_the_focal_prior_and_sets_the_principal_point(ros_context, scene):
    # A wrong hand-set focal range that K corrects; the rest of the prior is the default.
    overrides = [
        Parameter('prior.focal_px', value=[1500.0, 2500.0]),
        Parameter('camera_info.topic', value='left/camera_info'),
        Parameter('camera_info.focal_tolerance', value=0.1)]
    node = PlaneNode(context=ros_context, parameter_overrides=overrides)
    driver = Driver(ros_context, [node], 'left/image_raw', 'right/image_raw', kind=Image)
    info_pub = driver.node.create_publisher(CameraInfo, 'left/camera_info',
                                            qos_profile_sensor_data)
    try:
        driver.wait_for_discovery()
        height, width = scene.left.shape
        # An uncalibrated camera (K = 0) is ignored: the prior stays as configured.
        for _ in range(3):
            info_pub.publish(_camera_info(0.0, 0.0, 0.0, width, height, 1))
            driver.executor.spin_once(timeout_sec=0.1)
        assert list(node.get_parameter('prior.focal_px').value) == [1500.0, 2500.0]
        f = 1.03 * scene.setup.focal_px  # a calibration 3 % off
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        info_pub.publish(_camera_info(f, cx, cy, width, height, 2))
        driver.spin_until(lambda: node.config.prior.principal_point_px != (), 10.0)
        assert list(node.get_parameter('prior.focal_px').value) == pytest.approx(
            [0.9 * f, 1.1 * f])
        assert list(node.config.prior.focal_px) == pytest.approx([0.9 * f, 1.1 * f])
        assert list(node.pipeline.config.prior.principal_point_px) == pytest.approx([cx, cy])
        # The node keeps running and finds the plane with the narrowed prior.
        stamps = send_black_then_scene(driver, scene, raw_msg, n_black=0)
        check_results_match_masks(driver, stamps, node)
        planes = [r for r in driver.results if result_values(r)['plane'] == 'true']
        assert planes
        h = np.array(json.loads(result_values(planes[-1])['homography'])).reshape(3, 3)
        assert truth_error_px(scene, h) < 1.0
    finally:
        driver.close(node)


KITTI = ROOT / 'test' / 'data' / 'kitti2015_000046'
# KITTI raw 2011_09_26 (the 1242x375 frames) rectified camera 2: f and principal point, px.
KITTI_F, KITTI_CX, KITTI_CY = 721.5377, 609.5593, 172.854
KITTI_TARGET_PX = 1.5  # the evaluation's KITTI target


def test_kitti_png_files_and_camera_info_give_the_road_live_as_offline(ros_context):
    # The rig's documented set-up (b/h, tilt, vergence) and the road's part of the image; the
    # focal length and principal point come from camera_info, nothing from the disparity.
    overrides = [Parameter('image_transport', value='compressed'),
                 Parameter('camera_info.topic', value='left/camera_info'),
                 Parameter('prior.baseline_over_height', value=[0.25, 0.40]),
                 Parameter('prior.tilt_deg', value=[-5.0, 5.0]),
                 Parameter('prior.vergence_deg', value=[-1.0, 1.0]),
                 Parameter('features.roi', value=[0.0, 0.55, 1.0, 1.0])]
    node = PlaneNode(context=ros_context, parameter_overrides=overrides)
    driver = Driver(ros_context, [node], 'left/image_raw/compressed',
                    'right/image_raw/compressed')
    info_pub = driver.node.create_publisher(CameraInfo, 'left/camera_info',
                                            qos_profile_sensor_data)
    files = {side: (KITTI / f'{side}.png').read_bytes() for side in ('left', 'right')}

    def png_file(side, stamp_ns):
        msg = fill_header(CompressedImage(), stamp_ns, f'{side}_cam')
        msg.format = 'rgb8; png compressed bgr8'
        msg.data = files[side]
        return msg

    try:
        driver.wait_for_discovery()
        info = _camera_info(KITTI_F, KITTI_CX, KITTI_CY, 1242, 375, 1)
        info_pub.publish(info)
        driver.spin_until(lambda: node.config.prior.principal_point_px != (), 10.0)
        stamp = 30_000_000_000
        while not driver.results:
            driver.send_pair(png_file('left', stamp), png_file('right', stamp), wait_s=1.0)
            stamp += 100_000_000
            assert stamp < 30_000_000_000 + 20 * 100_000_000, 'no result from the node'
        result = driver.results[0]
        values = result_values(result)
        assert values['plane'] == 'true', values['reason']
        h = np.array(json.loads(values['homography'])).reshape(3, 3)
        driver.spin_until(lambda: any(stamp_key(m.header) == stamp_key(result.header)
                                      for m in driver.masks), 5.0)
        config = node.config
    finally:
        driver.close(node)
    # Road pixels of the ground-truth disparity: x_right = x_left - d.
    disparity = cv2.imread(str(KITTI / 'disp_occ_left.png'), cv2.IMREAD_UNCHANGED) / 256.0
    road = kitti_reference(KITTI).road
    ys, xs = np.nonzero(road)
    src = np.stack([xs, ys], axis=1).astype(float)
    dst = np.stack([xs - disparity[ys, xs], ys], axis=1)
    error = float(np.linalg.norm(apply_homography(h, src) - dst, axis=1).mean())
    assert error < KITTI_TARGET_PX, error
    # Live equals offline: the same decoder and the same first-pair pipeline on the files.
    offline = PlanePipeline(config).process(
        cv2.imread(str(KITTI / 'left.png'), cv2.IMREAD_GRAYSCALE),
        cv2.imread(str(KITTI / 'right.png'), cv2.IMREAD_GRAYSCALE), 30_000_000_000)
    assert offline.ok and np.allclose(offline.homography, h, rtol=0, atol=1e-9)
