"""plane_node fed bad input: random messages, bad pairs then good ones, bad parameters.

The node runs in-process with a private rclpy context; the recovery test goes over real DDS
(loopback). Parameter files are tested through the installed ``plane_node`` and
``plane_replay`` executables as subprocesses.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import subprocess
import sys
import time

import cv2
from domplane_ros.health import INPUT_COUNTER_NAMES
from domplane_ros.node import PlaneNode
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from rclpy.exceptions import ParameterNotDeclaredException
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image
from test_bad_input import transfer_error_px
from test_node import _prior_overrides, Harness, scene  # noqa: F401 - scene is a fixture

BIN = Path(sys.executable).parent


# --- Random messages into the image callback ---------------------------------------------

_ENCODINGS = st.one_of(st.sampled_from(['mono8', 'rgb8', 'bgra8', 'mono16', '8UC3']),
                       st.text(max_size=6))


@st.composite
def image_messages(draw, shape=None):
    """A sensor_msgs/Image with random fields; often consistent, sometimes not."""
    msg = Image()
    msg.encoding = draw(_ENCODINGS)
    height, width = shape if shape is not None else (draw(st.integers(0, 40)),
                                                     draw(st.integers(0, 40)))
    msg.height, msg.width = height, width
    channels = {'mono8': 1, 'mono16': 2, 'rgb8': 3, '8UC3': 3, 'bgra8': 4}.get(msg.encoding, 1)
    msg.step = draw(st.one_of(st.just(width * channels), st.integers(0, 200)))
    msg.is_bigendian = draw(st.integers(0, 1))
    length = draw(st.one_of(st.just(height * msg.step), st.integers(0, 2000)))
    seed = draw(st.integers(0, 2**32 - 1))
    flat = draw(st.sampled_from(['random', 'zeros', 'saturated']))
    if flat == 'random':
        data = np.random.default_rng(seed).integers(0, 256, length, dtype=np.uint8)
    else:
        data = np.full(length, 0 if flat == 'zeros' else 255, np.uint8)
    msg.data = data.tobytes()
    stamp_ns = draw(st.one_of(st.just(0), st.integers(-2**62, 2**62),
                              st.integers(1_700_000_000 * 10**9, 1_700_000_100 * 10**9)))
    stamp_ns = max(min(stamp_ns, (2**31 - 1) * 10**9), -(2**31) * 10**9)
    msg.header.stamp.sec = stamp_ns // 10**9
    msg.header.stamp.nanosec = stamp_ns % 10**9
    return msg


@st.composite
def message_streams(draw):
    """1-8 messages on random sides; half the time left and right share one shape."""
    shape = None
    if draw(st.booleans()):
        shape = (draw(st.integers(1, 48)), draw(st.integers(1, 48)))
    return [(draw(st.sampled_from(['left', 'right'])), draw(image_messages(shape)))
            for _ in range(draw(st.integers(1, 8)))]


class _Recorder:
    """Record what a publisher publishes, then publish it for real."""

    def __init__(self, publisher):
        self.messages = []
        self._publish = publisher.publish
        publisher.publish = self

    def __call__(self, msg):
        self.messages.append(msg)
        self._publish(msg)


def _check_published(homographies, masks, diagnostics):
    for msg in homographies:
        h = np.asarray(msg.data, np.float64)
        assert h.shape == (9,) and np.all(np.isfinite(h)) and h[8] == 1.0
    for msg in masks:
        mask = np.frombuffer(bytes(msg.data), np.uint8)
        assert msg.encoding == 'mono8' and mask.size == msg.height * msg.step
        assert set(np.unique(mask)) <= {0, 127, 255}
    for msg in diagnostics:
        status = msg.status[0]
        assert status.level in (b'\x00', b'\x01', b'\x02')
        assert status.message
        for kv in status.values:
            try:
                value = float(kv.value)
            except ValueError:
                continue
            assert math.isfinite(value), (kv.key, kv.value)


def test_random_messages_never_escape_or_publish_invalid_values(ros_context):
    node = PlaneNode(context=ros_context, parameter_overrides=[
        Parameter('features.block_size', value=3), Parameter('sync.slop_s', value=1e-3)])
    # Stop the worker: the test runs the worker's step itself so that any exception escapes.
    with node._cv:
        node._stop = True
        node._cv.notify_all()
    node._worker.join(timeout=5.0)
    recorders = [_Recorder(p) for p in (node._pub_h, node._pub_mask, node._pub_diag)]

    @settings(max_examples=80, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(stream=message_streams())
    def feed(stream):
        for side, msg in stream:
            node._on_image(side, msg)
            pair, node._pending = node._pending, None
            if pair is not None:
                node._process(pair)
        node._publish_diagnostics()

    try:
        feed()
        _check_published(*(r.messages for r in recorders))
        assert node._counters['processed'] > 0 and node._counters['decode_errors'] > 0
        assert recorders[2].messages
    finally:
        node.destroy_node()


# --- Bad pairs, then good ones, over DDS ------------------------------------------------------


def _diagnostic_values(h):
    return {kv.key: kv.value for kv in h.diagnostics[-1].status[0].values}


def test_node_fed_bad_pairs_then_good_pairs_recovers(ros_context, scene):  # noqa: F811
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        h.wait_for_subscribers()
        counts = h.node.pipeline.checks.counts
        small = cv2.resize(scene.right, (320, 240), interpolation=cv2.INTER_AREA)
        stamp = h.send_until(scene.left, small, lambda: counts['size_mismatch'] >= 2,
                             10_000_000_000)
        black = np.zeros_like(scene.left)
        stamp = h.send_until(black, scene.right, lambda: counts['clipped'] >= 2, stamp)
        flat = np.full_like(scene.left, 90)
        stamp = h.send_until(flat, flat, lambda: counts['too_few_features'] >= 2, stamp)
        stamp = h.send_until(scene.left, scene.right,
                             lambda: h.node._decode_counts['decode_encoding'] >= 2, stamp,
                             encoding='yuv444_bogus')
        # A failing stream: masks of zeros, no homography, diagnostics WARN or ERROR.
        h.send_until(flat, flat, lambda: h.diagnostics and h.diagnostics[-1].status[0].level
                     == b'\x02', stamp)
        assert not h.homographies
        assert h.masks and all(not np.frombuffer(bytes(m.data), np.uint8).any()
                               for m in h.masks)
        values = _diagnostic_values(h)
        assert 'too few left features' in h.diagnostics[-1].status[0].message
        assert int(values['pairs refused: left/right sizes differ']) >= 2
        assert int(values['pairs refused: black or saturated']) >= 2
        assert int(values['decode errors (encoding)']) >= 2
        assert set(INPUT_COUNTER_NAMES.values()) <= set(values)
        # Good pairs: the node locks again on the true plane.
        h.send_until(scene.left, scene.right, lambda: bool(h.homographies), stamp + 10**9)
        est = np.asarray(h.homographies[-1].data).reshape(3, 3)
        assert transfer_error_px(scene, est) < 1.0
        assert h.node._counters['internal_errors'] == 0
    finally:
        h.close()


# --- Parameters ------------------------------------------------------------------------------

_BAD_PARAMS = [
    ('unknown key', 'no_such.key: 1', "unknown parameter 'no_such.key'"),
    ('wrong type', "estimator.threshold_px: 'three'", "'estimator.threshold_px'"),
    ('out of range', 'estimator.lambda_weight: 1.5', "'estimator.lambda_weight'"),
    ('inverted range', 'prior.tilt_deg: [40.0, 10.0]', "'prior.tilt_deg': inverted range"),
    ('new parameter out of range', 'pipeline.min_inlier_spread: 2.0',
     "'pipeline.min_inlier_spread'"),
]


def _params_file(tmp_path, line, name):
    path = tmp_path / f'{name.replace(" ", "_")}.yaml'
    path.write_text(f'plane_node:\n  ros__parameters:\n    {line}\n')
    return path


def test_bad_params_file_fails_startup_with_one_line(tmp_path, ros_domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id))
    procs = []
    for name, line, needle in _BAD_PARAMS:
        path = _params_file(tmp_path, line, name)
        node = subprocess.Popen([str(BIN / 'plane_node'), '--ros-args', '--params-file',
                                 str(path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env)
        replay = subprocess.Popen([str(BIN / 'plane_replay'), str(tmp_path / 'in'),
                                   str(tmp_path / 'out'), '--params-file', str(path)],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                  env=env)
        procs.append((name, needle, node, replay))
    for name, needle, node, replay in procs:
        for prog, proc in (('plane_node', node), ('plane_replay', replay)):
            out, err = proc.communicate(timeout=60)
            lines = [line for line in err.splitlines() if line.strip()]
            assert proc.returncode == 2, (name, prog, err)
            assert len(lines) == 1 and lines[0].startswith(f'{prog}: '), (name, err)
            assert needle in lines[0], (name, lines[0])
            assert out == ''
    assert not (tmp_path / 'out').exists()


def test_runtime_parameter_changes_are_refused_and_old_values_kept(ros_context):
    node = PlaneNode(context=ros_context)
    try:
        before = node.config
        cases = [
            (Parameter('estimator.threshold_px', value='three'), 'estimator.threshold_px'),
            (Parameter('estimator.threshold_px', value=-1.0), 'estimator.threshold_px'),
            (Parameter('pipeline.min_inlier_spread', value=1.5), 'pipeline.min_inlier_spread'),
            (Parameter('pipeline.max_stamp_jump_s', value=True), 'pipeline.max_stamp_jump_s'),
            (Parameter('prior.vergence_deg', value=[3.0, -3.0]), 'inverted'),
            (Parameter('features.max_points', value=2.5), 'features.max_points'),
        ]
        for param, needle in cases:
            result = node.set_parameters([param])[0]
            assert not result.successful, param.name
            assert needle in result.reason, result.reason
        with pytest.raises(ParameterNotDeclaredException):
            node.set_parameters([Parameter('no_such.key', value=1)])
        assert node.config == before and node.pipeline.config == before
        assert node.get_parameter('estimator.threshold_px').value == 3.0
        assert node.get_parameter('pipeline.min_inlier_spread').value == 0.02
        # A good change in the same call as a bad one is refused too (all or nothing).
        result = node.set_parameters_atomically([
            Parameter('pipeline.max_stamp_jump_s', value=30.0),
            Parameter('estimator.lambda_weight', value=2.0)])
        assert not result.successful and node.config == before
        assert node.set_parameters([Parameter('pipeline.max_stamp_jump_s',
                                              value=30.0)])[0].successful
        assert node.pipeline.checks.max_stamp_jump_s == 30.0
    finally:
        node.destroy_node()
