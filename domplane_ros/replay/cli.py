"""plane_replay: run the plane pipeline over a rosbag2 file and record what plane_node would.

This is the offline adapter of the house-style picture: it reads stereo image messages from a
rosbag2 bag (sqlite3 or MCAP storage, ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage``)
with the pure-Python ``rosbags`` library, pairs them with the node's
:class:`~domplane_ros.stream.sync.ApproximateTimeSync`, runs the node's
:class:`~domplane_ros.stream.pipeline.PlanePipeline` on every pair (dropping the warm start on the
same resets), and writes a new bag with the node's outputs::

    plane_replay INPUT_BAG OUTPUT_BAG [--params-file config/plane_node.yaml]
                 [--left-topic /left/image_raw] [--right-topic /right/image_raw]
                 [--storage sqlite3|mcap] [--force] [--csv FILE] [--no-progress]
                 [--strict] [--keep-partial]

Output topics, each written with the bag timestamp of the left image's header stamp:

* ``/plane/homography`` (``std_msgs/msg/Float64MultiArray``): 3x3 row-major, layout dims
  ``rows`` (size 3, stride 9) and ``cols`` (size 3, stride 3), ``H[2][2] == 1``; only for
  pairs where a plane was found, as the node publishes it.
* ``/plane/mask`` (``sensor_msgs/msg/Image``, mono8, the left image's header): for every
  processed pair; all 0 when no plane was found.
* ``/diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``): the node's keys, once per
  ``diagnostics.period_s`` of bag time (1 s by default) and once at the end.

Exit codes: 0 on success; 3 when the output is complete except for messages the bag could
not give (undecodable payloads: skipped, counted, named on stderr and recorded in the output's
``metadata.yaml`` ``custom_data``; ``--strict`` makes them fatal); 2 when the run is refused
before anything is written (missing, unreadable or truncated bag, a folder without
metadata.yaml, unknown topic, existing output without ``--force``, invalid params file); 1 when
reading fails part-way (a damaged bag, say): the partial output is removed, or with
``--keep-partial`` kept as ``OUTPUT_BAG.incomplete`` (``plane_replay.complete: 'false'`` in its
metadata); 130 on Ctrl-C and 143 on SIGTERM, the partial output removed.

The output is written into a hidden temporary folder next to ``OUTPUT_BAG`` and renamed into
place only when it is complete, so an interrupted run never leaves a bag that looks complete.

The module imports ``rosbags`` but not ``rclpy``; the pipeline, pairing and decoding are the
core modules that the live node uses.
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import dataclass, field
import os
from pathlib import Path
import shutil
import signal
import sys
import tempfile
import time
from typing import Any, Callable, Iterable, Iterator, NamedTuple, TextIO

from domplane_ros.config import load_params_file, PlaneNodeConfig
from domplane_ros.core.image import gray_to_image_fields, message_to_gray
from domplane_ros.errors import BagError, ConfigError, ImageDecodeError
from domplane_ros.stream.health import INPUT_COUNTER_NAMES, new_counts, StampChecks
from domplane_ros.stream.pipeline import FrameResult, PlanePipeline
from domplane_ros.stream.status import plane_status, STATUS_NAME
from domplane_ros.stream.sync import ApproximateTimeSync, Pair, Side
import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

PROG = 'plane_replay'

IMAGE_TYPE = 'sensor_msgs/msg/Image'
COMPRESSED_IMAGE_TYPE = 'sensor_msgs/msg/CompressedImage'
IMAGE_TYPES = (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE)
HOMOGRAPHY_TYPE = 'std_msgs/msg/Float64MultiArray'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

HOMOGRAPHY_TOPIC = '/plane/homography'
MASK_TOPIC = '/plane/mask'
DIAGNOSTICS_TOPIC = '/diagnostics'

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_REFUSED = 2
EXIT_SKIPPED = 3          # complete, but messages the bag could not give were skipped
EXIT_INTERRUPTED = 130    # Ctrl-C
EXIT_TERMINATED = 143     # SIGTERM

# As plane_node: the latency statistics over the last this many pairs.
_LATENCY_WINDOW = 200
_DIAGNOSTICS_NAME = STATUS_NAME
_DIAGNOSTICS_HARDWARE_ID = 'plane_replay'

CSV_COLUMNS = (
    'stamp_ns', 'ok', 'reinitialised', 'n_left', 'n_right', 'n_inliers', 'iterations',
    'final_energy', 'converged',
    'h00', 'h01', 'h02', 'h10', 'h11', 'h12', 'h20', 'h21', 'h22',
    'features_ms', 'estimate_ms', 'mask_ms', 'total_ms', 'reason',
)


class BagReadError(BagError):
    """Reading a bag failed part-way (a truncated or corrupt file).

    Attributes:
        kept: Where the output up to the failure was kept (``--keep-partial``), or ''.

    """

    kept = ''


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived; raised like Ctrl-C so that the partial output is removed."""


def _typestore() -> Any:
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


# --------------------------------------------------------------------------------------------
# The frame loop (shared by the CLI, the demo and the tests).


