"""Tests of domplane_ros.core.image: decoding and building sensor_msgs images without ROS."""

from __future__ import annotations

from array import array
from types import SimpleNamespace

import cv2
from domplane_ros.core.image import (
                                     compressed_to_gray,
                                     gray_to_image_fields,
                                     image_to_array,
                                     image_to_gray,
                                     message_to_gray,
                                     rgb_to_image_fields,
                                     SUPPORTED_ENCODINGS,
                                     )
from domplane_ros.errors import DomplaneError, ImageDecodeError
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

# encoding -> (channels, bytes per channel)
LAYOUTS = {
    'mono8': (1, 1), '8UC1': (1, 1), 'mono16': (1, 2), 'rgb8': (3, 1), 'bgr8': (3, 1),
    '8UC3': (3, 1), 'rgba8': (4, 1), 'bgra8': (4, 1),
}
HEIGHT, WIDTH = 5, 7


def _native(encoding: str, seed: int = 0) -> np.ndarray:
    """Return a random image in the encoding's native layout, (H, W) or (H, W, C)."""
    channels, depth = LAYOUTS[encoding]
    rng = np.random.default_rng(seed)
    shape = (HEIGHT, WIDTH) if channels == 1 else (HEIGHT, WIDTH, channels)
    dtype = np.uint16 if depth == 2 else np.uint8
    return rng.integers(0, np.iinfo(dtype).max + 1, size=shape, dtype=dtype)


def _expected_gray(encoding: str, native: np.ndarray) -> np.ndarray:
    if encoding == 'mono16':
        return (native >> 8).astype(np.uint8)
    code = {
        'rgb8': cv2.COLOR_RGB2GRAY, 'bgr8': cv2.COLOR_BGR2GRAY, '8UC3': cv2.COLOR_BGR2GRAY,
        'rgba8': cv2.COLOR_RGBA2GRAY, 'bgra8': cv2.COLOR_BGRA2GRAY,
    }.get(encoding)
    return native if code is None else cv2.cvtColor(native, code)


def _encode(native: np.ndarray, encoding: str, padding: int, bigendian: bool) -> dict:
    """Serialise a native image into message fields with ``padding`` bytes after each row."""
    channels, depth = LAYOUTS[encoding]
    row_bytes = WIDTH * channels * depth
    if depth == 2:
        native = native.astype('>u2' if bigendian else '<u2')
    raw = np.ascontiguousarray(native).view(np.uint8).reshape(HEIGHT, row_bytes)
    padded = np.full((HEIGHT, row_bytes + padding), 0xAB, dtype=np.uint8)
    padded[:, :row_bytes] = raw
    return {
        'header': None, 'height': HEIGHT, 'width': WIDTH, 'encoding': encoding,
        'is_bigendian': int(bigendian), 'step': row_bytes + padding, 'data': padded.tobytes(),
    }


def _cases():
    for encoding in SUPPORTED_ENCODINGS:
        for padding in (0, 3):
            for bigendian in ((False, True) if encoding == 'mono16' else (False,)):
                yield encoding, padding, bigendian


CASES = list(_cases())


def _rclpy_image(fields: dict):
    sensor_msgs = pytest.importorskip('sensor_msgs.msg')
    msg = sensor_msgs.Image()
    for key, value in fields.items():
        if key != 'header':
            setattr(msg, key, value)
    return msg


def _rosbags_types():
    typesys = pytest.importorskip('rosbags.typesys')
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    return store


def _rosbags_image(fields: dict, roundtrip_cdr: bool = True):
    store = _rosbags_types()
    image_type = store.types['sensor_msgs/msg/Image']
    header = store.types['std_msgs/msg/Header'](
        stamp=store.types['builtin_interfaces/msg/Time'](sec=1, nanosec=2), frame_id='cam')
    msg = image_type(
        header=header, height=fields['height'], width=fields['width'],
        encoding=fields['encoding'], is_bigendian=fields['is_bigendian'], step=fields['step'],
        data=np.frombuffer(fields['data'], dtype=np.uint8))
    if roundtrip_cdr:  # As a message read from a bag: data is a view into the CDR buffer.
        raw = store.serialize_cdr(msg, image_type.__msgtype__)
        msg = store.deserialize_cdr(raw, image_type.__msgtype__)
    return msg


MESSAGE_KINDS = {
    'namespace': lambda fields: SimpleNamespace(**fields),
    'namespace_array': lambda fields: SimpleNamespace(
        **{**fields, 'data': array('B', fields['data'])}),
    'rclpy': _rclpy_image,
    'rosbags': _rosbags_image,
}


