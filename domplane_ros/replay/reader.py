"""Reading stereo image messages from a rosbag2 bag, and pairing them as plane_node does.

:class:`BagInput` opens a bag (sqlite3 or MCAP storage, ``sensor_msgs/Image`` or
``sensor_msgs/CompressedImage``) with the pure-Python ``rosbags`` library and yields the left
and right messages in bag order; :class:`ReplaySession` is the
:class:`~domplane_ros.stream.session.StreamSession` of a bag, whose clock is the header stamps.
:func:`pair_messages` and :func:`replay_frames` are the same steps as generators. Messages are
rosbags' own types (its typestore); nothing here imports rclpy.
"""

from __future__ import annotations

from dataclasses import replace
import os
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, NamedTuple

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.image import message_to_gray
from domplane_ros.errors import BagError, clip_text, ConfigError, ImageDecodeError
from domplane_ros.ros.camera_info import camera_model, CameraInfoTracker
from domplane_ros.stream.pipeline import FrameResult, PlanePipeline
from domplane_ros.stream.session import DEFAULT_TOPICS, ProcessedPair, StreamSession
from domplane_ros.stream.sync import ApproximateTimeSync, Pair, Side
import numpy as np
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores

IMAGE_TYPE = 'sensor_msgs/msg/Image'
COMPRESSED_IMAGE_TYPE = 'sensor_msgs/msg/CompressedImage'
IMAGE_TYPES = (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE)
CAMERA_INFO_TYPE = 'sensor_msgs/msg/CameraInfo'
# BagMessage.side of the camera_info.topic's messages.
CAMERA_INFO = 'camera_info'
JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
# BagMessage.side of the head.joint_states_topic's messages.
JOINT_STATES = 'joint_states'

# One processed pair of a replay (the session's processed pair; the name the tools use).
ReplayedFrame = ProcessedPair


class BagReadError(BagError):
    """Reading a bag failed part-way (a truncated or corrupt file).

    Attributes:
        kept: Where the output up to the failure was kept (``--keep-partial``), or ''.

    """

    kept = ''


def typestore() -> Any:
    """Return the rosbags typestore of ROS 2 Jazzy (the message types of every bag here)."""
    return get_typestore(Stores.ROS2_JAZZY)


def header_stamp_ns(msg: Any) -> int:
    """Return a message's header stamp in nanoseconds.

    Args:
        msg: Any message with ``header.stamp.sec`` and ``header.stamp.nanosec`` (rosbags or
            rclpy).

    Returns:
        The stamp as an int.

    """
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def process_pair(pipeline: PlanePipeline, pair: Pair) -> tuple[np.ndarray, FrameResult]:
    """Decode a pair and run the pipeline on it, exactly as plane_node does.

    The stamp given to the pipeline is the left image's, and ``pair.after_reset`` drops the
    warm start.

    Args:
        pair: A pair from :class:`~domplane_ros.stream.sync.ApproximateTimeSync` whose items are
            image messages (``sensor_msgs/Image`` or ``CompressedImage``, rosbags or rclpy).

    Returns:
        ``(left, result)``: the (H, W) uint8 left image and the frame result.

    Raises:
        ImageDecodeError: If either image cannot be decoded; the pipeline is not called.

    """
    left = message_to_gray(pair.left)
    right = message_to_gray(pair.right)
    return left, pipeline.process(left, right, pair.left_stamp_ns, reset=pair.after_reset)


def pair_messages(messages: Iterable[tuple[Side, Any]],
                  sync: ApproximateTimeSync) -> Iterator[Pair]:
    """Pair image messages by their header stamps, in the order given.

    Args:
        messages: ``(side, message)`` tuples in bag (arrival) order; side is ``'left'`` or
            ``'right'``.
        sync: The synchroniser (its counters record the drops).

    Yields:
        The pairs, as the live node's synchroniser would emit them.

    """
    for side, msg in messages:
        yield from sync.add(side, header_stamp_ns(msg), msg)


def replay_frames(pairs: Iterable[Pair], pipeline: PlanePipeline,
                  decode_errors: list[str] | None = None) -> Iterator[FrameResult]:
    """Run the pipeline over stereo pairs, as plane_node does, and yield the results.

    Args:
        pairs: Pairs in emission order (from :func:`pair_messages`).
        pipeline: The pipeline, fresh for a new stream.
        decode_errors: If given, the messages of pairs that could not be decoded are appended
            to it; such pairs are skipped, as the node skips them.

    Yields:
        One :class:`~domplane_ros.stream.pipeline.FrameResult` per decoded pair.

    """
    for pair in pairs:
        try:
            _, result = process_pair(pipeline, pair)
        except ImageDecodeError as err:
            if decode_errors is not None:
                decode_errors.append(str(err))
            continue
        yield result


