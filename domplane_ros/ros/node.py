"""plane_node: the live ROS 2 adapter around :class:`~domplane_ros.stream.pipeline.PlanePipeline`.

Subscribes to ``left/image_raw`` and ``right/image_raw``, pairs them by stamp, and publishes
``plane/homography``, ``plane/mask``, ``plane/debug_image`` (only while subscribed) and
``/diagnostics``. If ``head.joint_states_topic`` is set, it also subscribes to the head's
``sensor_msgs/JointState``: a fast joint is a hint to the pipeline to expect a big change.
Image callbacks only hand work over: a worker thread processes the newest pair, and a pair
that is replaced before the worker takes it is counted as dropped.
"""

from __future__ import annotations

from collections import deque
import sys
import threading
import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.config import (check_value, ConfigError, PARAMETERS, PARAMETERS_BY_NAME,
                                 PlaneNodeConfig)
from domplane_ros.core.image import message_to_gray
from domplane_ros.errors import ImageDecodeError
from domplane_ros.ros.messages import descriptor, diagnostics_msg, homography_msg, image_msg
from domplane_ros.ros.messages import READ_ONLY
from domplane_ros.stream.health import (homography_problem, new_counts, problem_key, StampChecks,
                                        Throttle)
from domplane_ros.stream.pipeline import debug_overlay, FrameResult, PlanePipeline
from domplane_ros.stream.status import plane_status, STATUS_NAME
from domplane_ros.stream.sync import ApproximateTimeSync, Pair
import numpy as np
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Float64MultiArray