@pytest.mark.parametrize('kind', sorted(MESSAGE_KINDS))
@pytest.mark.parametrize('encoding,padding,bigendian', CASES)
def test_decode_every_encoding_with_padding(kind, encoding, padding, bigendian):
    native = _native(encoding, seed=len(encoding) + padding)
    msg = MESSAGE_KINDS[kind](_encode(native, encoding, padding, bigendian))

    array_out, encoding_out = image_to_array(msg)
    assert encoding_out == encoding
    assert array_out.dtype == native.dtype and array_out.dtype.isnative
    assert array_out.flags.c_contiguous
    np.testing.assert_array_equal(array_out, native)

    gray = image_to_gray(msg)
    assert gray.shape == (HEIGHT, WIDTH) and gray.dtype == np.uint8
    np.testing.assert_array_equal(gray, _expected_gray(encoding, native))
    np.testing.assert_array_equal(message_to_gray(msg), gray)
    # Without a copy: the same pixels; a view of the message's data only where it can be.
    view = message_to_gray(msg, copy=False)
    np.testing.assert_array_equal(view, gray)
    assert view.flags.c_contiguous and view.dtype == np.uint8
    data = np.frombuffer(memoryview(msg.data).cast('B'), np.uint8)
    aliased = encoding in ('mono8', '8UC1') and padding == 0
    assert np.shares_memory(view, data) == aliased
    assert view.flags.writeable != aliased


def test_rclpy_image_data_reads_back_as_array_of_bytes():
    msg = _rclpy_image(_encode(_native('mono8'), 'mono8', 0, False))
    assert isinstance(msg.data, array) and msg.data.typecode == 'B'


def test_rosbags_image_data_is_uint8_ndarray():
    msg = _rosbags_image(_encode(_native('mono8'), 'mono8', 0, False))
    assert isinstance(msg.data, np.ndarray) and msg.data.dtype == np.uint8


def test_decoded_image_does_not_alias_message_data():
    fields = _encode(_native('mono8'), 'mono8', 0, False)
    msg = SimpleNamespace(**{**fields, 'data': bytearray(fields['data'])})
    gray = image_to_gray(msg)
    before = gray.copy()
    msg.data[:] = bytes(len(msg.data))
    np.testing.assert_array_equal(gray, before)


def test_mono16_scaling_keeps_high_byte():
    native = np.array([[0, 255, 256, 65535]], dtype=np.uint16)
    msg = SimpleNamespace(
        height=1, width=4, encoding='mono16', is_bigendian=0, step=8,
        data=native.astype('<u2').tobytes())
    np.testing.assert_array_equal(image_to_gray(msg), [[0, 0, 1, 255]])


def test_is_bigendian_accepts_bool():
    native = np.array([[1, 2]], dtype=np.uint16) * 300
    msg = SimpleNamespace(
        height=1, width=2, encoding='mono16', is_bigendian=True, step=4,
        data=native.astype('>u2').tobytes())
    np.testing.assert_array_equal(image_to_array(msg)[0], native)


def _good_fields(**changes) -> dict:
    fields = _encode(_native('rgb8'), 'rgb8', 2, False)
    fields.update(changes)
    return fields


@pytest.mark.parametrize('changes,problem', [
    ({'encoding': 'xyz'}, "unsupported encoding 'xyz'"),
    ({'encoding': 'yuv422'}, 'supported encodings are mono8'),
    ({'encoding': None}, "'encoding' must be a string"),
    ({'height': 0, 'data': b''}, 'zero width or height'),
    ({'width': 0}, 'zero width or height'),
    ({'step': 3 * WIDTH - 1}, 'step 20 is smaller than width * bytes_per_pixel'),
    ({'data': b'\x00' * 10}, 'data length 10 != height * step'),
    ({'data': b'\x00' * (HEIGHT * (3 * WIDTH + 2) + 1)}, 'data length 116 != height * step'),
    ({'height': 5.0}, "'height' must be an integer"),
    ({'width': '7'}, "'width' must be an integer"),
    ({'step': None}, "'step' must be an integer"),
    ({'is_bigendian': 0.5}, "'is_bigendian' must be an integer"),
    ({'height': -5}, "'height' must be non-negative"),
    ({'height': True}, "'height' must be an integer"),
    ({'data': 'not bytes'}, 'image data must be bytes'),
    ({'data': 115}, 'image data must be bytes'),
    ({'data': np.zeros(115, dtype=np.int16)}, 'must have dtype uint8'),
    ({'data': array('H', [0] * 115)}, 'items of 2 bytes'),
    ({'data': [300] * 115}, 'sequence of ints in [0, 255]'),
])
def test_bad_image_raises_decode_error_naming_problem(changes, problem):
    msg = SimpleNamespace(**_good_fields(**changes))
    with pytest.raises(ImageDecodeError) as info:
        image_to_gray(msg)
    assert problem in str(info.value)
    assert isinstance(info.value, ValueError) and isinstance(info.value, DomplaneError)


