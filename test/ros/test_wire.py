"""Serialised images read in place (ros/wire.py) give the fields rclpy gives, pixels uncopied."""

from __future__ import annotations

from array import array

from domplane_ros.core.image import message_to_gray
from domplane_ros.ros.wire import image_from_cdr, RawImage
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image

_FIELDS = ('height', 'width', 'encoding', 'is_bigendian', 'step')


def _message(width: int, height: int, encoding: str, frame_id: str, padding: int,
             sec: int = 1_796_148_113) -> Image:
    channels = {'mono8': 1, 'rgb8': 3, 'mono16': 2}[encoding]
    msg = Image(height=height, width=width, encoding=encoding, is_bigendian=int(padding == 2),
                step=width * channels + padding)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, 123_456_789
    msg.header.frame_id = frame_id
    rng = np.random.default_rng(width + padding)
    msg.data = array('B', rng.integers(0, 256, msg.step * height, dtype=np.uint8).tobytes())
    return msg


@pytest.mark.parametrize('width,height,encoding,frame_id,padding,sec', [
    (64, 48, 'mono8', 'left_cam', 0, 1_796_148_113),
    (5, 3, 'rgb8', '', 1, -5),
    (7, 2, 'mono16', 'x' * 5, 2, 0),
    (13, 11, 'mono8', 'ü' * 3, 3, 2**31 - 1)])
def test_fields_and_pixels_are_those_rclpy_serialised(
        width, height, encoding, frame_id, padding, sec):
    msg = _message(width, height, encoding, frame_id, padding, sec)
    raw = serialize_message(msg)
    image = image_from_cdr(raw)
    assert isinstance(image, RawImage)
    assert image.header == msg.header
    for name in _FIELDS:
        assert getattr(image, name) == getattr(msg, name), name
    assert bytes(image.data) == bytes(msg.data)
    np.testing.assert_array_equal(message_to_gray(image), message_to_gray(msg))


def test_the_pixels_are_a_view_of_the_serialised_bytes():
    raw = serialize_message(_message(64, 48, 'mono8', 'left_cam', 0))
    gray = message_to_gray(image_from_cdr(raw), copy=False)
    assert np.shares_memory(gray, np.frombuffer(raw, np.uint8))
    assert not gray.flags.writeable


def test_bytes_it_does_not_read_go_to_rclpy_or_raise():
    msg = _message(64, 48, 'mono8', 'left_cam', 0)
    raw = serialize_message(msg)
    big_endian = b'\x00\x00' + raw[2:]  # another encapsulation: rclpy's deserialiser decides
    try:
        fallback = image_from_cdr(big_endian)
    except Exception:  # noqa: B902 - rclpy's error types
        fallback = None
    assert not isinstance(fallback, RawImage)
    with pytest.raises(Exception):  # noqa: B017 - rclpy's RMWError for a truncated message
        image_from_cdr(raw[:100])


@pytest.mark.parametrize('transport,raw', [('raw', True), ('compressed', False)])
def test_the_node_takes_raw_images_serialised(ros_context, transport, raw):
    from domplane_ros.ros.node import PlaneNode
    from rclpy.parameter import Parameter
    node = PlaneNode(context=ros_context,
                     parameter_overrides=[Parameter('image_transport', value=transport)])
    try:
        assert [sub.raw for sub in node._subs] == [raw, raw]
        # A message that is no image is counted, not raised into the executor.
        node._on_serialised_image('left', b'\x00\x01\x00\x00' + b'\xff' * 12)
        assert node.session.counters.undecodable_messages == 1
    finally:
        node.destroy_node()