class ReplaySession(StreamSession):
    """The session of a bag: pairs image messages and runs the pipeline, as plane_node does.

    Feed it every left and right message in bag order with :meth:`add`; it returns the
    processed pairs. Its clock is the messages' header stamps (nanoseconds), so per-camera
    rates and ages in its status are in bag time.

    Args:
        config: The configuration (the node's parameters).
        topics: The left and right topic names, for the per-camera diagnostics.

    """

    def __init__(self, config: PlaneNodeConfig | None = None,
                 topics: tuple[str, str] = DEFAULT_TOPICS) -> None:
        """Make a fresh session whose clock starts at the first message's stamp."""
        super().__init__(config, topics, start=None, tick_s=1e-9)
        self._camera_info = CameraInfoTracker()
        self._received_s: float | None = None   # the newest bag (receive) time read, s

    def add_joint_state(self, msg: Any, received_ns: int) -> str:
        """Take a ``sensor_msgs/JointState`` recorded at bag time ``received_ns``.

        As plane_node takes it on arrival: the fastest joint is the pipeline's hint to expect a
        big change for ``head.max_age_s`` of bag time (:class:`JointSpeeds`).

        Returns:
            A one-line warning for an implausible speed (no hint then), else ''.

        """
        self._received_s = received_ns * 1e-9
        return self.joints.observe(msg.velocity, msg.name, self._received_s)

    def apply_camera_info(self, msg: Any) -> str:
        """Narrow the prior from the left camera's K, as plane_node does (once per distinct K).

        ``prior.focal_px`` becomes f x [1 - t, 1 + t] (t = ``camera_info.focal_tolerance``)
        and ``prior.principal_point_px`` K's (cx, cy); the new prior starts one search.

        Args:
            msg: A ``sensor_msgs/CameraInfo`` (rosbags or rclpy).

        Returns:
            What was done, in one line for the summary ('' for a K applied before).

        """
        try:
            model = camera_model(msg)
        except ValueError as err:
            return f'{err}; ignored, the prior stays as configured'
        tolerance = self.config.transport.camera_info_focal_tolerance
        values = self._camera_info.new_values(model, tolerance)
        if values is None:
            return ''
        try:
            prior = replace(self.config.prior, focal_px=tuple(values['prior.focal_px']),
                            principal_point_px=tuple(values['prior.principal_point_px']))
        except ConfigError as err:
            return f'camera_info not applied to the prior: {err}'
        self.update_config(replace(self.config, prior=prior))
        return self._camera_info.describe(model, values, tolerance)

    def add(self, side: Side, msg: Any, received_ns: int | None = None
            ) -> list[ReplayedFrame]:
        """Add one image message and process the pairs it completes.

        Args:
            side: ``'left'`` or ``'right'``.
            msg: The image message (``header``, and the Image or CompressedImage fields).
            received_ns: Its bag (receive) time: a pair it completes gets the joint speed
                recent at that time, as the live node's pair gets the speed recent when it is
                processed (None: no joint speed).

        Returns:
            The processed pairs (none or one); a pair whose images do not decode is counted in
            ``counters.decode_errors`` and not returned.

        """
        stamp_ns = header_stamp_ns(msg)
        pairs, _ = self.receive(side, stamp_ns, msg, stamp_ns)
        if received_ns is not None:
            self._received_s = received_ns * 1e-9
        speed = self._joint_value(self.joints.speed)
        frames = [self.process(pair, speed) for pair in pairs]
        return [frame for frame in frames if frame is not None]

    def diagnostic_values(self, rate: float, now_ns: int | None = None
                          ) -> tuple[int, str, list[tuple[str, str]]]:
        """Return the node's diagnostics for the state now.

        Args:
            rate: Pairs per second over the last diagnostics period (bag time).
            now_ns: Bag time of the diagnostics, for the per-camera rates and ages (default:
                the newest stamp received).

        Returns:
            ``(level, message, values)``: the DiagnosticStatus level (0 OK, 1 WARN, 2 ERROR),
            its one-line message and the key/value pairs with the node's keys.

        """
        newest = self.activity.newest()
        now = now_ns if now_ns is not None else (newest if newest is not None else 0)
        joints = bool(self.config.head.joint_states_topic)
        return self.status(now, rate=rate, joint_speed=self._joint_value(self.joints.speed),
                           implausible_joint_speed=self._joint_value(
                               self.joints.implausible_speed),
                           implausible_joint_states=(self.joints.implausible_count
                                                     if joints else None))

    def _joint_value(self, value: Callable[[float], float | None]) -> float | None:
        """Return a joint speed at the newest bag time read (None before any, or no topic)."""
        if not self.config.head.joint_states_topic or self._received_s is None:
            return None
        return value(self._received_s)