_EMPTY_ARRAY_KINDS = {'floats': Parameter.Type.DOUBLE_ARRAY}
_THROTTLE_S = 5.0


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class PlaneNode(Node):
    """Dominant ground plane and obstacle mask from a stereo pair.

    Raises:
        ConfigError: At construction, when a parameter (from a params file or overrides) is
            invalid; the message names it.

    """

    def __init__(self, **kwargs: Any) -> None:
        """Declare parameters, build the pipeline, publishers, subscriptions and timers."""
        super().__init__('plane_node', **kwargs)
        self._values = self._declare_parameters()
        self.config = PlaneNodeConfig.from_flat(self._values)
        # Guards the pipeline and config changes. Image callbacks never take it (the worker
        # holds it while processing); they take _input_lock (stamp checks, synchroniser).
        self._lock = threading.Lock()
        self._input_lock = threading.Lock()
        self._cv = threading.Condition()       # guards the hand-over slot
        self._pending: Pair | None = None
        self._stop = False
        self.pipeline = PlanePipeline(self.config)
        self._sync = ApproximateTimeSync(self.config.sync.slop_s, self.config.sync.queue_size)
        self._counters = {'pairs': 0, 'processed': 0, 'dropped_busy': 0, 'decode_errors': 0,
                          'consecutive_failures': 0, 'internal_errors': 0}
        # Input problems (see domplane_ros.stream.health): per-message stamp checks, decode errors
        # by kind, one throttle clock per kind of problem, the last warning for diagnostics.
        self._stamp_checks = StampChecks(self._sync.slop_ns)
        self._decode_counts = new_counts()
        self._throttle = Throttle(_THROTTLE_S)
        self._input_warning = ''
        self._latency_ms: deque[float] = deque(maxlen=200)
        self._last_result: FrameResult | None = None
        self._last_error = ''
        self._period_pairs = 0
        self._period_start = time.monotonic()
        self._qos_warned: set[str] = set()
        self._joint_speed: tuple[float, float] | None = None  # (rad/s, monotonic receive time)
        # Per camera: monotonic time of the last image (None: none yet), images this period.
        self._last_image: dict[str, float | None] = {'left': None, 'right': None}
        self._period_images = {'left': 0, 'right': 0}
        self._start = time.monotonic()
        self.add_on_set_parameters_callback(self._on_set_parameters)

        transport = self.config.transport
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=transport.depth,
            reliability=(ReliabilityPolicy.RELIABLE if transport.reliable
                         else ReliabilityPolicy.BEST_EFFORT),
            durability=DurabilityPolicy.VOLATILE)
        self._pub_h = self.create_publisher(Float64MultiArray, 'plane/homography', 10)
        self._pub_mask = self.create_publisher(Image, 'plane/mask', 10)
        self._pub_debug = self.create_publisher(Image, 'plane/debug_image', 2)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._subs = [
            self.create_subscription(
                Image, f'{side}/image_raw', lambda msg, s=side: self._on_image(s, msg), qos,
                event_callbacks=SubscriptionEventCallbacks(
                    incompatible_qos=lambda info, s=side: self._on_incompatible_qos(s, info)))
            for side in ('left', 'right')]
        self._topics = {side: sub.topic_name for side, sub in zip(('left', 'right'), self._subs)}
        self._joint_sub = None
        if self.config.head.joint_states_topic:
            # Sensor-data QoS matches both reliable and best-effort publishers.
            self._joint_sub = self.create_subscription(
                JointState, self.config.head.joint_states_topic, self._on_joint_state,
                qos_profile_sensor_data)
        self._diag_timer = self.create_timer(transport.diagnostics_period_s,
                                             self._publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name='plane_node_worker',
                                        daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'plane_node ready: {self._subs[0].topic_name} + {self._subs[1].topic_name}, '
            f'{"reliable" if transport.reliable else "best-effort"} QoS, '
            f'potential {self.config.estimator.potential}')

    # --- Parameters -------------------------------------------------------------------------
    def _declare_parameters(self) -> dict[str, Any]:
        values: dict[str, Any] = {}
        for spec in PARAMETERS:
            default: Any = spec.default
            if spec.kind in _EMPTY_ARRAY_KINDS and not default:
                default = _EMPTY_ARRAY_KINDS[spec.kind]
            try:
                param = self.declare_parameter(spec.name, default, descriptor(spec))
            except (InvalidParameterTypeException, InvalidParameterValueException,
                    ParameterException) as err:
                # Our validator's message is shorter and says which bound was crossed.
                override = (getattr(self, '_parameter_overrides', None) or {}).get(spec.name)
                if override is not None:
                    check_value(spec, _plain(override.value))
                raise ConfigError(f'parameter {spec.name!r}: {err}') from err
            value = param.value
            if value is None:
                value = spec.default
            values[spec.name] = check_value(spec, _plain(value))
        self._check_unknown_overrides()
        return values

    def _check_unknown_overrides(self) -> None:
        overrides = getattr(self, '_parameter_overrides', {}) or {}
        unknown = sorted(name for name in overrides
                         if name not in PARAMETERS_BY_NAME and name != 'use_sim_time')
        if unknown:
            raise ConfigError(f'unknown parameter {unknown[0]!r}')

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        trial = dict(self._values)
        for param in params:
            if param.name == 'use_sim_time':
                continue
            spec = PARAMETERS_BY_NAME.get(param.name)
            if spec is None:
                return SetParametersResult(successful=False,
                                           reason=f'unknown parameter {param.name!r}')
            if param.name in READ_ONLY:
                return SetParametersResult(
                    successful=False, reason=f'{param.name!r} only takes effect at start-up')
            try:
                trial[param.name] = check_value(spec, _plain(param.value))
            except ConfigError as err:
                return SetParametersResult(successful=False, reason=str(err))
        try:
            config = PlaneNodeConfig.from_flat(trial)
        except ConfigError as err:
            return SetParametersResult(successful=False, reason=str(err))
        with self._lock, self._input_lock:
            if config.sync != self.config.sync:
                self._sync = ApproximateTimeSync(config.sync.slop_s, config.sync.queue_size)
                self._stamp_checks.slop_ns = self._sync.slop_ns
            self.pipeline.update_config(config)
            self.config = config
            self._values = trial
        self.get_logger().info('parameters updated: ' + ', '.join(p.name for p in params))
        return SetParametersResult(successful=True)

    # --- Input -----------------------------------------------------------------------------
    def _on_incompatible_qos(self, side: str, info: Any) -> None:
        if side in self._qos_warned:
            return
        self._qos_warned.add(side)
        wanted = 'reliable' if self.config.transport.reliable else 'best effort'
        self.get_logger().warning(
            f'{side}/image_raw: a publisher offers QoS incompatible with this subscription '
            f'({wanted}; policy id {getattr(info, "last_policy_kind", "?")}); no images will '
            'arrive from it. Set qos.reliable to match the camera driver.')

    def _warn_input(self, message: str, key: str | None = None) -> None:
        """Log an input problem, throttled per kind of problem (``key``, or the message's)."""
        if self._throttle.due(key or problem_key(message), time.monotonic()):
            self.get_logger().warning(message)

    def _on_image(self, side: str, msg: Image) -> None:
        now = time.monotonic()
        last, self._last_image[side] = self._last_image[side], now
        self._period_images[side] += 1
        if last is not None and now - last > self.config.transport.silence_s:
            self.get_logger().info(f'images on {self._topics[side]} again after '
                                   f'{now - last:.1f} s')
        stamp_ns = _stamp_ns(msg)
        with self._input_lock:
            warnings = self._stamp_checks.observe(side, stamp_ns)
            pairs = self._sync.add(side, stamp_ns, msg)
        for warning in warnings:
            self._input_warning = warning
            self._warn_input(warning)
        for pair in pairs:
            with self._cv:
                if self._pending is not None:
                    self._counters['dropped_busy'] += 1
                self._pending = pair
                self._counters['pairs'] += 1
                self._period_pairs += 1
                self._cv.notify()

    def _on_joint_state(self, msg: JointState) -> None:
        velocities = np.asarray(msg.velocity, dtype=np.float64)
        velocities = velocities[np.isfinite(velocities)]
        if velocities.size == 0:
            return  # no velocities: no hint
        self._joint_speed = (float(np.max(np.abs(velocities))), time.monotonic())

    def joint_speed(self) -> float | None:
        """Return the head's latest largest joint speed in rad/s, or None if none is recent."""
        latest = self._joint_speed
        if latest is None or time.monotonic() - latest[1] > self.config.head.max_age_s:
            return None
        return latest[0]

    # --- Processing ----------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            with self._cv:
                while self._pending is None and not self._stop:
                    self._cv.wait(0.2)
                if self._stop:
                    return
                pair, self._pending = self._pending, None
            try:
                self._process(pair)
            except Exception as err:  # noqa: B902 - the worker must survive any one frame
                self._counters['internal_errors'] += 1
                self._last_error = f'{type(err).__name__}: {err}'
                self.get_logger().error(f'frame failed: {self._last_error}',
                                        throttle_duration_sec=_THROTTLE_S)

    def _process(self, pair: Pair) -> None:
        t0 = time.perf_counter()
        try:
            left = message_to_gray(pair.left)
            right = message_to_gray(pair.right)
        except ImageDecodeError as err:
            self._counters['decode_errors'] += 1
            self._counters['consecutive_failures'] += 1
            self._decode_counts['decode_' + err.kind] += 1
            self._last_error = f'image rejected: {err}'
            self._last_result = None
            if self._throttle.due('decode ' + err.kind, time.monotonic()):
                self.get_logger().error(self._last_error)
            return
        with self._lock:
            result = self.pipeline.process(left, right, pair.left_stamp_ns,
                                           reset=pair.after_reset,
                                           joint_speed=self.joint_speed())
        for warning in result.warnings:
            self._input_warning = warning
            self._warn_input(warning)
        header = pair.left.header
        if result.ok and not homography_problem(result.homography):
            self._pub_h.publish(homography_msg(result.homography))
            self._counters['consecutive_failures'] = 0
        else:
            self._counters['consecutive_failures'] += 1
            self._warn_input(f'no plane: {result.reason}',
                             key='no plane ' + problem_key(result.reason))
        self._pub_mask.publish(image_msg(result.mask, header, 'mono8'))
        if self._pub_debug.get_subscription_count() > 0:
            rgb = debug_overlay(left, result)
            self._pub_debug.publish(image_msg(rgb, header, 'rgb8'))
        self._latency_ms.append(1e3 * (time.perf_counter() - t0))
        self._counters['processed'] += 1
        self._last_result = result

    # --- Diagnostics ---------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        elapsed = max(now - self._period_start, 1e-6)
        rate = self._period_pairs / elapsed
        self._period_pairs = 0
        self._period_start = now
        cameras = []
        sync = self._sync.stats()
        for side in ('left', 'right'):
            last = self._last_image[side]
            cameras.append((self._topics[side], getattr(sync, 'received_' + side),
                            self._period_images[side] / elapsed,
                            now - (last if last is not None else self._start)))
            self._period_images[side] = 0
        level, message, values = plane_status(
            rate=rate, latencies_ms=list(self._latency_ms), pairs=self._counters['pairs'],
            processed=self._counters['processed'],
            dropped_busy=self._counters['dropped_busy'],
            dropped_sync=sync.dropped,
            decode_errors=self._counters['decode_errors'], lock_state=self.pipeline.state,
            reinitialisations=self.pipeline.stats.reinitialisations,
            consecutive_failures=self._counters['consecutive_failures'],
            last_result=self._last_result, last_error=self._last_error,
            input_counts=(self.pipeline.checks.counts, self._stamp_checks.counts,
                          self._decode_counts),
            input_warning=self._input_warning, cameras=cameras,
            silence_s=self.config.transport.silence_s, joint_speed=self.joint_speed())
        self._input_warning = ''
        if message.startswith('no images on '):
            self.get_logger().warning(message, throttle_duration_sec=_THROTTLE_S)
        fastest = max(camera[2] for camera in cameras)
        if fastest > 0 and self.config.sync.slop_s >= 0.5 / fastest:
            self.get_logger().warning(
                f'sync.slop_s {self.config.sync.slop_s:g} s is not below half the frame period '
                f'({fastest:.0f} images/s): a frame whose partner was lost can be paired with '
                f'the next frame of the other camera; set sync.slop_s below {0.5 / fastest:.4f}',
                throttle_duration_sec=60.0)
        self._pub_diag.publish(diagnostics_msg(
            self.get_clock().now().to_msg(), STATUS_NAME, self.get_fully_qualified_name(),
            level, message, values))

    def destroy_node(self) -> None:
        """Stop the worker thread, then destroy the node."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._worker.is_alive():
            self._worker.join(timeout=5.0)
        super().destroy_node()


def _plain(value: Any) -> Any:
    """Return ROS parameter values as plain Python (array.array -> list)."""
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return value.tolist()
    return value


def main(args: list[str] | None = None) -> int:
    """Run plane_node until Ctrl-C or an external shutdown.

    Returns:
        0 on a clean shutdown, 2 on an invalid parameter.

    """
    rclpy.init(args=args)
    try:
        node = PlaneNode()
    except ConfigError as err:
        print(f'plane_node: {err}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
