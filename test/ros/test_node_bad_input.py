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

import cv2
from domplane_ros.ros.node import PlaneNode
from domplane_ros.stream.health import INPUT_COUNTER_NAMES
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from rclpy.exceptions import ParameterNotDeclaredException
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image
from test_node import _prior_overrides, Harness, scene  # noqa: F401 - scene is a fixture
from truth import transfer_error_px

BIN = Path(sys.executable).parent


# --- Random messages into the image callback ---------------------------------------------

_CHANNELS = {'mono8': 1, 'mono16': 2, 'rgb8': 3, '8UC3': 3, 'bgra8': 4}
_ENCODINGS = st.one_of(st.sampled_from(sorted(_CHANNELS)), st.text(max_size=6))


def _set_stamp(msg, stamp_ns):
    stamp_ns = max(min(stamp_ns, (2**31 - 1) * 10**9), -(2**31) * 10**9)
    msg.header.stamp.sec = stamp_ns // 10**9
    msg.header.stamp.nanosec = stamp_ns % 10**9


@st.composite
def image_messages(draw, shape, stamp_ns, scene_image=None):
    """Draw a sensor_msgs/Image: a random or ``scene_image``, with valid or random fields."""
    msg = Image()
    _set_stamp(msg, stamp_ns)
    if scene_image is not None and draw(st.integers(0, 2)) > 0:
        msg.height, msg.width = scene_image.shape
        msg.encoding, msg.step = 'mono8', scene_image.shape[1]
        msg.data = scene_image.tobytes()
        return msg
    valid = draw(st.integers(0, 3)) > 0
    msg.encoding = draw(st.sampled_from(sorted(_CHANNELS)) if valid else _ENCODINGS)
    height, width = shape if valid else (draw(st.integers(0, 40)), draw(st.integers(0, 40)))
    msg.height, msg.width = height, width
    row = width * _CHANNELS.get(msg.encoding, 1)
    msg.step = row + draw(st.integers(0, 3)) if valid else draw(st.integers(0, 200))
    msg.is_bigendian = draw(st.integers(0, 1))
    length = height * msg.step if valid else draw(st.integers(0, 2000))
    content = draw(st.sampled_from(['noise', 'blocks', 'zeros', 'saturated']))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if content == 'noise':
        data = rng.integers(0, 256, length, dtype=np.uint8)
    elif content == 'blocks':   # a few large squares: corners, maybe collinear or clustered
        data = np.repeat(rng.integers(0, 256, length // 64 + 1, dtype=np.uint8), 64)[:length]
    else:
        data = np.full(length, 0 if content == 'zeros' else 255, np.uint8)
    msg.data = data.tobytes()
    return msg


_STAMPS = st.one_of(st.just(0), st.integers(-2**62, 2**62),
                    st.integers(1_700_000_000 * 10**9, 1_700_000_100 * 10**9))


@st.composite
def message_streams(draw, scene_pair):
    """1-5 stereo pairs (random stamps, jitter, order) and sometimes a lone message."""
    shape = (draw(st.integers(1, 120)), draw(st.integers(1, 160)))
    use_scene = draw(st.booleans())
    left_scene, right_scene = scene_pair if use_scene else (None, None)
    stream = []
    for _ in range(draw(st.integers(1, 5))):
        stamp = draw(_STAMPS)
        jitter = draw(st.one_of(st.just(0), st.integers(-5_000_000, 5_000_000)))
        right_shape = shape if draw(st.integers(0, 4)) else (shape[0], shape[1] + 1)
        pair = [('left', draw(image_messages(shape, stamp, left_scene))),
                ('right', draw(image_messages(right_shape, stamp + jitter, right_scene)))]
        if draw(st.booleans()):
            pair.reverse()
        stream += pair
        if draw(st.integers(0, 4)) == 0:
            stream.append((draw(st.sampled_from(['left', 'right'])),
                           draw(image_messages(shape, draw(_STAMPS)))))
    return stream


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


def test_random_messages_never_escape_or_publish_invalid_values(ros_context, scene):  # noqa
    # The scene at a quarter of its size (and the prior scaled to it) gives planes too.
    scene_pair = tuple(cv2.resize(img, (160, 120), interpolation=cv2.INTER_AREA)
                       for img in (scene.left, scene.right))
    overrides = [p for p in _prior_overrides(scene) if p.name != 'prior.focal_px']
    focal = scene.setup.focal_px / 4
    node = PlaneNode(context=ros_context, parameter_overrides=overrides + [
        Parameter('prior.focal_px', value=[0.8 * focal, 1.2 * focal]),
        Parameter('features.block_size', value=3), Parameter('sync.slop_s', value=1e-3),
        # The whole prior search in one pair, so that a lone scene pair gives a plane.
        Parameter('pipeline.search_candidates_per_frame', value=6)])
    # Stop the worker: the test runs the worker's step itself so that any exception escapes.
    node.stop_worker()
    recorders = [_Recorder(p) for p in (node._pub_h, node._pub_mask, node._pub_diag)]

    @settings(max_examples=80, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(stream=message_streams(scene_pair))
    def feed(stream):
        for side, msg in stream:
            node.on_image(side, msg)
            node.process_pending()
        node.publish_diagnostics()

    try:
        feed()
        _check_published(*(r.messages for r in recorders))
        counters = node.session.counters
        assert counters.processed > 0 and counters.decode_errors > 0
        assert recorders[2].messages
        assert recorders[0].messages, 'some random streams should hold planes'
        assert counters.internal_errors == 0
    finally:
        node.destroy_node()


# --- Bad pairs, then good ones, over DDS ------------------------------------------------------


def _diagnostic_values(h):
    return {kv.key: kv.value for kv in h.diagnostics[-1].status[0].values}


def test_node_fed_bad_pairs_then_good_pairs_recovers(ros_context, scene):  # noqa: F811
    h = Harness(ros_context, _prior_overrides(scene))
    try:
        h.wait_for_subscribers()
        counts = h.node.session.counts
        small = cv2.resize(scene.right, (320, 240), interpolation=cv2.INTER_AREA)
        stamp = h.send_until(scene.left, small, lambda: counts['size_mismatch'] >= 2,
                             10_000_000_000)
        black = np.zeros_like(scene.left)
        stamp = h.send_until(black, scene.right, lambda: counts['clipped'] >= 2, stamp)
        flat = np.full_like(scene.left, 90)
        stamp = h.send_until(flat, flat, lambda: counts['too_few_features'] >= 2, stamp)
        stamp = h.send_until(scene.left, scene.right,
                             lambda: counts['decode_encoding'] >= 2, stamp,
                             encoding='yuv444_bogus')
        # A failing stream: masks of zeros, no homography, diagnostics ERROR. (Wait for a status
        # about the flat pairs: the one before them can be ERROR already, naming the decoder.)
        h.send_until(flat, flat, lambda: h.diagnostics and h.diagnostics[-1].status[0].level
                     == b'\x02' and 'too few' in h.diagnostics[-1].status[0].message, stamp)
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
        assert h.node.session.counters.internal_errors == 0
    finally:
        h.close()


# --- Parameters ------------------------------------------------------------------------------

_BAD_PARAMS = [
    ('unknown key', 'no_such.key: 1', "unknown parameter 'no_such.key'"),
    ('wrong type', "estimator.threshold_px: 'three'",
     "'estimator.threshold_px': expected a finite number, got 'three'"),
    ('out of range', 'estimator.lambda_weight: 1.5',
     "'estimator.lambda_weight': 1.5 is above the maximum 0.99"),
    ('inverted range', 'prior.tilt_deg: [40.0, 10.0]', "'prior.tilt_deg': inverted range"),
    ('new parameter out of range', 'pipeline.min_inlier_spread: 2.0',
     "'pipeline.min_inlier_spread': 2.0 is above the maximum 1.0"),
    ('integer below minimum', 'features.max_points: 2',
     "'features.max_points': 2 is below the minimum 8"),
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
        assert node.pipeline.config.pipeline.max_stamp_jump_s == 30.0
    finally:
        node.destroy_node()


def _noise_image(stamp_ns, encoding='mono8', seed=0):
    msg = Image()
    _set_stamp(msg, stamp_ns)
    msg.height, msg.width, msg.step, msg.encoding = 48, 64, 64, encoding
    msg.data = np.random.default_rng(seed).integers(0, 256, 48 * 64, np.uint8).tobytes()
    return msg


def test_stamp_problems_and_undecodable_streams_reach_diagnostics(ros_context):
    node = PlaneNode(context=ros_context,
                     parameter_overrides=[Parameter('diagnostics.period_s', value=60.0)])
    node.stop_worker()
    diagnostics = _Recorder(node._pub_diag)

    def status():
        node.publish_diagnostics()
        msg = diagnostics.messages[-1].status[0]
        return msg.level[0], msg.message, {kv.key: kv.value for kv in msg.values}

    try:
        # The right camera's stamps are 50 ms late at 10 Hz: nothing pairs (slop 10 ms).
        t0 = 1_700_000_000 * 10**9
        for k in range(20):
            node.on_image('left', _noise_image(t0 + k * 10**8))
            node.on_image('right', _noise_image(t0 + k * 10**8 + 50_000_000))
        assert not node.process_pending()
        level, message, values = status()
        assert level == 1 and message.startswith('no stereo pairs received; ')
        assert 'differs by 50.0 ms > sync.slop_s 10 ms' in message
        assert int(values['frames unpaired: stamp skew > slop']) >= 20
        # A driver that does not stamp: the first pair goes through, the rest are duplicates.
        for k in range(3):
            node.on_image('left', _noise_image(0, seed=k))
            node.on_image('right', _noise_image(0, seed=k + 10))
            node.process_pending()
        level, message, values = status()
        assert level >= 1 and 'header stamp is zero' in message
        assert values['stamps zero'] == '6'
        # Only undecodable images: WARN, then ERROR after three pairs, naming the problem.
        t1 = t0 + 10 * 10**9
        for k in range(4):
            node.on_image('left', _noise_image(t1 + k * 10**8, encoding='nv12'))
            node.on_image('right', _noise_image(t1 + k * 10**8, encoding='nv12'))
            assert node.process_pending()
        level, message, values = status()
        assert level == 2 and "unsupported encoding 'nv12'" in message, message
        assert values['decode errors (encoding)'] == '4'
        assert node.session.counters.internal_errors == 0
    finally:
        node.destroy_node()