def test_missing_field_raises_decode_error():
    fields = _good_fields()
    del fields['step']
    with pytest.raises(ImageDecodeError, match="no 'step' field"):
        image_to_gray(SimpleNamespace(**fields))


def test_list_data_is_accepted():
    fields = _good_fields()
    msg = SimpleNamespace(**{**fields, 'data': list(fields['data'])})
    np.testing.assert_array_equal(image_to_gray(msg), image_to_gray(SimpleNamespace(**fields)))


# Compressed images.

def _gray_pattern() -> np.ndarray:
    y, x = np.mgrid[0:24, 0:32]
    return ((x * 8 + y * 3) % 256).astype(np.uint8)


@pytest.mark.parametrize('fmt,extension', [
    ('png', '.png'), ('mono8; png compressed mono8', '.png'), ('jpeg', '.jpg'),
    ('bgr8; jpeg compressed bgr8', '.jpg'), ('JPG', '.jpg'),
])
def test_compressed_image_decodes(fmt, extension):
    gray = _gray_pattern()
    ok, encoded = cv2.imencode(extension, cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    assert ok
    for data in (encoded.tobytes(), array('B', encoded.tobytes()), encoded.reshape(-1)):
        msg = SimpleNamespace(format=fmt, data=data)
        decoded = compressed_to_gray(msg)
        assert decoded.shape == gray.shape and decoded.dtype == np.uint8
        np.testing.assert_array_equal(message_to_gray(msg), decoded)
        if extension == '.png':
            np.testing.assert_array_equal(decoded, gray)
        else:
            assert np.abs(decoded.astype(int) - gray).mean() < 4.0


def test_compressed_16_bit_png_becomes_8_bit():
    gray16 = _gray_pattern().astype(np.uint16) * 257
    ok, encoded = cv2.imencode('.png', gray16)
    assert ok
    decoded = compressed_to_gray(SimpleNamespace(format='png', data=encoded.tobytes()))
    assert decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded, _gray_pattern())


def test_compressed_rclpy_message_decodes():
    sensor_msgs = pytest.importorskip('sensor_msgs.msg')
    ok, encoded = cv2.imencode('.png', _gray_pattern())
    msg = sensor_msgs.CompressedImage(format='png', data=encoded.tobytes())
    np.testing.assert_array_equal(message_to_gray(msg), _gray_pattern())


@pytest.mark.parametrize('fmt,data,problem', [
    ('png', b'', 'compressed image data is empty'),
    ('jpeg', b'definitely not a jpeg', 'could not decode 21 bytes'),
    ('tiff', b'\x00', "unsupported compressed format 'tiff'"),
    ('16UC1; compressedDepth png', b'\x00', 'compressedDepth'),
    (None, b'\x00', "'format' must be a string"),
    ('png', 3.5, 'image data must be bytes'),
])
def test_bad_compressed_image_raises_decode_error(fmt, data, problem):
    with pytest.raises(ImageDecodeError) as info:
        compressed_to_gray(SimpleNamespace(format=fmt, data=data))
    assert problem in str(info.value)


# Building outgoing messages.

@pytest.mark.parametrize('encoding,dtype', [
    ('mono8', np.uint8), ('8UC1', np.uint8), ('mono16', np.uint16)])
def test_gray_fields_round_trip(encoding, dtype):
    native = np.random.default_rng(3).integers(0, np.iinfo(dtype).max, (4, 6), dtype=dtype)
    fields = gray_to_image_fields(native, encoding)
    assert fields['height'] == 4 and fields['width'] == 6 and fields['encoding'] == encoding
    assert fields['step'] == 6 * np.dtype(dtype).itemsize and fields['is_bigendian'] == 0
    assert isinstance(fields['data'], bytes)
    for make in (lambda f: SimpleNamespace(**f), _rclpy_image, _rosbags_image):
        np.testing.assert_array_equal(image_to_array(make(fields))[0], native)


def test_gray_fields_fill_rclpy_message_via_constructor():
    sensor_msgs = pytest.importorskip('sensor_msgs.msg')
    mask = (np.arange(12).reshape(3, 4) % 2 * 255).astype(np.uint8)
    msg = sensor_msgs.Image(**gray_to_image_fields(mask))
    np.testing.assert_array_equal(image_to_gray(msg), mask)


def test_big_endian_array_is_written_little_endian():
    native = np.array([[1, 258]], dtype='>u2')
    fields = gray_to_image_fields(native, 'mono16')
    assert fields['data'] == b'\x01\x00\x02\x01'