@dataclass(frozen=True)
class ReplayedFrame:
    """One processed stereo pair.

    Attributes:
        pair: The pair, as the synchroniser emitted it (its items are the image messages).
        result: What the pipeline made of it.
        left: (H, W) uint8 decoded left image.
        latency_ms: Decoding plus processing time, milliseconds.

    """

    pair: Pair
    result: FrameResult
    left: np.ndarray
    latency_ms: float


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


@dataclass
class _Counters:
    pairs: int = 0
    processed: int = 0
    plane_found: int = 0
    converged: int = 0
    decode_errors: int = 0
    undecodable_messages: int = 0
    consecutive_failures: int = 0


class ReplaySession:
    """Pairs image messages and runs the pipeline on each pair, with the node's counters.

    Feed it every left and right message in bag order with :meth:`add`; it returns the
    processed pairs. State (warm start, sync queues, counters) lives in the session.

    Args:
        config: The configuration (the node's parameters).
        topics: The left and right topic names, for the per-camera diagnostics.

    """

    def __init__(self, config: PlaneNodeConfig | None = None,
                 topics: tuple[str, str] = ('/left/image_raw', '/right/image_raw')) -> None:
        """Make a fresh pipeline and synchroniser from the configuration."""
        self.config = config if config is not None else PlaneNodeConfig()
        self.topics = dict(zip(('left', 'right'), topics))
        # Per camera, in bag time (header stamps): the last stamp, images received, and the
        # count at the last diagnostics; the node keeps the same in wall time.
        self._last_stamp_ns: dict[str, int | None] = {'left': None, 'right': None}
        self._received = {'left': 0, 'right': 0}
        self._received_mark = {'left': 0, 'right': 0}
        self._first_ns: int | None = None
        self._diag_ns: int | None = None
        self.pipeline = PlanePipeline(self.config)
        self.sync = ApproximateTimeSync(self.config.sync.slop_s, self.config.sync.queue_size)
        self.counters = _Counters()
        self.latencies_ms: list[float] = []
        self.last_result: FrameResult | None = None
        self.last_error = ''
        # Input problems, as the node counts them (see domplane_ros.stream.health).
        self.stamp_checks = StampChecks(self.sync.slop_ns)
        self.decode_counts = new_counts()
        self.input_warning = ''

    def add(self, side: Side, msg: Any) -> list[ReplayedFrame]:
        """Add one image message and process the pairs it completes.

        Args:
            side: ``'left'`` or ``'right'``.
            msg: The image message (``header``, and the Image or CompressedImage fields).

        Returns:
            The processed pairs (none or one); a pair whose images do not decode is counted in
            ``counters.decode_errors`` and not returned.

        """
        frames = []
        stamp_ns = header_stamp_ns(msg)
        self._received[side] += 1
        self._last_stamp_ns[side] = stamp_ns
        if self._first_ns is None:
            self._first_ns = stamp_ns
        for warning in self.stamp_checks.observe(side, stamp_ns):
            self.input_warning = warning
        for pair in self.sync.add(side, stamp_ns, msg):
            self.counters.pairs += 1
            frame = self.process(pair)
            if frame is not None:
                frames.append(frame)
        return frames

    def process(self, pair: Pair) -> ReplayedFrame | None:
        """Process one pair (see :func:`process_pair`) and update the counters.

        Args:
            pair: The pair.

        Returns:
            The processed frame, or None if an image could not be decoded.

        """
        t0 = time.perf_counter()
        try:
            left, result = process_pair(self.pipeline, pair)
        except ImageDecodeError as err:
            self.counters.decode_errors += 1
            self.counters.consecutive_failures += 1
            self.decode_counts['decode_' + err.kind] += 1
            self.last_error = f'image rejected: {err}'
            self.last_result = None
            return None
        if result.warnings:
            self.input_warning = result.warnings[-1]
        latency_ms = 1e3 * (time.perf_counter() - t0)
        counters = self.counters
        counters.processed += 1
        if result.ok:
            counters.plane_found += 1
            counters.consecutive_failures = 0
        else:
            counters.consecutive_failures += 1
        if bool(getattr(result.estimate, 'converged', False)):
            counters.converged += 1
        self.latencies_ms.append(latency_ms)
        self.last_result = result
        return ReplayedFrame(pair, result, left, latency_ms)

    def note_undecodable(self, error: str) -> None:
        """Count a message that could not be deserialised (it never reaches the pairing)."""
        self.counters.undecodable_messages += 1
        self.last_error = error

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
        counters = self.counters
        stamps = [s for s in self._last_stamp_ns.values() if s is not None]
        now = now_ns if now_ns is not None else max(stamps, default=0)
        span_s = (now - self._diag_ns) * 1e-9 if self._diag_ns is not None else 0.0
        cameras = []
        for side in ('left', 'right'):
            new = self._received[side] - self._received_mark[side]
            last = self._last_stamp_ns[side]
            since = last if last is not None else (self._first_ns or now)
            cameras.append((self.topics[side], self._received[side],
                            new / span_s if span_s > 0 else rate, max(now - since, 0) * 1e-9))
            self._received_mark[side] = self._received[side]
        self._diag_ns = now
        warning, self.input_warning = self.input_warning, ''
        return plane_status(
            rate=rate, latencies_ms=self.latencies_ms[-_LATENCY_WINDOW:], pairs=counters.pairs,
            processed=counters.processed, dropped_busy=0,
            dropped_sync=self.sync.stats().dropped,
            decode_errors=counters.decode_errors + counters.undecodable_messages,
            lock_state=self.pipeline.state,
            reinitialisations=self.pipeline.stats.reinitialisations,
            consecutive_failures=counters.consecutive_failures, last_result=self.last_result,
            last_error=self.last_error,
            input_counts=(self.pipeline.checks.counts, self.stamp_checks.counts,
                          self.decode_counts),
            input_warning=warning, cameras=cameras,
            silence_s=self.config.transport.silence_s)

    def input_counts(self) -> dict[str, int]:
        """Return the input problems seen so far (names of ``health.INPUT_COUNTER_NAMES``)."""
        return {name: (self.pipeline.checks.counts[name] + self.stamp_checks.counts[name]
                       + self.decode_counts[name]) for name in INPUT_COUNTER_NAMES}


