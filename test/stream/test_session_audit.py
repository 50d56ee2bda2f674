"""The audit's findings 13, 16 and 20 in the layer the node, the replay and plane_pair share."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

from domplane_ros.config import ImageConfig, PlaneNodeConfig
from domplane_ros.core.image import image_to_gray, mono16_to_gray
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.stream.session import StreamSession
from domplane_ros.stream.status import (ERROR, OK, plane_status, reason_for_arguments,
                                        SWAP_HINT_ARGUMENTS, SWAP_HINT_TOPICS, WARN)
import numpy as np
import pytest
from truth import transfer_error_px

T0 = 1_700_000_000 * 10**9


def _image(gray: np.ndarray, stamp_ns: int, encoding: str = 'mono8', shift: int = 4):
    """Return a duck-typed Image; mono16 holds 12-bit data, ``grey << shift``."""
    height, width = gray.shape
    if encoding == 'mono16':
        data, step = (gray.astype('<u2') << shift).tobytes(), 2 * width
    else:
        data, step = gray.tobytes(), width
    stamp = SimpleNamespace(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return SimpleNamespace(header=SimpleNamespace(stamp=stamp, frame_id='cam'),
                           height=height, width=width, step=step, encoding=encoding,
                           is_bigendian=0, data=data)


def _process(session: StreamSession, frame, k: int, encoding: str, now: float):
    stamp = T0 + k * 10**8
    pairs = []
    for side, gray in (('left', frame.left), ('right', frame.right)):
        pairs += session.receive(side, stamp, _image(gray, stamp, encoding), now)[0]
    (pair,) = pairs
    return session.process(pair)


@pytest.fixture(scope='module')
def scene():
    return scene_sequence(1, seed=5, width=320, height=240, n_boxes=3)[0]


def test_mono16_bits_scales_a_12_bit_sensor_to_the_full_grey_range():
    grey = np.arange(256, dtype=np.uint8).reshape(16, 16)
    twelve_bit = grey.astype(np.uint16) << 4      # a 12-bit sensor's values, all < 4096
    msg = _image(grey, T0, 'mono16')
    # The default, as cv_bridge: the high byte, 16 grey levels of 256.
    assert np.array_equal(image_to_gray(msg), grey >> 4)
    assert np.array_equal(image_to_gray(msg, mono16_bits=12), grey)
    # Values above the configured range saturate instead of wrapping.
    assert mono16_to_gray(np.array([[4095, 4096, 65535]], np.uint16), 12).tolist() == \
        [[255, 255, 255]]
    assert np.array_equal(mono16_to_gray(twelve_bit, 16), grey >> 4)
    with pytest.raises(ValueError, match='8..16'):
        mono16_to_gray(twelve_bit, 7)


def test_12_bit_mono16_gives_the_plane_with_image_mono16_bits_and_a_hint_without(scene):
    # Default 16 bits: 16 grey levels, no plane, and a warning naming the parameter.
    session = StreamSession(PlaneNodeConfig(), start=0.0)
    frame = _process(session, scene, 0, 'mono16', now=0.0)
    assert not frame.publishable
    assert 'image.mono16_bits' in frame.image_warning and '(12 fit the data)' in \
        frame.image_warning
    level, message, values = session.status(now=0.1)
    assert level >= WARN and 'image.mono16_bits' in message
    assert 'image.mono16_bits' in dict(values)['image warning']
    # image.mono16_bits 12: the decoded images are the 8-bit ones, and the plane is the truth.
    config = replace(PlaneNodeConfig(), image=ImageConfig(mono16_bits=12))
    session = StreamSession(config, start=0.0)
    frame = _process(session, scene, 0, 'mono16', now=0.0)
    assert np.array_equal(frame.left, scene.left)
    assert frame.image_warning == ''
    assert frame.publishable, frame.result.reason
    assert transfer_error_px(scene, frame.result.homography) < 1.0
    assert dict(session.status(now=0.1)[2])['image warning'] == 'none'


def test_mono8_pairs_get_no_image_warning(scene):
    session = StreamSession(replace(PlaneNodeConfig(), image=ImageConfig(mono16_bits=12)),
                            start=0.0)
    dark = replace(scene, left=scene.left >> 4, right=scene.right >> 4)  # 16 grey levels
    frame = _process(session, dark, 0, 'mono8', now=0.0)
    assert frame.image_warning == '' and session.image_warning == ''
    assert dict(session.status(now=0.1)[2])['image warning'] == 'none'


def _status(cameras, consecutive_failures, result, rate=0.0, last_error=''):
    return plane_status(rate=rate, latencies_ms=[], pairs=3, processed=3, dropped_busy=0,
                        dropped_sync=0, decode_errors=0, lock_state='searching',
                        reinitialisations=1, consecutive_failures=consecutive_failures,
                        last_result=result, last_error=last_error, cameras=cameras,
                        silence_s=1.0)


SWAPPED = SimpleNamespace(ok=False, reason="left and right cameras appear swapped: the plane's "
                          'disparity shrinks toward the image bottom (-0.050 px per row); '
                          'swap the image topics', warm_start='', confidence=0.0,
                          candidates=0, n_inliers=0)


def test_silence_after_pairs_without_a_plane_keeps_the_error_and_its_reason():
    silent = [('/left/image_raw', 3, 0.0, 5.0), ('/right/image_raw', 3, 0.0, 5.0)]
    level, message, _ = _status(silent, 3, SWAPPED)
    assert level == ERROR
    assert message.startswith('no images on /left/image_raw for 5.0 s')
    assert message.endswith('; last pairs: no plane for 3 pairs: ' + SWAPPED.reason)
    # One pair without a plane, then silence: WARN with both.
    level, message, _ = _status(silent, 1, SWAPPED)
    assert level == WARN and 'no images on' in message and 'appear swapped' in message
    # A locked plane, then silence: WARN, the silence only (as before).
    locked = SimpleNamespace(ok=True, reason='', warm_start='tracked', confidence=1.0,
                             candidates=0, n_inliers=50, estimate=SimpleNamespace(
                                 potential='truncated_quadratic', final_energy=1.0,
                                 converged=True))
    level, message, _ = _status(silent, 0, locked)
    assert (level, message) == (WARN, 'no images on /left/image_raw for 5.0 s, '
                                      '/right/image_raw for 5.0 s')
    # Images flowing but none paired after the failures: the same.
    flowing = [('/left/image_raw', 3, 10.0, 0.1), ('/right/image_raw', 3, 10.0, 0.1)]
    level, message, _ = _status(flowing, 3, SWAPPED)
    assert level == ERROR and message.startswith('no stereo pairs received; last pairs: ')
    assert _status(flowing, 0, locked, rate=10.0)[:2] == (OK, 'plane searching')


def test_the_session_keeps_the_error_when_the_cameras_stop():
    session = StreamSession(start=0.0)
    for k in range(3):   # three undecodable pairs: ERROR
        stamp = T0 + k * 10**8
        msg = _image(np.zeros((8, 8), np.uint8), stamp, 'nv12')
        session.receive('left', stamp, msg, 0.1 * k)
        (pair,), _ = session.receive('right', stamp, msg, 0.1 * k)
        assert session.process(pair) is None
    level, message, _ = session.status(now=0.3)
    assert level == ERROR and message.startswith('no plane for 3 pairs')
    level, message, _ = session.status(now=5.0)   # both cameras silent for 4.8 s
    assert level == ERROR
    assert message.startswith('no images on /left/image_raw for 4.8 s')
    assert "last pairs: no plane for 3 pairs: image rejected: unsupported encoding 'nv12'" \
        in message


def test_the_swap_hint_names_the_arguments_for_plane_pair_only():
    assert SWAPPED.reason.endswith(SWAP_HINT_TOPICS)
    said = reason_for_arguments(SWAPPED.reason)
    assert said == SWAPPED.reason.replace(SWAP_HINT_TOPICS, SWAP_HINT_ARGUMENTS)
    assert 'topics' not in said
    other = 'plane not verified: too few textured pixels'
    assert reason_for_arguments(other) == other