def test_float_fields_are_little_endian_32fc1():
    native = np.array([[-1.0, 0.25], [3.5, 1e6]], dtype='>f4')  # big-endian input
    fields = gray_to_image_fields(native, '32FC1')
    assert (fields['encoding'], fields['step'], fields['is_bigendian']) == ('32FC1', 8, 0)
    np.testing.assert_array_equal(np.frombuffer(fields['data'], '<f4').reshape(2, 2), native)


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8'])
def test_rgb_fields_round_trip(encoding):
    native = np.random.default_rng(4).integers(0, 256, (3, 5, 3), dtype=np.uint8)
    fields = rgb_to_image_fields(native[:, ::-1], encoding)  # Non-contiguous input.
    assert fields['step'] == 15 and fields['encoding'] == encoding
    for make in (lambda f: SimpleNamespace(**f), _rclpy_image, _rosbags_image):
        np.testing.assert_array_equal(image_to_array(make(fields))[0], native[:, ::-1])


@pytest.mark.parametrize('builder,array_in,encoding,problem', [
    (gray_to_image_fields, np.zeros((2, 2), np.uint8), 'rgb8', 'encoding must be one of'),
    (gray_to_image_fields, np.zeros((2, 2, 1), np.uint8), 'mono8', 'shape (H, W)'),
    (gray_to_image_fields, np.zeros((0, 2), np.uint8), 'mono8', 'shape (H, W)'),
    (gray_to_image_fields, np.zeros((2, 2), np.float32), 'mono8', 'dtype uint8'),
    (gray_to_image_fields, np.zeros((2, 2), np.uint8), 'mono16', 'dtype uint16'),
    (gray_to_image_fields, np.zeros((2, 2), np.float64), '32FC1', 'dtype float32'),
    (gray_to_image_fields, np.array([[0.0, np.nan]], np.float32), '32FC1', 'non-finite'),
    (rgb_to_image_fields, np.zeros((2, 2, 3), np.uint8), 'mono8', 'rgb8 or bgr8'),
    (rgb_to_image_fields, np.zeros((2, 2, 4), np.uint8), 'rgb8', 'shape (H, W, 3)'),
    (rgb_to_image_fields, np.zeros((2, 2, 3), np.uint16), 'rgb8', 'dtype uint8'),
])
def test_builders_reject_bad_arrays(builder, array_in, encoding, problem):
    with pytest.raises(ValueError) as info:
        builder(array_in, encoding)
    assert problem in str(info.value)


# Property: arbitrary field values only ever raise ImageDecodeError.

_integers = st.one_of(
    st.integers(min_value=-2, max_value=40), st.integers(), st.floats(allow_nan=True),
    st.none(), st.booleans(), st.text(max_size=3))


@settings(max_examples=400, deadline=None)
@given(
    encoding=st.one_of(st.sampled_from(SUPPORTED_ENCODINGS), st.text(max_size=8), st.none(),
                       st.integers()),
    height=_integers, width=_integers, step=_integers,
    is_bigendian=st.one_of(st.integers(min_value=0, max_value=2), st.booleans(), st.floats()),
    data=st.one_of(
        st.binary(max_size=300),
        st.binary(max_size=300).map(lambda b: array('B', b)),
        st.binary(max_size=300).map(lambda b: np.frombuffer(b, dtype=np.uint8)),
        st.lists(st.integers(min_value=-1, max_value=256), max_size=50),
        st.none(), st.integers(), st.text(max_size=5)),
)
def test_arbitrary_fields_decode_or_raise_decode_error(
        encoding, height, width, step, is_bigendian, data):
    msg = SimpleNamespace(
        encoding=encoding, height=height, width=width, step=step, is_bigendian=is_bigendian,
        data=data)
    try:
        gray = image_to_gray(msg)
    except ImageDecodeError:
        return
    assert gray.dtype == np.uint8
    assert gray.shape == (height, width)


@settings(max_examples=200, deadline=None)
@given(
    encoding=st.sampled_from(SUPPORTED_ENCODINGS),
    height=st.integers(min_value=1, max_value=6), width=st.integers(min_value=1, max_value=6),
    padding=st.integers(min_value=-3, max_value=5), extra=st.integers(min_value=-3, max_value=3),
    bigendian=st.booleans(), seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_consistent_sizes_decode_and_inconsistent_sizes_raise(
        encoding, height, width, padding, extra, bigendian, seed):
    channels, depth = LAYOUTS[encoding]
    step = width * channels * depth + padding
    size = max(0, height * step + extra)
    data = np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8).tobytes()
    msg = SimpleNamespace(
        encoding=encoding, height=height, width=width, step=step, is_bigendian=int(bigendian),
        data=data)
    if padding < 0 or extra != 0:
        with pytest.raises(ImageDecodeError):
            image_to_gray(msg)
    else:
        gray = image_to_gray(msg)
        assert gray.shape == (height, width) and gray.dtype == np.uint8