# --------------------------------------------------------------------------------------------
# Bag input.


class BagMessage(NamedTuple):
    """One image message read from the bag."""

    side: Side
    bag_time_ns: int
    msg: Any


def _describe_error(err: BaseException) -> str:
    text = str(err).strip().rstrip('.')
    return f'{type(err).__name__}: {text}' if text else type(err).__name__


def _damage_hint(err: BaseException) -> str:
    text = str(err)
    if 'end magic' in text:
        return (' (the MCAP file is truncated: it has no footer, as when a recording is killed; '
                "'mcap recover' can rebuild it)")
    if 'malformed' in text or 'not a database' in text:
        return ' (the sqlite3 file is truncated or damaged)'
    return ''


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
        left_topic: Left image topic.
        right_topic: Right image topic.

    Raises:
        BagError: If the bag does not exist or cannot be opened, or a topic is missing or is
            not an image topic; the message lists the bag's image topics.

    """

    def __init__(self, path: str | os.PathLike[str], left_topic: str,
                 right_topic: str) -> None:
        """Open the bag and check the topics."""
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'input bag {str(self.path)!r} does not exist')
        self.typestore = _typestore()
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
            raise BagError(f'cannot read bag {str(self.path)!r}: {_describe_error(err)}'
                           + _damage_hint(err)) from err
        try:
            self.storage = _storage_name(self._reader)
            topics = {name: info.msgtype for name, info in self._reader.topics.items()}
            image_topics = sorted(name for name, msgtype in topics.items()
                                  if msgtype in IMAGE_TYPES)
            listing = ', '.join(f'{name} ({topics[name].rsplit("/", 1)[-1]})'
                                for name in image_topics) or 'none'
            self.sides: dict[str, Side] = {}
            for side, topic in (('left', left_topic), ('right', right_topic)):
                if topic not in topics:
                    raise BagError(f'{side} topic {topic!r} is not in bag {str(self.path)!r}; '
                                   f'image topics in the bag: {listing}')
                if topics[topic] not in IMAGE_TYPES:
                    raise BagError(f'{side} topic {topic!r} has type {topics[topic]}, not '
                                   f'{IMAGE_TYPE} or {COMPRESSED_IMAGE_TYPE}; image topics '
                                   f'in the bag: {listing}')
                self.sides[topic] = side
            if left_topic == right_topic:
                raise BagError(f'left and right topics are the same: {left_topic!r}')
            self.connections = [c for c in self._reader.connections if c.topic in self.sides]
            self.counts = {side: sum(c.msgcount for c in self.connections
                                     if self.sides[c.topic] == side)
                           for side in ('left', 'right')}
        except BaseException:
            self.close()
            raise

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
                                   f'messages: {_describe_error(err)}') from err
            count += 1
            try:
                msg = self.typestore.deserialize_cdr(raw, connection.msgtype)
                header_stamp_ns(msg)
            except Exception as err:  # noqa: B902 - corrupt CDR data raises many types
                self.undecodable.append(
                    f'{connection.topic} message {count} cannot be deserialised: '
                    f'{_describe_error(err)}')
                continue
            yield BagMessage(self.sides[connection.topic], int(bag_time_ns), msg)

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


# --------------------------------------------------------------------------------------------
# Bag output.


class BagOutput:
    """Writes the node's outputs into a bag that appears only when it is complete.

    The bag is written into a hidden temporary folder next to ``path``; :meth:`commit`
    closes it and renames it into place (replacing an existing ``path`` only if ``replace``),
    :meth:`abort` removes it.

    Args:
        path: Where the finished bag goes.
        storage: ``'sqlite3'`` or ``'mcap'``.
        replace: Replace an existing ``path`` at commit.

    """

    def __init__(self, path: str | os.PathLike[str], storage: str, replace: bool) -> None:
        """Create the temporary bag and its three connections."""
        self.path = Path(path)
        self.replace = replace
        self.typestore = ts = _typestore()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-',
                                             dir=self.path.parent))
        self.counts = {HOMOGRAPHY_TOPIC: 0, MASK_TOPIC: 0, DIAGNOSTICS_TOPIC: 0}
        try:
            self._writer = Writer(self._tmpdir / self.path.name, version=9,
                                  storage_plugin=STORAGES[storage])
            self._writer.open()
            self._conn_h = self._writer.add_connection(HOMOGRAPHY_TOPIC, HOMOGRAPHY_TYPE,
                                                       typestore=ts)
            self._conn_mask = self._writer.add_connection(MASK_TOPIC, IMAGE_TYPE, typestore=ts)
            self._conn_diag = self._writer.add_connection(DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE,
                                                          typestore=ts)
        except BaseException:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise
        t = ts.types
        self._Time = t['builtin_interfaces/msg/Time']
        self._Header = t['std_msgs/msg/Header']
        self._Image = t[IMAGE_TYPE]
        self._Float64MultiArray = t[HOMOGRAPHY_TYPE]
        self._MultiArrayLayout = t['std_msgs/msg/MultiArrayLayout']
        self._MultiArrayDimension = t['std_msgs/msg/MultiArrayDimension']
        self._DiagnosticArray = t[DIAGNOSTICS_TYPE]
        self._DiagnosticStatus = t['diagnostic_msgs/msg/DiagnosticStatus']
        self._KeyValue = t['diagnostic_msgs/msg/KeyValue']

    def _write(self, connection: Any, topic: str, stamp_ns: int, msg: Any) -> None:
        data = self.typestore.serialize_cdr(msg, connection.msgtype)
        self._writer.write(connection, stamp_ns, data)
        self.counts[topic] += 1

    def write_frame(self, frame: ReplayedFrame) -> None:
        """Write a processed pair: its homography (if a plane was found) and its mask.

        Both are written at the left image's header stamp; the mask carries the left header.
        """
        header = frame.pair.left.header
        stamp = frame.pair.left_stamp_ns
        result = frame.result
        if result.ok:
            self._write(self._conn_h, HOMOGRAPHY_TOPIC, stamp,
                        self.homography_msg(result.homography))
        fields = gray_to_image_fields(result.mask, 'mono8')
        mask = self._Image(
            header=self._Header(stamp=self._Time(sec=int(header.stamp.sec),
                                                 nanosec=int(header.stamp.nanosec)),
                                frame_id=str(header.frame_id)),
            height=fields['height'], width=fields['width'], encoding=fields['encoding'],
            is_bigendian=fields['is_bigendian'], step=fields['step'],
            data=np.frombuffer(fields['data'], np.uint8))
        self._write(self._conn_mask, MASK_TOPIC, stamp, mask)

    def homography_msg(self, homography: np.ndarray) -> Any:
        """Return the node's Float64MultiArray for a (3, 3) homography (rosbags message)."""
        dim = self._MultiArrayDimension
        layout = self._MultiArrayLayout(dim=[dim(label='rows', size=3, stride=9),
                                             dim(label='cols', size=3, stride=3)],
                                        data_offset=0)
        data = np.asarray(homography, dtype=np.float64).reshape(9).copy()
        return self._Float64MultiArray(layout=layout, data=data)

    def write_diagnostics(self, stamp_ns: int, level: int, message: str,
                          values: list[tuple[str, str]]) -> None:
        """Write one DiagnosticArray with one status at ``stamp_ns``."""
        status = self._DiagnosticStatus(
            level=level, name=_DIAGNOSTICS_NAME, message=message,
            hardware_id=_DIAGNOSTICS_HARDWARE_ID,
            values=[self._KeyValue(key=k, value=v) for k, v in values])
        msg = self._DiagnosticArray(
            header=self._Header(stamp=self._Time(sec=stamp_ns // 1_000_000_000,
                                                 nanosec=stamp_ns % 1_000_000_000),
                                frame_id=''),
            status=[status])
        self._write(self._conn_diag, DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def set_custom_data(self, key: str, value: str) -> None:
        """Record a key/value string in the output bag's metadata.yaml ``custom_data``."""
        self._writer.set_custom_data(key, value)

    def commit(self, path: str | os.PathLike[str] | None = None) -> None:
        """Close the bag and move it into place (to ``path`` instead, if given)."""
        self._writer.close()
        finished = self._tmpdir / self.path.name
        target = Path(path) if path is not None else self.path
        if target.exists() or target.is_symlink():
            if not self.replace:
                raise BagError(f'output {str(target)!r} appeared while replaying; '
                               f'the result is left in {str(finished)!r}')
            # Move the old one aside first, so the rename below is atomic.
            os.replace(target, self._tmpdir / 'replaced')
        os.replace(finished, target)
        shutil.rmtree(self._tmpdir, ignore_errors=True)

    def abort(self) -> None:
        """Drop the partial bag."""
        try:
            if self._writer.storage is not None:
                self._writer.abort()
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)


