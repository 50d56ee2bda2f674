"""rclpy message building and parameter descriptors for plane_node (an adapter: ROS only)."""

from __future__ import annotations

from typing import Any, Iterable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from domplane_ros.config import ParamSpec
from domplane_ros.core.image import gray_to_image_fields, rgb_to_image_fields
from domplane_ros.stream.status import result_status, RESULT_STATUS_NAME
import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import ParameterType
from sensor_msgs.msg import Image
from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension

_TYPES = {
    'bool': ParameterType.PARAMETER_BOOL,
    'int': ParameterType.PARAMETER_INTEGER,
    'float': ParameterType.PARAMETER_DOUBLE,
    'str': ParameterType.PARAMETER_STRING,
    'range': ParameterType.PARAMETER_DOUBLE_ARRAY,
    'floats': ParameterType.PARAMETER_DOUBLE_ARRAY,
}

# Parameters that only take effect when the node starts.
READ_ONLY = frozenset({'qos.reliable', 'qos.depth', 'diagnostics.period_s',
                       'head.joint_states_topic', 'image_transport', 'camera_info.topic'})


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """Build the ROS ParameterDescriptor of a spec: description, type, range."""
    # Dynamic typing lets the node's own validator (config.check_value) judge every value, so
    # a refused value gets a reason that names the parameter, and an integer (or a list of
    # integers, as for initial_homography) is accepted for a float as the replay's YAML
    # reader accepts it. A parameter whose default is an empty list is declared unset
    # (the node reads that as its default).
    desc = ParameterDescriptor(name=spec.name, type=_TYPES[spec.kind],
                               description=spec.description,
                               read_only=spec.name in READ_ONLY, dynamic_typing=True)
    constraints = []
    if spec.kind == 'float' and spec.low is not None and spec.high is not None:
        desc.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    elif spec.kind == 'int' and spec.low is not None and spec.high is not None:
        desc.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                           step=1)]
    elif spec.kind == 'range':
        constraints.append(f'[min, max] with {spec.low} <= min <= max <= {spec.high}')
    elif spec.kind == 'floats' and spec.lengths:
        constraints.append('length ' + ' or '.join(str(n) for n in spec.lengths))
    if spec.choices:
        constraints.append('one of ' + ', '.join(spec.choices))
    desc.additional_constraints = '; '.join(constraints)
    return desc


def homography_msg(matrix: np.ndarray) -> Float64MultiArray:
    """Build the 3x3 row-major Float64MultiArray (dims rows=3, cols=3), ``H[2][2] == 1``."""
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label='rows', size=3, stride=9),
                      MultiArrayDimension(label='cols', size=3, stride=3)]
    msg.layout.data_offset = 0
    msg.data = [float(v) for v in np.asarray(matrix, dtype=np.float64).ravel()]
    return msg


def result_msg(header: Header, hardware_id: str, frame: Any) -> DiagnosticArray:
    """Build the stamped per-pair result: a DiagnosticArray with one status named ``plane``.

    The array's header is the left image's (stamp and frame id), so the result matches the
    mask of the same pair; the status is :func:`~domplane_ros.stream.status.result_status`.

    Args:
        header: The left image's header.
        hardware_id: The node's fully qualified name.
        frame: The processed pair (a ``ProcessedPair``).

    Returns:
        The message.

    """
    level, message, values = result_status(frame)
    status = DiagnosticStatus(level=bytes([level]), name=RESULT_STATUS_NAME,
                              hardware_id=hardware_id, message=message)
    status.values = [KeyValue(key=k, value=v) for k, v in values]
    array = DiagnosticArray()
    array.header = header
    array.status = [status]
    return array


def stamped_header(stamp_ns: int, frame_id: str) -> Header:
    """Return a std_msgs/Header with a stamp given in nanoseconds and a frame id."""
    header = Header()
    header.stamp.sec, header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    header.frame_id = frame_id
    return header


def image_msg(array: np.ndarray, header: Header, encoding: str) -> Image:
    """Return a sensor_msgs/Image of a mono8 (2-D) or rgb8 (3-D) uint8 array."""
    if encoding == 'mono8':
        fields = gray_to_image_fields(array, encoding)
    else:
        fields = rgb_to_image_fields(array, encoding)
    msg = Image()
    msg.header = header
    msg.height = fields['height']
    msg.width = fields['width']
    msg.encoding = fields['encoding']
    msg.is_bigendian = int(fields['is_bigendian'])
    msg.step = fields['step']
    msg.data = bytes(fields['data'])
    return msg


def parallax_msg(parallax: np.ndarray, header: Header) -> Image:
    """Return a 32FC1 sensor_msgs/Image (little-endian) of a finite (H, W) parallax image.

    Raises:
        ValueError: If the array is not 2-D and non-empty, or holds a non-finite value.

    """
    array = np.asarray(parallax, dtype='<f4')
    if array.ndim != 2 or 0 in array.shape:
        raise ValueError(f'parallax image must have shape (H, W) with H, W > 0, got '
                         f'{array.shape}')
    if not np.all(np.isfinite(array)):
        raise ValueError('parallax image holds non-finite values')
    msg = Image()
    msg.header = header
    msg.height, msg.width = array.shape
    msg.encoding = '32FC1'
    msg.is_bigendian = 0
    msg.step = 4 * array.shape[1]
    msg.data = np.ascontiguousarray(array).tobytes()
    return msg


def diagnostics_msg(stamp: Any, name: str, hardware_id: str, level: int, message: str,
                    values: Iterable[tuple[str, Any]]) -> DiagnosticArray:
    """Return a DiagnosticArray with one status.

    Args:
        stamp: builtin_interfaces/Time of the array.
        name: Status name.
        hardware_id: Hardware id (the camera pair).
        level: ``DiagnosticStatus.OK``, ``WARN`` or ``ERROR`` (an int).
        message: One-line summary.
        values: Key/value pairs; values are formatted with ``str``.

    Returns:
        The message.

    """
    status = DiagnosticStatus(level=bytes([level]), name=name, message=message,
                              hardware_id=hardware_id)
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values]
    array = DiagnosticArray()
    array.header.stamp = stamp
    array.status = [status]
    return array
