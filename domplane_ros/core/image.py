"""Duck-typed conversion between sensor_msgs images and numpy arrays.

The decoders read only the fields ``encoding``, ``height``, ``width``, ``step``, ``is_bigendian``
and ``data`` of a ``sensor_msgs/Image`` (and ``format`` and ``data`` of a
``sensor_msgs/CompressedImage``), so they accept rclpy messages, whose ``data`` is an
``array.array('B')``, rosbags messages, whose ``data`` is a ``uint8`` numpy array, and any other
object with those attributes. Row padding (``step`` larger than ``width * bytes_per_pixel``) and
big-endian 16-bit data are honoured.

The encoders return plain dicts of message fields, so this module depends on no message class:
the ROS adapter fills a message from the dict.

This module is part of the core and imports no ROS package.
"""

from __future__ import annotations

from array import array as py_array
from typing import Any, NamedTuple

import cv2
from domplane_ros.errors import ImageDecodeError, wire_repr
import numpy as np


class _EncodingLayout(NamedTuple):
    """Memory layout of a raw image encoding."""

    channels: int
    bytes_per_channel: int
    gray_conversion: int | None  # cv2.cvtColor code to gray; None for one channel.


_LAYOUTS: dict[str, _EncodingLayout] = {
    'mono8': _EncodingLayout(1, 1, None),
    '8UC1': _EncodingLayout(1, 1, None),
    'mono16': _EncodingLayout(1, 2, None),
    'rgb8': _EncodingLayout(3, 1, cv2.COLOR_RGB2GRAY),
    'bgr8': _EncodingLayout(3, 1, cv2.COLOR_BGR2GRAY),
    '8UC3': _EncodingLayout(3, 1, cv2.COLOR_BGR2GRAY),  # OpenCV's channel order: BGR.
    'rgba8': _EncodingLayout(4, 1, cv2.COLOR_RGBA2GRAY),
    'bgra8': _EncodingLayout(4, 1, cv2.COLOR_BGRA2GRAY),
}

SUPPORTED_ENCODINGS: tuple[str, ...] = tuple(_LAYOUTS)
"""Raw ``sensor_msgs/Image`` encodings that :func:`image_to_gray` decodes."""

SUPPORTED_COMPRESSED_FORMATS: tuple[str, ...] = ('jpeg', 'png')
"""Compression names that :func:`compressed_to_gray` accepts in ``CompressedImage.format``."""