class _CsvOutput:
    """One row per processed pair, written to a temporary file renamed at commit."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f'.{self.path.name}.', suffix='.partial',
                                   dir=self.path.parent)
        self._tmp = Path(tmp)
        self._stream: TextIO = os.fdopen(fd, 'w', newline='', encoding='utf-8')
        self._csv = csv.writer(self._stream)
        self._csv.writerow(CSV_COLUMNS)
        self.rows = 0

    def write(self, result: FrameResult) -> None:
        estimate = result.estimate
        h = (result.homography.reshape(9).tolist() if result.homography is not None
             else [''] * 9)
        final_energy = getattr(estimate, 'final_energy', None)
        timings = result.timings_ms
        self._csv.writerow([
            result.stamp_ns, int(result.ok), int(result.reinitialised),
            # Features: corners plus line segments (features.kind lines or both).
            result.left_points.shape[0] + result.left_lines.shape[0],
            result.right_points.shape[0] + result.right_lines.shape[0], result.n_inliers,
            int(getattr(estimate, 'iterations', 0)),
            '' if final_energy is None else repr(float(final_energy)),
            int(bool(getattr(estimate, 'converged', False))),
            *[repr(float(v)) if v != '' else '' for v in h],
            *[f'{timings.get(k, float("nan")):.3f}'
              for k in ('features', 'estimate', 'mask', 'total')],
            result.reason,
        ])
        self.rows += 1

    def commit(self, path: Path | None = None) -> None:
        self._stream.close()
        # mkstemp makes the file private; give it the permissions open() would have.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self._tmp, 0o666 & ~umask)
        os.replace(self._tmp, path if path is not None else self.path)

    def abort(self) -> None:
        self._stream.close()
        self._tmp.unlink(missing_ok=True)


# --------------------------------------------------------------------------------------------
# A whole run.


@dataclass
class ReplaySummary:
    """What a replay did.

    Attributes:
        input_bag: The input bag.
        output_bag: The output bag.
        storage: Storage of the output bag.
        left_messages: Left image messages read.
        right_messages: Right image messages read.
        pairs: Pairs made by the synchroniser.
        processed: Pairs that went through the pipeline.
        plane_found: Processed pairs with a plane.
        converged: Processed pairs whose estimator met its tolerance.
        dropped_sync: Messages the synchroniser dropped.
        unpaired_at_end: Messages still waiting for a partner at the end of the bag.
        decode_errors: Pairs whose images could not be decoded.
        undecodable_messages: Messages that could not be deserialised.
        reinitialisations: Prior searches started.
        latency_ms: Decode plus processing time of every processed pair, ms.
        wall_s: Wall time of the run, seconds.
        written: Messages written per output topic.
        first_errors: The first few decode errors, for the report.
        input_problems: Input problems seen, by diagnostics key (only the non-zero ones).

    """

    input_bag: str
    output_bag: str
    storage: str
    left_messages: int = 0
    right_messages: int = 0
    pairs: int = 0
    processed: int = 0
    plane_found: int = 0
    converged: int = 0
    dropped_sync: int = 0
    unpaired_at_end: int = 0
    decode_errors: int = 0
    undecodable_messages: int = 0
    reinitialisations: int = 0
    latency_ms: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    written: dict[str, int] = field(default_factory=dict)
    first_errors: list[str] = field(default_factory=list)
    input_problems: dict[str, int] = field(default_factory=dict)

    @property
    def rate_pairs_per_s(self) -> float:
        """Return processed pairs per second of wall time."""
        return self.processed / self.wall_s if self.wall_s > 0 else 0.0

    def percent(self, count: int) -> float:
        """Return ``count`` as a percentage of the processed pairs (0 if none)."""
        return 100.0 * count / self.processed if self.processed else 0.0

    def latency_percentile(self, q: float) -> float:
        """Return a latency percentile in ms (NaN if nothing was processed)."""
        return float(np.percentile(self.latency_ms, q)) if self.latency_ms else float('nan')

    def lines(self) -> list[str]:
        """Return the human-readable summary."""
        out = [
            f'{PROG}: {self.input_bag} -> {self.output_bag} ({self.storage})',
            f'  messages read:   {self.left_messages} left, {self.right_messages} right',
            f'  pairs processed: {self.processed} of {self.pairs} paired '
            f'(dropped by sync: {self.dropped_sync} messages, unpaired at end: '
            f'{self.unpaired_at_end}, decode errors: {self.decode_errors} pairs + '
            f'{self.undecodable_messages} messages)',
            f'  plane found:     {self.plane_found} ({self.percent(self.plane_found):.1f} %), '
            f'converged {self.converged} ({self.percent(self.converged):.1f} %), '
            f're-initialisations {self.reinitialisations}',
            f'  latency:         median {self.latency_percentile(50):.1f} ms, '
            f'p95 {self.latency_percentile(95):.1f} ms; '
            f'{self.rate_pairs_per_s:.1f} pairs/s over {self.wall_s:.1f} s',
            '  written:         ' + ', '.join(f'{topic} {count}'
                                              for topic, count in self.written.items()),
        ]
        if self.input_problems:
            out.append('  input problems:  ' + ', '.join(
                f'{key} {count}' for key, count in self.input_problems.items()))
        out += [f'  error: {text}' for text in self.first_errors]
        return out


class _DiagnosticsClock:
    """Decides when a diagnostics message is due, in bag time (the pairs' left stamps)."""

    def __init__(self, period_s: float) -> None:
        self.period_ns = max(1, int(round(period_s * 1e9)))
        self.start_ns: int | None = None
        self.pairs = 0
        self.last_ns: int | None = None

    def due(self, stamp_ns: int) -> list[tuple[int, float]]:
        """Return ``(stamp, rate)`` of the diagnostics to write before a pair at ``stamp_ns``.

        A gap in the bag gives one message with the pairs before it and, if the gap is longer
        than a period, one more with rate 0 (the node would send one per period).
        """
        out: list[tuple[int, float]] = []
        if self.start_ns is None or (self.last_ns is not None and stamp_ns < self.last_ns):
            # First pair, or the stamps went back (a bag loop): start a new period.
            self.start_ns, self.pairs = stamp_ns, 0
        else:
            out = self.tick(stamp_ns)
        self.pairs += 1
        self.last_ns = stamp_ns
        return out

    def tick(self, stamp_ns: int) -> list[tuple[int, float]]:
        """Return ``(stamp, rate)`` of the periods that ended before a message at ``stamp_ns``.

        Called for every image message, so that a camera drop-out (images on one side only)
        gets a diagnostics message per period, as the node sends.
        """
        out: list[tuple[int, float]] = []
        if self.start_ns is None or stamp_ns < self.start_ns:
            return out
        end = self.start_ns + self.period_ns
        if stamp_ns >= end:
            out.append((end, self.pairs / (self.period_ns * 1e-9)))
            self.start_ns, self.pairs = end, 0
            periods = (stamp_ns - end) // self.period_ns
            if periods >= 1:
                end = self.start_ns + periods * self.period_ns
                out.append((end, 0.0))
                self.start_ns = end
        return out

    def final(self) -> tuple[int, float] | None:
        """Return the last diagnostics (the partial period up to the last pair), if any."""
        if self.start_ns is None or self.last_ns is None or self.pairs == 0:
            return None
        span_ns = max(self.last_ns - self.start_ns, 0)
        # n pairs spread over span cover about span * n / (n - 1).
        rate = ((self.pairs - 1) / (span_ns * 1e-9) if span_ns > 0 and self.pairs > 1
                else self.pairs / (self.period_ns * 1e-9))
        return self.last_ns, rate


def _check_paths(input_bag: Path, output_bag: Path, csv_path: Path | None,
                 force: bool) -> None:
    in_res = input_bag.resolve()
    out_res = output_bag.resolve()
    if out_res == in_res or in_res.is_relative_to(out_res) or out_res.is_relative_to(in_res):
        raise BagError(f'output {str(output_bag)!r} would overwrite or nest in the input bag '
                       f'{str(input_bag)!r}')
    if (output_bag.exists() or output_bag.is_symlink()) and not force:
        raise BagError(f'output {str(output_bag)!r} exists; use --force to replace it')
    if csv_path is not None:
        if csv_path.resolve().is_relative_to(in_res) or csv_path.resolve() == out_res:
            raise BagError(f'CSV file {str(csv_path)!r} would overwrite a bag')
        if csv_path.exists() and not force:
            raise BagError(f'CSV file {str(csv_path)!r} exists; use --force to replace it')
        if csv_path.is_dir():
            raise BagError(f'CSV file {str(csv_path)!r} is a directory')


def run_replay(input_bag: str | os.PathLike[str], output_bag: str | os.PathLike[str],
               config: PlaneNodeConfig | None = None, left_topic: str = '/left/image_raw',
               right_topic: str = '/right/image_raw', storage: str | None = None,
               force: bool = False, csv_path: str | os.PathLike[str] | None = None,
               progress: bool = False,
               on_frame: Callable[[ReplayedFrame], None] | None = None,
               strict: bool = False, keep_partial: bool = False) -> ReplaySummary:
    """Replay a bag through the pipeline and write the node's outputs to a new bag.

    Everything that can be checked up front is checked before anything is written.

    Args:
        input_bag: Input rosbag2 folder, or a single ``.db3`` / ``.mcap`` file.
        output_bag: Output bag folder; it must not exist unless ``force``.
        config: Configuration (default: the node's defaults).
        left_topic: Left image topic.
        right_topic: Right image topic.
        storage: ``'sqlite3'`` or ``'mcap'``; default: the input's storage.
        force: Replace an existing output bag (and CSV file).
        csv_path: If given, write one CSV row per processed pair there.
        progress: Show a progress bar on stderr.
        on_frame: Called with every processed pair, after it is written.
        strict: Fail (``BagReadError``, partial output removed) on the first message that
            cannot be deserialised, instead of skipping and counting it.
        keep_partial: On a read failure part-way, keep the output up to it as
            ``OUTPUT_BAG.incomplete`` (and ``CSV.incomplete``), marked
            ``plane_replay.complete: 'false'`` in its metadata, instead of removing it.

    Returns:
        The summary.

    Raises:
        BagReadError: If reading fails part-way (or, with ``strict``, a message cannot be
            deserialised); the partial output is removed (or kept, see ``keep_partial``).
        BagError: If the run is refused (missing or unreadable bag, unknown topic, existing
            output); nothing is written.
        ValueError: If ``storage`` is not one of the names in :data:`STORAGES`.

    """
    if storage is not None and storage not in STORAGES:
        raise ValueError(f'storage must be one of {", ".join(STORAGES)}, got {storage!r}')
    config = config if config is not None else PlaneNodeConfig()
    input_path, output_path = Path(input_bag), Path(output_bag)
    csv_file = Path(csv_path) if csv_path is not None else None
    if not input_path.exists():
        raise BagError(f'input bag {str(input_path)!r} does not exist')
    _check_paths(input_path, output_path, csv_file, force)
    incomplete = output_path.with_name(output_path.name + '.incomplete')
    csv_incomplete = (csv_file.with_name(csv_file.name + '.incomplete')
                      if csv_file is not None else None)
    if keep_partial and not force:
        for path in (incomplete, csv_incomplete):
            if path is not None and (path.exists() or path.is_symlink()):
                raise BagError(f'{str(path)!r} exists (where --keep-partial would put a '
                               'partial output); use --force to replace it')
    t_start = time.perf_counter()
    with BagInput(input_path, left_topic, right_topic) as bag:
        out_storage = storage or bag.storage
        summary = ReplaySummary(str(input_path), str(output_path), out_storage)
        session = ReplaySession(config, (left_topic, right_topic))
        clock = _DiagnosticsClock(config.transport.diagnostics_period_s)
        output = BagOutput(output_path, out_storage, replace=force)
        table = _CsvOutput(csv_file) if csv_file is not None else None
        bar = _progress_bar(bag.counts['left'], progress)
        try:
            n_undecodable = 0
            for item in bag.messages():
                if strict and bag.undecodable:
                    raise BagReadError(f'bag {str(input_path)!r}: {bag.undecodable[0]} '
                                       '(--strict)')
                while n_undecodable < len(bag.undecodable):
                    session.note_undecodable(bag.undecodable[n_undecodable])
                    n_undecodable += 1
                for stamp_ns, rate in clock.tick(header_stamp_ns(item.msg)):
                    output.write_diagnostics(stamp_ns,
                                             *session.diagnostic_values(rate, stamp_ns))
                if item.side == 'left':
                    summary.left_messages += 1
                    bar.update(1)
                else:
                    summary.right_messages += 1
                for frame in session.add(item.side, item.msg):
                    for stamp_ns, rate in clock.due(frame.pair.left_stamp_ns):
                        output.write_diagnostics(stamp_ns,
                                                 *session.diagnostic_values(rate, stamp_ns))
                    output.write_frame(frame)
                    if table is not None:
                        table.write(frame.result)
                    if on_frame is not None:
                        on_frame(frame)
                done = session.counters.processed
                if done and bar.enabled:
                    found = 100.0 * session.counters.plane_found / done
                    bar.set_postfix_str(f'plane {found:.0f} %', refresh=False)
            while n_undecodable < len(bag.undecodable):
                session.note_undecodable(bag.undecodable[n_undecodable])
                n_undecodable += 1
            if strict and bag.undecodable:
                raise BagReadError(f'bag {str(input_path)!r}: {bag.undecodable[0]} (--strict)')
            last = clock.final()
            if last is not None:
                output.write_diagnostics(last[0],
                                         *session.diagnostic_values(last[1], last[0]))
            output.set_custom_data('plane_replay.input_bag', str(input_path))
            output.set_custom_data('plane_replay.skipped_messages',
                                   str(len(bag.undecodable)))
            output.set_custom_data('plane_replay.complete', 'true')
            bar.close()
            if table is not None:
                table.commit()
            output.commit()
        except BagReadError as err:
            bar.close()
            if not keep_partial:
                output.abort()
                if table is not None:
                    table.abort()
                raise
            output.set_custom_data('plane_replay.input_bag', str(input_path))
            output.set_custom_data('plane_replay.skipped_messages',
                                   str(len(bag.undecodable)))
            output.set_custom_data('plane_replay.complete', 'false')
            output.set_custom_data('plane_replay.error', str(err))
            output.commit(incomplete)
            if table is not None:
                table.commit(csv_incomplete)
            kept = BagReadError(f'{err}; the output up to the failure is in '
                                f'{str(incomplete)!r} (incomplete)')
            kept.kept = str(incomplete)
            raise kept from err
        except BaseException:
            bar.close()
            output.abort()
            if table is not None:
                table.abort()
            raise
    counters = session.counters
    stats = session.sync.stats()
    summary.pairs = counters.pairs
    summary.processed = counters.processed
    summary.plane_found = counters.plane_found
    summary.converged = counters.converged
    summary.dropped_sync = stats.dropped
    summary.unpaired_at_end = stats.queued_left + stats.queued_right
    summary.decode_errors = counters.decode_errors
    summary.undecodable_messages = counters.undecodable_messages
    summary.reinitialisations = session.pipeline.stats.reinitialisations
    summary.latency_ms = list(session.latencies_ms)
    summary.input_problems = {INPUT_COUNTER_NAMES[name]: count
                              for name, count in session.input_counts().items() if count}
    summary.wall_s = time.perf_counter() - t_start
    summary.written = dict(output.counts)
    if counters.decode_errors or counters.undecodable_messages:
        summary.first_errors = (bag.undecodable[:3] + ([session.last_error]
                                                       if counters.decode_errors else []))
    return summary


class _NoBar:
    enabled = False

    def update(self, n: int) -> None:
        pass

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, enabled: bool) -> Any:
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    bar = tqdm(total=total or None, unit='frame', desc=PROG, file=sys.stderr,
               dynamic_ncols=True, smoothing=0.1)
    bar.enabled = True
    return bar