class BagMessage(NamedTuple):
    """One message read from the bag: an image (left or right), a CameraInfo or a JointState."""

    side: str   # 'left', 'right', CAMERA_INFO or JOINT_STATES
    bag_time_ns: int
    msg: Any


def describe_error(err: BaseException) -> str:
    """Return ``'Type: message'`` of an error on one line, clipped to 200 characters."""
    text = ' '.join(str(err).split()).rstrip('.')
    return clip_text(f'{type(err).__name__}: {text}' if text else type(err).__name__, 200)


def _damage_hint(err: BaseException) -> str:
    text = str(err)
    if 'end magic' in text:
        return (' (the MCAP file is truncated: it has no footer, as when a recording is killed; '
                "'mcap recover' can rebuild it)")
    if 'malformed' in text or 'not a database' in text:
        return ' (the sqlite3 file is truncated or damaged)'
    return ''


def _bag_topic(name: str, topics: dict[str, str]) -> str:
    """Return the bag's topic for ``name``: itself, or ``/name`` for a relative name."""
    if name not in topics and '/' + name in topics:
        return '/' + name   # relative, as the node's names are: 'left/image_raw'
    return name


def _storage_name(reader: Reader) -> str:
    """Return 'sqlite3' or 'mcap' for an open reader."""
    storage = reader.storage
    storages = getattr(storage, 'storages', None) or [storage]
    name = type(storages[0]).__name__.lower()
    return 'mcap' if 'mcap' in name else 'sqlite3'


