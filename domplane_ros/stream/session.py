"""One session per stereo stream: the bookkeeping around the pipeline (no ROS imports).

The live node and the offline replay are thin adapters around :class:`StreamSession`: they
decode nothing and count nothing themselves. One stream's flow::

    receive(side, stamp, message, now)  stamp checks, camera activity, synchroniser -> pairs
    process(pair)                       decode, pipeline, counters, latency, last result
    status(now)                         the ``/diagnostics`` status (:func:`plane_status`)

Everything one stream counts lives here, once: the pair counters (:class:`StreamCounters`),
the input problems (one :class:`~domplane_ros.stream.health.InputCounts` that the stamp
checks, the pipeline's pair checks and the decoder add to), the latency window, the last
result and error, and per-camera activity. The adapter chooses the clock: the node gives
monotonic seconds, the replay header stamps in nanoseconds (``tick_s`` says which).

Thread safety (the node's use): :meth:`receive` and :meth:`status` from one thread (the
executor), :meth:`process` from another (the worker), :meth:`update_config` from either.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
import threading
import time
from typing import Any, Callable, Sequence

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.estimator import PlaneEstimate
from domplane_ros.core.image import is_mono16, message_to_gray, mono16_range_warning
from domplane_ros.errors import clip_text, ImageDecodeError
from domplane_ros.stream.health import homography_problem, InputCounts, StampChecks
from domplane_ros.stream.joints import JointSpeeds
from domplane_ros.stream.pipeline import FrameResult, PlanePipeline
from domplane_ros.stream.status import plane_status
from domplane_ros.stream.sync import ApproximateTimeSync, merge_dropped, Pair, Side
import numpy as np

# The status's latency statistics cover the last this many pairs.
LATENCY_WINDOW = 200
SIDES: tuple[Side, Side] = ('left', 'right')
DEFAULT_TOPICS = ('/left/image_raw', '/right/image_raw')
# The status's 'last error' (and the node's log of it) holds at most this many characters;
# strings from the wire in it are clipped further where the error is made.
LAST_ERROR_CHARS = 300


@dataclass
class StreamCounters:
    """What happened to one stream's pairs.

    Attributes:
        pairs: Pairs made by the synchroniser.
        processed: Pairs that went through the pipeline.
        plane_found: Processed pairs with a plane.
        converged: Processed pairs whose estimator met its tolerance.
        decode_errors: Pairs whose images could not be decoded.
        undecodable_messages: Messages that could not be deserialised (the replay's bags).
        consecutive_failures: Pairs in a row without a publishable plane.
        internal_errors: Pairs whose processing raised (the node's worker survives them).

    """

    pairs: int = 0
    processed: int = 0
    plane_found: int = 0
    converged: int = 0
    decode_errors: int = 0
    undecodable_messages: int = 0
    consecutive_failures: int = 0
    internal_errors: int = 0


@dataclass(frozen=True)
class ProcessedPair:
    """One processed stereo pair.

    Attributes:
        pair: The pair, as the synchroniser emitted it (its items are the image messages).
        result: What the pipeline made of it.
        left: (H, W) uint8 decoded left image.
        latency_ms: Decoding plus processing time, milliseconds.
        image_warning: A problem of the images that did not refuse the pair (mono16 data
            using far fewer bits than ``image.mono16_bits``), '' if none.

    """

    pair: Pair
    result: FrameResult
    left: np.ndarray
    latency_ms: float
    image_warning: str = ''

    @property
    def publishable(self) -> bool:
        """Return whether the result has a plane whose homography may be published."""
        return self.result.ok and not homography_problem(self.result.homography)


class CameraActivity:
    """Per camera: images received, the rate over the last period, the age of the last image.

    Args:
        topics: ``(left topic, right topic)``, named in the status.
        start: Time the stream started (None: at its first image).
        tick_s: Seconds per unit of the adapter's clock (1.0 for seconds, 1e-9 for ns).

    """

    def __init__(self, topics: tuple[str, str], start: float | None, tick_s: float) -> None:
        """Start with no images."""
        self.topics = dict(zip(SIDES, topics))
        self.tick_s = tick_s
        self._start = start
        self._period_start = start
        self._last: dict[str, float | None] = {'left': None, 'right': None}
        self._received = {'left': 0, 'right': 0}
        self._mark = {'left': 0, 'right': 0}
        self._period_pairs = 0

    def last_seen(self, side: Side) -> float | None:
        """Return when ``side`` last received an image (None: never)."""
        return self._last[side]

    def newest(self) -> float | None:
        """Return the time of the newest image on either side (None: none yet)."""
        seen = [t for t in self._last.values() if t is not None]
        return max(seen) if seen else None

    def note_image(self, side: Side, now: float) -> None:
        """Count an image on ``side`` at ``now``."""
        if self._start is None:
            self._start = now
        self._last[side] = now
        self._received[side] += 1

    def note_pairs(self, n: int) -> None:
        """Count ``n`` pairs made in this period."""
        self._period_pairs += n

    def end_period(self, now: float, rate: float | None
                   ) -> tuple[float, list[tuple[str, int, float, float]]]:
        """Close the period at ``now``; return the pair rate and the per-camera activity.

        Args:
            now: The time of the status.
            rate: The pair rate if the adapter measures it (the replay: by its clock); None
                measures pairs made over the period (the node).

        Returns:
            ``(pairs per second, cameras)``, cameras as :func:`plane_status` takes them.
            Without a previous period (the replay's first status) a camera's rate is the
            pair rate.

        """
        span = now - self._period_start if self._period_start is not None else 0
        if rate is None:
            rate = self._period_pairs / max(span * self.tick_s, 1e-6)
        cameras = []
        for side in SIDES:
            new = self._received[side] - self._mark[side]
            last = self._last[side]
            since = last if last is not None else (self._start if self._start is not None
                                                   else now)
            cameras.append((self.topics[side], self._received[side],
                            new / (span * self.tick_s) if span > 0 else rate,
                            max(now - since, 0) * self.tick_s))
            self._mark[side] = self._received[side]
        self._period_start = now
        self._period_pairs = 0
        return rate, cameras


class StreamSession:
    """The pipeline of one stereo stream with all its bookkeeping; see the module docstring.

    Args:
        config: The configuration (default: the node's defaults).
        topics: The left and right topic names, for the per-camera diagnostics.
        start: The stream's start in the adapter's clock (None: its first image).
        tick_s: Seconds per unit of the adapter's clock.

    """

    def __init__(self, config: PlaneNodeConfig | None = None,
                 topics: tuple[str, str] = DEFAULT_TOPICS, start: float | None = None,
                 tick_s: float = 1.0) -> None:
        """Make a fresh pipeline, synchroniser and counters from the configuration."""
        self.config = config if config is not None else PlaneNodeConfig()
        self.counts = InputCounts()
        self.counters = StreamCounters()
        self.pipeline = PlanePipeline(self.config, self.counts)
        self.sync = ApproximateTimeSync(self.config.sync.slop_s, self.config.sync.queue_size)
        self.stamp_checks = StampChecks(self.sync.slop_ns, self.counts)
        self.activity = CameraActivity(topics, start, tick_s)
        # The head's joint speeds (head.joint_states_topic), in the adapter's receive clock.
        self.joints = JointSpeeds(self.config.head)
        self.latencies_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.last_result: FrameResult | None = None
        # The last result with the lock state the pipeline had right after it: a status shows
        # both together (the pipeline's state changes while a pair is processed, e.g. locked
        # before its mask is computed, so the live state could sit beside the previous result).
        self._shown: tuple[FrameResult | None, str] = (None, self.pipeline.state)
        self.last_error = ''
        self.last_decode_error: ImageDecodeError | None = None
        # The cameras of the last status: (topic, received, images/s, age in seconds).
        self.last_cameras: list[tuple[str, int, float, float]] = []
        # An input problem since the last status that did not fail a pair ('' if none).
        self.input_warning = ''
        # The last decoded pair's image warning (mono16 range), '' if none.
        self.image_warning = ''
        # The pipeline and configuration (process, update_config); the stamp checks and the
        # synchroniser (receive, update_config).
        self._pipeline_lock = threading.Lock()
        self._input_lock = threading.Lock()
        # A pair that did not decode, merged into the next (merge_dropped): its reset and its
        # gap still count, or the next pair's short gap would hide a long one before it.
        self._undecoded: Pair | None = None

    def update_config(self, config: PlaneNodeConfig) -> None:
        """Use a new configuration from the next message on, keeping the warm start.

        A changed ``sync.*`` makes a new synchroniser (its queues are dropped) with new stamp
        checks for its slop; the counts go on.
        """
        with self._pipeline_lock, self._input_lock:
            if config.sync != self.config.sync:
                self.sync = ApproximateTimeSync(config.sync.slop_s, config.sync.queue_size)
                self.stamp_checks = StampChecks(self.sync.slop_ns, self.counts)
            self.pipeline.update_config(config)
            self.joints.settings = config.head
            self.config = config
            self._shown = (self._shown[0], self.pipeline.state)

    def receive(self, side: Side, stamp_ns: int, msg: Any, now: float
                ) -> tuple[list[Pair], list[str]]:
        """Take one image message: check its stamp, count it, pair it.

        Args:
            side: ``'left'`` or ``'right'``.
            stamp_ns: Its header stamp, nanoseconds.
            msg: The message (kept opaque until :meth:`process` decodes it).
            now: Arrival time in the adapter's clock.

        Returns:
            ``(pairs, warnings)``: the pairs it completed (counted in ``counters.pairs``) and
            the stamp problems it showed (the last is kept for the status).

        """
        self.activity.note_image(side, now)
        with self._input_lock:
            warnings = self.stamp_checks.observe(side, stamp_ns)
            pairs = self.sync.add(side, stamp_ns, msg)
        if warnings:
            self.input_warning = warnings[-1]
        self.counters.pairs += len(pairs)
        self.activity.note_pairs(len(pairs))
        return pairs, warnings

    def process(self, pair: Pair, joint_speed: float | None = None,
                publish: Callable[[ProcessedPair], None] | None = None
                ) -> ProcessedPair | None:
        """Decode a pair, run the pipeline on it and update the bookkeeping.

        The stamp given to the pipeline is the left image's (a stamp jump is ``pair.gap_ns``,
        the cameras' gap, not the time since the last pair processed), and
        ``pair.after_reset`` drops the warm start.

        Args:
            pair: A pair from :meth:`receive` (its items are ``sensor_msgs/Image`` or
                ``CompressedImage`` messages, rosbags or rclpy).
            joint_speed: The head's largest joint speed in rad/s, if known.
            publish: Called with the processed pair before it is counted; the status's
                latency includes it (the node publishes there).

        Returns:
            The processed pair, or None if an image did not decode (counted, and kept in
            :attr:`last_error` and :attr:`last_decode_error`; its reset and its cameras' gap
            go on with the next pair).

        """
        t0 = time.perf_counter()
        bits = self.config.image.mono16_bits
        if self._undecoded is not None:
            pair = merge_dropped(self._undecoded, pair)
        self._undecoded = pair
        try:
            # Read-only, views of the messages' data where the encoding allows (no copy of
            # a 4K frame); the pair holds its messages, which nothing changes.
            left = _read_only(message_to_gray(pair.left, copy=False, mono16_bits=bits))
            right = _read_only(message_to_gray(pair.right, copy=False, mono16_bits=bits))
        except ImageDecodeError as err:
            self._decode_failed(err)
            return None
        self._undecoded = None
        image_warning = self._image_warning(pair, (left, right), bits)
        with self._pipeline_lock:
            result = self.pipeline.process(left, right, pair.left_stamp_ns,
                                           reset=pair.after_reset, joint_speed=joint_speed,
                                           stream_gap_ns=pair.gap_ns)
            state = self.pipeline.state
        frame = ProcessedPair(pair, result, left, 1e3 * (time.perf_counter() - t0),
                              image_warning)
        # Recorded before publishing, so a status built meanwhile (the diagnostics timer)
        # never shows the pipeline's new lock state beside no result.
        self.last_result = result
        self._shown = (result, state)
        self._count(frame)
        if publish is not None:
            publish(frame)
        self.latencies_ms.append(1e3 * (time.perf_counter() - t0))
        self.counters.processed += 1
        return frame

    def _image_warning(self, pair: Pair, grays: tuple[np.ndarray, np.ndarray],
                       bits: int) -> str:
        """Check the range of a pair's mono16 images (mono8 and colour: two string tests)."""
        mono16 = [gray for msg, gray in zip((pair.left, pair.right), grays) if is_mono16(msg)]
        warning = mono16_range_warning(mono16, bits) if mono16 else ''
        self.image_warning = warning
        if warning:
            self.input_warning = warning
        return warning

    def _decode_failed(self, err: ImageDecodeError) -> None:
        self.counters.decode_errors += 1
        self.counters.consecutive_failures += 1
        self.counts.add('decode_' + err.kind)
        self.last_error = clip_text(f'image rejected: {err}', LAST_ERROR_CHARS)
        self.last_decode_error = err
        self.last_result = None
        self._shown = (None, self._shown[1])

    def _count(self, frame: ProcessedPair) -> None:
        result, counters = frame.result, self.counters
        if result.warnings:
            self.input_warning = result.warnings[-1]
        if frame.publishable:
            counters.consecutive_failures = 0
        else:
            counters.consecutive_failures += 1
        if result.ok:
            counters.plane_found += 1
        if isinstance(result.estimate, PlaneEstimate) and result.estimate.converged:
            counters.converged += 1

    def note_internal_error(self, err: BaseException) -> str:
        """Count a pair whose processing raised; return the error as the status shows it."""
        self.counters.internal_errors += 1
        self.last_error = clip_text(f'{type(err).__name__}: {err}', LAST_ERROR_CHARS)
        return self.last_error

    def note_undecodable(self, error: str) -> None:
        """Count a message that could not be deserialised (it never reaches the pairing)."""
        self.counters.undecodable_messages += 1
        self.last_error = clip_text(error, LAST_ERROR_CHARS)

    def status(self, now: float, rate: float | None = None, dropped_busy: int = 0,
               joint_speed: float | None = None, implausible_joint_speed: float | None = None,
               implausible_joint_states: int | None = None,
               silence_hint: Callable[[Sequence[str]], str] | None = None
               ) -> tuple[int, str, list[tuple[str, str]]]:
        """Return the ``/diagnostics`` status and start a new period.

        Args:
            now: The time of the status, in the adapter's clock.
            rate: Pairs per second over the period, if the adapter measures it (default: the
                pairs made since the last status, over the time since then).
            dropped_busy: Pairs the adapter replaced before its worker took them.
            joint_speed: The head's largest joint speed in rad/s, or None.
            implausible_joint_speed: A recent implausible joint speed (rad/s), or None.
            implausible_joint_states: Joint states flagged implausible so far (None: no
                joint input, no key).
            silence_hint: Why the given silent cameras' topics may be silent ('' if not
                known), said after the silence (:func:`plane_status`).

        Returns:
            ``(level, message, values)``, see :func:`plane_status`.

        """
        rate, cameras = self.activity.end_period(now, rate)
        self.last_cameras = cameras
        warning, self.input_warning = self.input_warning, ''
        counters = self.counters
        last_result, lock_state = self._shown
        return plane_status(
            rate=rate, latencies_ms=list(self.latencies_ms), pairs=counters.pairs,
            processed=counters.processed, dropped_busy=dropped_busy,
            dropped_sync=self.sync.stats().dropped,
            decode_errors=counters.decode_errors + counters.undecodable_messages,
            lock_state=lock_state,
            reinitialisations=self.pipeline.stats.reinitialisations,
            consecutive_failures=counters.consecutive_failures, last_result=last_result,
            last_error=self.last_error, input_counts=(self.counts,), input_warning=warning,
            cameras=cameras, silence_s=self.config.transport.silence_s,
            joint_speed=joint_speed, implausible_joint_speed=implausible_joint_speed,
            implausible_joint_states=implausible_joint_states,
            plane=self.config.verification.plane, image_warning=self.image_warning,
            silence_hint=silence_hint, refusals=self.pipeline.stats.refusals)


def _read_only(image: np.ndarray) -> np.ndarray:
    """Return ``image`` marked read-only (the pipeline's checks then keep it uncopied)."""
    image.flags.writeable = False
    return image