# --------------------------------------------------------------------------------------------
# Command line.


def build_parser() -> argparse.ArgumentParser:
    """Return the command-line parser of plane_replay."""
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Run the dominant-plane pipeline over a rosbag2 bag (sqlite3 or MCAP) and '
                    'write what plane_node would publish (/plane/homography, /plane/mask, '
                    '/diagnostics) to a new bag.')
    parser.add_argument('input_bag', metavar='INPUT_BAG',
                        help='input bag folder, or a single .db3 or .mcap file')
    parser.add_argument('output_bag', metavar='OUTPUT_BAG', help='output bag folder')
    parser.add_argument('--params-file', metavar='YAML',
                        help='ROS 2 parameters file with a "plane_node: ros__parameters:" '
                             "block (default: the node's defaults)")
    parser.add_argument('--left-topic', default='/left/image_raw',
                        help='left image topic (default: %(default)s)')
    parser.add_argument('--right-topic', default='/right/image_raw',
                        help='right image topic (default: %(default)s)')
    parser.add_argument('--storage', choices=sorted(STORAGES),
                        help="output storage (default: the input's)")
    parser.add_argument('--force', action='store_true',
                        help='replace an existing OUTPUT_BAG (and --csv file)')
    parser.add_argument('--csv', metavar='FILE',
                        help='write one CSV row per processed pair to FILE')
    parser.add_argument('--keep-partial', action='store_true',
                        help='if reading fails part-way, keep the output up to the failure as '
                             'OUTPUT_BAG.incomplete (marked incomplete in its metadata) '
                             'instead of removing it')
    parser.add_argument('--strict', action='store_true',
                        help='fail (exit 1, output removed) on the first message that cannot '
                             'be deserialised, instead of skipping it (exit 3)')
    bar = parser.add_mutually_exclusive_group()
    bar.add_argument('--no-progress', dest='progress', action='store_false', default=None,
                     help='no progress bar (the default when stderr is not a terminal)')
    bar.add_argument('--progress', dest='progress', action='store_true',
                     help='show the progress bar even when stderr is not a terminal')
    return parser