def _integer_field(msg: Any, name: str, allow_bool: bool = False) -> int:
    """Read a message field that must hold a non-negative integer.

    Args:
        msg: The message.
        name: The field name.
        allow_bool: Whether a ``bool`` value is accepted (for ``is_bigendian``).

    Returns:
        The field value as a Python int.

    Raises:
        ImageDecodeError: If the field is missing, not an integer, or negative.

    """
    try:
        value = getattr(msg, name)
    except AttributeError as err:
        raise ImageDecodeError(f'image message has no {name!r} field') from err
    if isinstance(value, (bool, np.bool_)) and allow_bool:
        return int(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ImageDecodeError(
            f'image field {name!r} must be an integer, got {wire_repr(value)} '
            f'of type {type(value).__name__}')
    value = int(value)
    if value < 0:
        raise ImageDecodeError(f'image field {name!r} must be non-negative, got {value}')
    return value


def _message_data(msg: Any, what: str) -> np.ndarray:
    """Return the ``data`` field of a message as a flat ``uint8`` array (see _data_bytes).

    Raises:
        ImageDecodeError: If the message has no ``data`` field, or it is not a byte buffer.

    """
    try:
        data = msg.data
    except AttributeError as err:
        raise ImageDecodeError(f"{what} message has no 'data' field") from err
    return _data_bytes(data)


def _data_bytes(data: Any) -> np.ndarray:
    """View message data as a flat ``uint8`` array.

    Args:
        data: ``bytes``, ``bytearray``, ``memoryview``, ``array.array('B')``, a ``uint8`` numpy
            array, or a sequence of ints in [0, 255].

    Returns:
        ``(N,) uint8`` array. It may share memory with ``data``; callers copy before returning.

    Raises:
        ImageDecodeError: If ``data`` is not a byte buffer.

    """
    if isinstance(data, np.ndarray):
        if data.dtype != np.uint8:
            raise ImageDecodeError(f'image data must have dtype uint8, got {data.dtype}',
                                   kind='data')
        return np.ascontiguousarray(data).reshape(-1)
    if isinstance(data, (list, tuple)):
        try:
            return np.frombuffer(bytes(data), dtype=np.uint8)
        except (TypeError, ValueError) as err:
            raise ImageDecodeError(
                f'image data must be a sequence of ints in [0, 255]: {err}', kind='data') from err
    if not isinstance(data, (bytes, bytearray, memoryview, py_array)):
        raise ImageDecodeError(
            f'image data must be bytes, array.array or a uint8 numpy array, '
            f'got {type(data).__name__}', kind='data')
    view = memoryview(data)
    if view.itemsize != 1:
        raise ImageDecodeError(
            f'image data must be bytes, got items of {view.itemsize} bytes '
            f'(format {view.format!r})', kind='data')
    return np.frombuffer(view.cast('B') if view.ndim != 1 else view, dtype=np.uint8)


def _encoding_layout(encoding: Any) -> _EncodingLayout:
    """Look up the layout of a raw encoding.

    Args:
        encoding: The message's ``encoding`` field.

    Returns:
        The encoding's layout.

    Raises:
        ImageDecodeError: If the encoding is not a string or not supported.

    """
    if not isinstance(encoding, str):
        raise ImageDecodeError(
            f"image field 'encoding' must be a string, got {type(encoding).__name__}")
    try:
        return _LAYOUTS[encoding]
    except KeyError:
        raise ImageDecodeError(
            f'unsupported encoding {wire_repr(encoding)}; supported encodings are '
            f'{", ".join(SUPPORTED_ENCODINGS)}', kind='encoding') from None


def image_to_array(msg: Any, copy: bool = True) -> tuple[np.ndarray, str]:
    """Decode a raw ``sensor_msgs/Image`` into its native numpy array.

    Args:
        msg: An object with the fields ``encoding``, ``height``, ``width``, ``step``,
            ``is_bigendian`` and ``data`` of ``sensor_msgs/Image``.
        copy: False: an 8-bit image without row padding is returned as a read-only view
            of the message's data (no copy of a 8 MB 4K frame); the message must then not
            change while the array is used.

    Returns:
        A tuple ``(array, encoding)``. ``array`` is a new C-contiguous array that shares no
        memory with the message (with ``copy`` False it may be a read-only view of it):
        ``(H, W) uint8`` for mono8 and 8UC1, ``(H, W) uint16`` in
        native byte order for mono16, and ``(H, W, C) uint8`` in the encoding's channel order
        for rgb8, bgr8, 8UC3 (C = 3), rgba8 and bgra8 (C = 4). ``encoding`` is the message's
        encoding.

    Raises:
        ImageDecodeError: If the encoding is unsupported, a field is missing or not an integer,
            the width or height is zero, ``step`` is smaller than ``width * bytes_per_pixel``,
            or the data length is not ``height * step``.

    """
    layout = _encoding_layout(getattr(msg, 'encoding', None))
    height = _integer_field(msg, 'height')
    width = _integer_field(msg, 'width')
    step = _integer_field(msg, 'step')
    is_bigendian = _integer_field(msg, 'is_bigendian', allow_bool=True)
    if height == 0 or width == 0:
        raise ImageDecodeError(f'image has zero width or height ({width}x{height})',
                               kind='zero_size')
    bytes_per_pixel = layout.channels * layout.bytes_per_channel
    if step < width * bytes_per_pixel:
        raise ImageDecodeError(
            f'step {step} is smaller than width * bytes_per_pixel = {width} * '
            f'{bytes_per_pixel} = {width * bytes_per_pixel}', kind='step')
    data = _message_data(msg, 'image')
    if data.size != height * step:
        raise ImageDecodeError(
            f'data length {data.size} != height * step = {height} * {step} = {height * step}',
            kind='data_length')

    if layout.bytes_per_channel == 2:
        dtype = np.dtype('>u2' if is_bigendian else '<u2')
        shape: tuple[int, ...] = (height, width)
        strides: tuple[int, ...] = (step, 2)
    else:
        dtype = np.dtype(np.uint8)
        if layout.channels == 1:
            shape, strides = (height, width), (step, 1)
        else:
            shape = (height, width, layout.channels)
            strides = (step, layout.channels, 1)
    # A strided view skips the row padding; astype copies into native byte order.
    view = np.ndarray(shape=shape, dtype=dtype, buffer=data, strides=strides)
    if not copy and layout.bytes_per_channel == 1 and view.flags.c_contiguous:
        view.flags.writeable = False
        return view, msg.encoding
    return view.astype(dtype.newbyteorder('='), order='C', copy=True), msg.encoding


MONO16_NARROW_FRACTION = 16
"""mono16 pairs whose brightest value is under 1/this of the ``image.mono16_bits`` range are
reported by :func:`mono16_range_warning`."""


def mono16_to_gray(array: np.ndarray, bits: int = 16) -> np.ndarray:
    """Scale a mono16 image with ``bits`` significant bits to 8 bits.

    Keeps the top 8 of the ``bits`` low bits (``value >> (bits - 8)``); values above
    ``2**bits - 1`` saturate at 255. ``bits`` 16 keeps the high byte, as cv_bridge does.

    Args:
        array: ``(H, W) uint16``.
        bits: Significant bits of the sensor, 8 to 16 (``image.mono16_bits``).

    Returns:
        ``(H, W) uint8`` C-contiguous array.

    Raises:
        ValueError: If ``bits`` is not an integer in 8..16.

    """
    if isinstance(bits, bool) or not isinstance(bits, (int, np.integer)) or not 8 <= bits <= 16:
        raise ValueError(f'mono16 bits must be an integer in 8..16, got {bits!r}')
    shifted = array >> (int(bits) - 8)
    if bits < 16:
        cv2.min(shifted, 255, dst=shifted)   # in place; a third of np.minimum's time at 4K
    return shifted.astype(np.uint8)


def mono16_range_warning(grays: Any, bits: int) -> str:
    """Say when mono16 images use far fewer bits than ``image.mono16_bits`` sets.

    Args:
        grays: The decoded ``(H, W) uint8`` images of a pair's mono16 messages
            (:func:`mono16_to_gray` with ``bits``).
        bits: The ``image.mono16_bits`` they were decoded with.

    Returns:
        One line naming ``image.mono16_bits`` and the bits the data seems to use when the
        brightest grey of every image is under 256 / :data:`MONO16_NARROW_FRACTION` (16 grey
        levels or fewer: 12-bit data read as 16 bits), else ''.

    """
    peak = max((int(gray.max()) for gray in grays), default=255)
    if peak >= 256 // MONO16_NARROW_FRACTION:
        return ''
    used = max(8, bits - 8 + peak.bit_length())
    return (f'mono16 images use under 1/{MONO16_NARROW_FRACTION} of the {bits}-bit range of '
            f'image.mono16_bits (brightest grey {peak} of 255 after decoding): set '
            f"image.mono16_bits to the sensor's significant bits ({used} fit the data)")


def image_to_gray(msg: Any, copy: bool = True, mono16_bits: int = 16) -> np.ndarray:
    """Decode a raw ``sensor_msgs/Image`` to an 8-bit gray image.

    Colour encodings are converted with OpenCV's ITU-R BT.601 luma weights. mono16 is scaled
    to 8 bits by :func:`mono16_to_gray` with ``mono16_bits`` (16: the high byte,
    ``value >> 8``, as cv_bridge does).

    Args:
        msg: An object with the fields ``encoding``, ``height``, ``width``, ``step``,
            ``is_bigendian`` and ``data`` of ``sensor_msgs/Image``. Supported encodings are
            listed in :data:`SUPPORTED_ENCODINGS`.
        copy: False: mono8 and 8UC1 without row padding come back as a read-only view of
            the message's data, and colour is converted from the data in place (see
            :func:`image_to_array`).
        mono16_bits: Significant bits of mono16 data (``image.mono16_bits``), 8 to 16;
            other encodings ignore it.

    Returns:
        ``(H, W) uint8`` C-contiguous array that shares no memory with the message (with
        ``copy`` False, a read-only view of it for mono8 and 8UC1).

    Raises:
        ImageDecodeError: As :func:`image_to_array`.

    """
    array, encoding = image_to_array(msg, copy)
    layout = _LAYOUTS[encoding]
    if layout.bytes_per_channel == 2:
        return mono16_to_gray(array, mono16_bits)
    if layout.gray_conversion is None:
        return array
    return cv2.cvtColor(array, layout.gray_conversion)


def compressed_to_gray(msg: Any) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` (JPEG or PNG) to an 8-bit gray image.

    Args:
        msg: An object with the fields ``format`` and ``data`` of
            ``sensor_msgs/CompressedImage``. ``format`` must name jpeg (or jpg) or png, as in
            ``'jpeg'`` or ``'bgr8; jpeg compressed bgr8'``; compressedDepth is not supported.

    Returns:
        ``(H, W) uint8`` C-contiguous array.

    Raises:
        ImageDecodeError: If the format is not a string, names no supported compression or
            names compressedDepth, the data is empty or not bytes, or OpenCV cannot decode it.

    """
    fmt = getattr(msg, 'format', None)
    if not isinstance(fmt, str):
        raise ImageDecodeError(
            f"compressed image field 'format' must be a string, got {type(fmt).__name__}")
    lowered = fmt.lower()
    if 'compresseddepth' in lowered:
        raise ImageDecodeError(f'unsupported compressed format {wire_repr(fmt)}: compressedDepth',
                               kind='encoding')
    if not any(name in lowered for name in ('jpeg', 'jpg', 'png')):
        raise ImageDecodeError(
            f'unsupported compressed format {wire_repr(fmt)}; supported compressions are '
            f'{", ".join(SUPPORTED_COMPRESSED_FORMATS)}', kind='encoding')
    data = _message_data(msg, 'compressed image')
    if data.size == 0:
        raise ImageDecodeError(f'compressed image data is empty (format {wire_repr(fmt)})',
                               kind='compressed')
    gray = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    if gray is None or gray.size == 0:
        raise ImageDecodeError(
            f'OpenCV could not decode {data.size} bytes of compressed image data '
            f'(format {wire_repr(fmt)})', kind='compressed')
    if gray.dtype != np.uint8:  # IMREAD_GRAYSCALE gives 8 bits; keep the contract anyway.
        gray = (gray.astype(np.uint16) >> 8).astype(np.uint8)
    return np.ascontiguousarray(gray)


def message_to_gray(msg: Any, copy: bool = True, mono16_bits: int = 16) -> np.ndarray:
    """Decode a raw or compressed image message to an 8-bit gray image.

    Args:
        msg: A ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` like object; objects
            with a ``format`` attribute are treated as compressed.
        copy: False: a raw mono8 image may come back as a read-only view of the message's
            data (:func:`image_to_gray`).
        mono16_bits: Significant bits of raw mono16 data (``image.mono16_bits``).

    Returns:
        ``(H, W) uint8`` C-contiguous array.

    Raises:
        ImageDecodeError: As :func:`image_to_gray` or :func:`compressed_to_gray`.

    """
    if hasattr(msg, 'format'):
        return compressed_to_gray(msg)
    return image_to_gray(msg, copy, mono16_bits)


def is_mono16(msg: Any) -> bool:
    """Return whether ``msg`` is a raw image message with encoding mono16."""
    return getattr(msg, 'encoding', None) == 'mono16'


def gray_to_image_fields(array: np.ndarray, encoding: str = 'mono8') -> dict[str, Any]:
    """Build the fields of a ``sensor_msgs/Image`` from a one-channel image.

    Args:
        array: ``(H, W) uint8`` for mono8 or 8UC1, ``(H, W) uint16`` for mono16, ``(H, W)
            float32`` for 32FC1 (finite). H and W must be positive.
        encoding: ``'mono8'``, ``'8UC1'``, ``'mono16'`` or ``'32FC1'``.

    Returns:
        A dict with the keys ``height``, ``width``, ``encoding``, ``is_bigendian``, ``step``
        and ``data`` (``bytes``, unpadded rows; mono16 and 32FC1 are written little-endian with
        ``is_bigendian = 0``).

    Raises:
        ValueError: If the encoding is not one of the above, the array's shape or dtype does
            not fit it, or a 32FC1 image holds a non-finite value.

    """
    dtypes = {'mono8': np.uint8, '8UC1': np.uint8, 'mono16': np.uint16, '32FC1': np.float32}
    if encoding not in dtypes:
        raise ValueError(
            f'encoding must be one of {", ".join(dtypes)} for a gray image, got {encoding!r}')
    array = np.asarray(array)
    if array.ndim != 2 or 0 in array.shape:
        raise ValueError(f'gray image must have shape (H, W) with H, W > 0, got {array.shape}')
    if array.dtype.newbyteorder('=') != np.dtype(dtypes[encoding]):
        raise ValueError(
            f'{encoding} image must have dtype {np.dtype(dtypes[encoding])}, got {array.dtype}')
    if encoding == '32FC1' and not np.all(np.isfinite(array)):
        raise ValueError('32FC1 image holds non-finite values')
    height, width = array.shape
    little_endian = array.astype(array.dtype.newbyteorder('<'), copy=False)
    return {
        'height': int(height),
        'width': int(width),
        'encoding': encoding,
        'is_bigendian': 0,
        'step': int(width * array.dtype.itemsize),
        'data': np.ascontiguousarray(little_endian).tobytes(),
    }


def rgb_to_image_fields(array: np.ndarray, encoding: str = 'rgb8') -> dict[str, Any]:
    """Build the fields of a ``sensor_msgs/Image`` from a three-channel 8-bit image.

    Args:
        array: ``(H, W, 3) uint8`` with H, W > 0, channels in the order that ``encoding``
            names.
        encoding: ``'rgb8'`` or ``'bgr8'``.

    Returns:
        A dict with the keys ``height``, ``width``, ``encoding``, ``is_bigendian``, ``step``
        and ``data`` (``bytes``, unpadded rows).

    Raises:
        ValueError: If the encoding is not rgb8 or bgr8, or the array is not
            ``(H, W, 3) uint8``.

    """
    if encoding not in ('rgb8', 'bgr8'):
        raise ValueError(f'encoding must be rgb8 or bgr8 for a colour image, got {encoding!r}')
    array = np.asarray(array)
    if array.ndim != 3 or array.shape[2] != 3 or 0 in array.shape:
        raise ValueError(
            f'colour image must have shape (H, W, 3) with H, W > 0, got {array.shape}')
    if array.dtype != np.uint8:
        raise ValueError(f'colour image must have dtype uint8, got {array.dtype}')
    height, width, _ = array.shape
    return {
        'height': int(height),
        'width': int(width),
        'encoding': encoding,
        'is_bigendian': 0,
        'step': int(width * 3),
        'data': np.ascontiguousarray(array).tobytes(),
    }


def check_gray(image: Any, name: str = 'gray') -> np.ndarray:
    """Check that ``image`` is a non-empty ``(H, W) uint8`` numpy array and return it.

    Args:
        image: The array to check.
        name: Its name in the error message.

    Returns:
        ``image`` itself.

    Raises:
        ValueError: If it is not a numpy array, not 2-D, not uint8, or empty; the message
            names the array and the problem.

    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f'{name} must be a numpy array, got {type(image).__name__}')
    if image.ndim != 2:
        raise ValueError(f'{name} must be a 2-D (H, W) image, got shape {image.shape}')
    if image.dtype != np.uint8:
        raise ValueError(f'{name} must have dtype uint8, got {image.dtype}')
    if min(image.shape) < 1:
        raise ValueError(f'{name} is empty, shape {image.shape}')
    return image
