"""What the session-13 audit found at the node's interface (docs/HARDENING.md, Audit).

``ros2 param set`` of an undeclared name got rclpy's ``Invalid access to undeclared
parameter(s): []``; ``plane_node --help`` left out ``plane/parallax``; docs/PARAMETERS.md did
not say which parameters only take effect at start-up; and ``/diagnostics`` said only "no
images" when a camera's publisher offered incompatible QoS (the log said why once); a 12-bit
camera's mono16 gave no hint, and the cameras going silent after an ERROR dropped the status
to WARN without the reason.
"""

from __future__ import annotations

from pathlib import Path
import re
import time

from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.replay.reader import ReplaySession
from domplane_ros.ros.messages import READ_ONLY
from domplane_ros.ros.node import PlaneNode
from domplane_ros.ros.usage import usage
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

DOCS = Path(__file__).resolve().parents[2] / 'docs'


def test_undeclared_parameter_set_over_the_service_is_named_with_the_nearest(ros_context):
    node = PlaneNode(context=ros_context)
    driver = Node('audit_param_driver', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(driver)
    try:
        client = AsyncParameterClient(driver, 'plane_node')

        def spin_until(predicate, timeout):
            deadline = time.monotonic() + timeout
            while not predicate() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            return predicate()

        assert spin_until(client.services_are_ready, 15.0), 'no parameter services'
        future = client.set_parameters([Parameter('prior.focal', value=[500.0, 700.0]),
                                        Parameter('prior.focal_px', value=[500.0, 700.0])])
        assert spin_until(future.done, 10.0)
        unknown, known = future.result().results
        assert not unknown.successful
        assert unknown.reason == ("unknown parameter 'prior.focal' "
                                  "(did you mean 'prior.focal_px'?)")
        assert known.successful and node.config.prior.focal_px == (500.0, 700.0)
    finally:
        executor.shutdown()
        driver.destroy_node()
        node.destroy_node()


def test_help_lists_every_topic_the_node_publishes(ros_context):
    node = PlaneNode(context=ros_context)
    try:
        published = {pub.topic_name for pub in node.publishers} - {
            '/rosout', '/parameter_events'}
    finally:
        node.destroy_node()
    assert '/plane/parallax' in published
    text = usage()
    for topic in published:
        name = topic if topic == '/diagnostics' else topic.lstrip('/')
        assert re.search(rf'(^|[ ,]){re.escape(name)}([ ,]|$)', text, re.M), topic


def test_parameters_doc_names_the_start_up_only_parameters():
    text = ' '.join((DOCS / 'PARAMETERS.md').read_text().split())
    match = re.search(r'Only at start-up \([^)]*\): ((?:`[a-z_.]+`(?:, | and )?)+)', text)
    assert match, 'docs/PARAMETERS.md should list the start-up-only parameters'
    assert set(re.findall(r'`([a-z_.]+)`', match.group(1))) == set(READ_ONLY)


def test_silent_camera_with_incompatible_publisher_says_so_in_diagnostics(ros_context):
    node = PlaneNode(context=ros_context, parameter_overrides=[
        Parameter('qos.reliable', value=True), Parameter('diagnostics.period_s', value=0.2),
        Parameter('diagnostics.silence_s', value=0.1)])
    driver = Node('audit_qos_driver', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(driver)
    statuses = []
    try:
        for side in ('left', 'right'):   # a camera driver that publishes best effort
            driver.create_publisher(Image, f'{side}/image_raw', qos_profile_sensor_data)
        driver.create_subscription(DiagnosticArray, '/diagnostics',
                                   lambda msg: statuses.append(msg.status[0]), 10)

        def said_why():
            return (len(node._qos_warned) == 2 and statuses
                    and 'incompatible' in statuses[-1].message)

        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline and not said_why():
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        driver.destroy_node()
        node.destroy_node()
    message = statuses[-1].message
    assert message.startswith('no images on /left/image_raw'), message
    assert ('a publisher on /left/image_raw, /right/image_raw offers QoS incompatible with this '
            'reliable subscription: set qos.reliable to match it') in message


def test_replay_applies_camera_info_as_the_node_does(ros_context):
    overrides = [Parameter('camera_info.topic', value='left/camera_info'),
                 Parameter('camera_info.focal_tolerance', value=0.2),
                 Parameter('prior.focal_px', value=[1500.0, 2500.0])]
    node = PlaneNode(context=ros_context, parameter_overrides=overrides)
    try:
        session = ReplaySession(node.config)
        uncalibrated, calibrated = CameraInfo(), CameraInfo()
        uncalibrated.width = calibrated.width = 640
        uncalibrated.height = calibrated.height = 480
        calibrated.k = [702.0, 0.0, 330.0, 0.0, 698.0, 250.0, 0.0, 0.0, 1.0]
        for msg in (uncalibrated, calibrated, calibrated):
            node._on_camera_info(msg)
            note = session.apply_camera_info(msg)
            assert session.config.prior == node.config.prior, note
        assert node.config.prior.focal_px == (560.0, 840.0)
        assert node.config.prior.principal_point_px == (330.0, 250.0)
        assert session.pipeline.config == node.pipeline.config
    finally:
        node.destroy_node()


class _Logger:
    """Stands in for the node's logger: keeps what it was asked to warn."""

    def __init__(self):
        self.warnings = []

    def warning(self, message, **kwargs):
        self.warnings.append(message)

    def __getattr__(self, name):
        return lambda *args, **kwargs: None


def _image(stamp_ns, encoding, data, width=64, height=48):
    msg = Image()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    msg.height, msg.width, msg.encoding = height, width, encoding
    msg.step = width * (2 if encoding == 'mono16' else 1)
    msg.data = data
    return msg


def test_mono16_range_and_silence_after_errors_reach_log_and_diagnostics(ros_context):
    node = PlaneNode(context=ros_context, parameter_overrides=[
        Parameter('diagnostics.period_s', value=60.0),
        Parameter('diagnostics.silence_s', value=0.05)])
    node.stop_worker()
    logger = _Logger()
    node.get_logger = lambda: logger
    published = []
    node._pub_diag.publish = published.append
    rng = np.random.default_rng(0)
    t0 = 1_700_000_000 * 10**9

    def feed(k, encoding, data):
        for side in ('left', 'right'):
            node.on_image(side, _image(t0 + k * 10**8, encoding, data))
        assert node.process_pending()

    def status():
        node.publish_diagnostics()
        msg = published[-1].status[0]
        return msg.level[0], msg.message, {kv.key: kv.value for kv in msg.values}

    try:
        # A 12-bit camera's mono16 read as 16 bits: one throttled log line and the status.
        twelve_bit = (rng.integers(0, 4096, 48 * 64).astype('<u2')).tobytes()
        for k in range(3):
            feed(k, 'mono16', twelve_bit)
        said = [w for w in logger.warnings if 'image.mono16_bits' in w]
        assert len(said) == 1 and '(12 fit the data)' in said[0]
        level, message, values = status()
        assert level >= 1 and 'image.mono16_bits' in message
        assert 'image.mono16_bits' in values['image warning']
        # Set at runtime: the warning goes.
        assert node.set_parameters([Parameter('image.mono16_bits', value=12)])[0].successful
        feed(3, 'mono16', twelve_bit)
        assert status()[2]['image warning'] == 'none'
        # mono8: no warning whatever its range.
        feed(4, 'mono8', (rng.integers(0, 8, 48 * 64).astype(np.uint8)).tobytes())
        assert status()[2]['image warning'] == 'none'
        # Undecodable pairs (ERROR), then the cameras stop: ERROR, both reasons.
        for k in range(5, 8):
            feed(k, 'nv12', bytes(48 * 64))
        assert status()[0] == 2
        time.sleep(0.2)
        level, message, _ = status()
        assert level == 2 and message.startswith('no images on /left/image_raw'), message
        assert re.search(r'; last pairs: no plane for \d+ pairs: image rejected: unsupported '
                         r"encoding 'nv12'", message), message
    finally:
        node.destroy_node()