def _error(message: str) -> None:
    print(f'{PROG}: error: {" ".join(message.split())}', file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run plane_replay.

    Args:
        argv: Arguments without the program name (default: ``sys.argv[1:]``).

    Returns:
        0 on success; 3 when the output is complete except for messages the bag could not
        give (skipped, counted and named on stderr); 2 if the run was refused (nothing
        written); 1 if it failed part-way (the partial output removed); 130 on Ctrl-C and
        143 on SIGTERM (the partial output removed).

    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed by argparse
        return int(exc.code) if isinstance(exc.code, int) else EXIT_REFUSED
    try:
        config = (load_params_file(args.params_file) if args.params_file
                  else PlaneNodeConfig())
    except ConfigError as err:
        _error(str(err) if args.params_file in str(err)
               else f'params file {args.params_file!r}: {err}')
        return EXIT_REFUSED
    progress = args.progress if args.progress is not None else sys.stderr.isatty()
    installed, previous = _terminate_like_ctrl_c()
    try:
        summary = run_replay(args.input_bag, args.output_bag, config,
                             left_topic=args.left_topic, right_topic=args.right_topic,
                             storage=args.storage, force=args.force, csv_path=args.csv,
                             progress=progress, strict=args.strict,
                             keep_partial=args.keep_partial)
    except Terminated:
        _error('terminated (SIGTERM); the partial output was removed')
        return EXIT_TERMINATED
    except BagReadError as err:
        _error(str(err) if err.kept else f'{err}; the partial output was removed')
        return EXIT_FAILED
    except BagError as err:
        _error(str(err))
        return EXIT_REFUSED
    except OSError as err:
        _error(f'{_describe_error(err)} (no output bag was written)')
        return EXIT_FAILED
    except KeyboardInterrupt:
        _error('interrupted; the partial output was removed')
        return EXIT_INTERRUPTED
    finally:
        if installed:
            signal.signal(signal.SIGTERM, previous)
    print('\n'.join(summary.lines()))
    if summary.undecodable_messages:
        print(f'{PROG}: warning: {summary.undecodable_messages} message(s) of '
              f'{summary.input_bag!r} could not be read and were skipped (first: '
              f'{summary.first_errors[0]}); {summary.output_bag!r} records the count in '
              'metadata.yaml custom_data plane_replay.skipped_messages', file=sys.stderr)
        return EXIT_SKIPPED
    return EXIT_OK


def _terminate_like_ctrl_c() -> tuple[bool, Any]:
    """Make SIGTERM raise :class:`Terminated` (main thread only).

    Returns:
        ``(installed, previous handler)``.

    """
    def on_sigterm(signum: int, frame: Any) -> None:
        raise Terminated()

    try:
        return True, signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:   # not the main thread: leave SIGTERM alone
        return False, None


if __name__ == '__main__':
    sys.exit(main())