class BagInput:
    """Stereo image messages from a rosbag2 bag, in bag order.

    Args:
        path: The bag folder (with metadata.yaml) or a single ``.db3`` or ``.mcap`` file.
        left_topic: Left image topic; a relative name (``left/image_raw``) finds
            ``/left/image_raw``, as a node in the root namespace resolves it.
        right_topic: Right image topic (relative names as for ``left_topic``).
        camera_info_topic: The node's ``camera_info.topic`` ('' for none): its messages are
            yielded too, side :data:`CAMERA_INFO`. Missing from the bag: :attr:`notes` says
            so and the prior stays as configured, as the node's would without it.
        joint_states_topic: The node's ``head.joint_states_topic`` ('' for none): its
            messages are yielded too, side :data:`JOINT_STATES`. Missing from the bag:
            :attr:`notes` says so, and the pairs get no joint hint.

    Raises:
        BagError: If the bag does not exist or cannot be opened, or a topic is missing or is
            not an image topic (the message lists the bag's image topics), or the
            camera_info topic is not a CameraInfo topic, or the joint states topic not a
            JointState topic.

    """

    def __init__(self, path: str | os.PathLike[str], left_topic: str,
                 right_topic: str, camera_info_topic: str = '',
                 joint_states_topic: str = '') -> None:
        """Open the bag and check the topics."""
        self.path = Path(path)
        self.notes: list[str] = []
        self.camera_info_topic = ''
        self.joint_states_topic = ''
        if not self.path.exists():
            raise BagError(f'input bag {str(self.path)!r} does not exist')
        self.typestore = typestore()
        self.undecodable: list[str] = []
        if self.path.is_dir() and not (self.path / 'metadata.yaml').exists():
            files = sorted(p.name for p in self.path.iterdir() if p.suffix in ('.db3', '.mcap'))
            hint = (f'; to read its storage file alone, give {str(self.path / files[0])!r}'
                    if files else '; it holds no .db3 or .mcap file either')
            raise BagError(f'bag folder {str(self.path)!r} has no metadata.yaml' + hint)
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as err:  # noqa: B902 - rosbags raises many types on corrupt input
            raise BagError(f'cannot read bag {str(self.path)!r}: {describe_error(err)}'
                           + _damage_hint(err)) from err
        try:
            self.storage = _storage_name(self._reader)
            topics = {name: info.msgtype for name, info in self._reader.topics.items()}
            image_topics = sorted(name for name, msgtype in topics.items()
                                  if msgtype in IMAGE_TYPES)
            # Names from the bag are clipped, and at most 10 listed: a bag may hold anything.
            listing = ', '.join(f'{clip_text(name, 80)} ({topics[name].rsplit("/", 1)[-1]})'
                                for name in image_topics[:10]) or 'none'
            if len(image_topics) > 10:
                listing += f' and {len(image_topics) - 10} more'
            self.sides: dict[str, Side] = {}
            for side, topic in (('left', left_topic), ('right', right_topic)):
                topic = _bag_topic(topic, topics)
                if topic not in topics:
                    raise BagError(f'{side} topic {topic!r} is not in bag {str(self.path)!r}; '
                                   f'image topics in the bag: {listing}')
                if topics[topic] not in IMAGE_TYPES:
                    raise BagError(f'{side} topic {topic!r} has type '
                                   f'{clip_text(topics[topic], 80)}, not '
                                   f'{IMAGE_TYPE} or {COMPRESSED_IMAGE_TYPE}; image topics '
                                   f'in the bag: {listing}')
                self.sides[topic] = side
            if len(self.sides) < 2:
                raise BagError(f'left and right topics are the same: {left_topic!r}')
            self.camera_info_topic = self._optional_topic(
                'camera_info.topic', camera_info_topic, CAMERA_INFO_TYPE, topics,
                'the prior stays as configured')
            self.joint_states_topic = self._optional_topic(
                'head.joint_states_topic', joint_states_topic, JOINT_STATE_TYPE, topics,
                'the pairs get no joint hint')
            self._kinds = {**self.sides, self.camera_info_topic: CAMERA_INFO,
                           self.joint_states_topic: JOINT_STATES}
            self._kinds.pop('', None)
            self.connections = [c for c in self._reader.connections if c.topic in self._kinds]
            self.counts = {side: sum(c.msgcount for c in self.connections
                                     if self.sides.get(c.topic) == side)
                           for side in ('left', 'right')}
        except BaseException:
            self.close()
            raise

    def _optional_topic(self, parameter: str, name: str, msgtype: str,
                        topics: dict[str, str], without: str) -> str:
        """Return the bag's topic for an optional input ('' if none or missing: noted)."""
        if not name:
            return ''
        topic = _bag_topic(name, topics)
        if topic not in topics:
            self.notes.append(f'{parameter} {clip_text(name, 80)!r} is not in the bag: '
                              + without)
            return ''
        if topics[topic] != msgtype:
            raise BagError(f'{parameter} {topic!r} has type '
                           f'{clip_text(topics[topic], 80)}, not {msgtype}')
        return topic

    def sides_topics(self) -> tuple[str, str]:
        """Return the ``(left, right)`` topic names."""
        by_side = {side: topic for topic, side in self.sides.items()}
        return by_side['left'], by_side['right']

    def messages(self) -> Iterator[BagMessage]:
        """Yield the left and right image messages in bag order.

        A message that cannot be deserialised is recorded in :attr:`undecodable` and skipped.

        Yields:
            :class:`BagMessage` values.

        Raises:
            BagReadError: If reading the bag fails part-way (a truncated or corrupt file).

        """
        stream = self._reader.messages(connections=self.connections)
        count = 0
        while True:
            try:
                connection, bag_time_ns, raw = next(stream)
            except StopIteration:
                return
            except Exception as err:  # noqa: B902 - rosbags raises many types on corrupt input
                raise BagReadError(f'reading bag {str(self.path)!r} failed after {count} '
                                   f'messages: {describe_error(err)}') from err
            count += 1
            try:
                msg = self.typestore.deserialize_cdr(raw, connection.msgtype)
                header_stamp_ns(msg)
            except Exception as err:  # noqa: B902 - corrupt CDR data raises many types
                self.undecodable.append(
                    f'{connection.topic} message {count} cannot be deserialised: '
                    f'{describe_error(err)}')
                continue
            yield BagMessage(self._kinds[connection.topic], int(bag_time_ns), msg)

    def close(self) -> None:
        """Close the bag (idempotent)."""
        reader = getattr(self, '_reader', None)
        if reader is not None and reader.is_open:
            reader.close()

    def __enter__(self) -> BagInput:
        """Return the open input."""
        return self

    def __exit__(self, *exc_info: Any) -> None:
        """Close the bag."""
        self.close()
