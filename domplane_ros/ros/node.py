"""plane_node: the live ROS 2 adapter around :class:`~domplane_ros.stream.session.StreamSession`.

Subscribes to ``left/image_raw`` and ``right/image_raw`` (or, with ``image_transport``
``compressed``, to ``<topic>/compressed`` of those topics after remapping, as image_transport
does), pairs them by stamp, and publishes ``plane/result`` (the stamped result of every pair),
``plane/homography``, ``plane/mask``, ``plane/debug_image`` and ``plane/parallax`` (both only
while subscribed) and ``/diagnostics``. If ``camera_info.topic`` is set, the left camera's K
narrows the prior. If ``head.joint_states_topic`` is set, it also subscribes to the head's
``sensor_msgs/JointState``: a fast joint is a hint to the pipeline to expect a big change.
Image callbacks only hand work over: a worker thread processes the newest pair, and a pair
that is replaced before the worker takes it is counted as dropped (:class:`NewestSlot`).
The session keeps every count and builds the status; the node decodes nothing itself.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.config import (check_value, ConfigError, PARAMETERS, PARAMETERS_BY_NAME,
                                 PlaneNodeConfig, unknown_parameter_message)
from domplane_ros.ros.camera_info import camera_model, CameraInfoTracker
from domplane_ros.ros.handover import NewestSlot
from domplane_ros.ros.messages import descriptor, diagnostics_msg, homography_msg, image_msg
from domplane_ros.ros.messages import parallax_msg, READ_ONLY, result_msg
from domplane_ros.ros.startup import check_params_files, init_rclpy
from domplane_ros.ros.usage import usage, wants_help
from domplane_ros.ros.wire import image_from_cdr
from domplane_ros.stream.frame import parallax_image
from domplane_ros.stream.health import problem_key, Throttle
from domplane_ros.stream.pipeline import debug_overlay, PlanePipeline
from domplane_ros.stream.session import ProcessedPair, SIDES, StreamSession
from domplane_ros.stream.status import STATUS_NAME
from domplane_ros.stream.sync import merge_dropped, Pair
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException, ParameterNotDeclaredException)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from std_msgs.msg import Float64MultiArray

_THROTTLE_S = 5.0


class UnknownParameterError(ParameterNotDeclaredException):
    """A parameter that is not declared was set; the message names the nearest declared one."""

    def __init__(self, name: str) -> None:
        """Make the error of the undeclared parameter ``name``."""
        Exception.__init__(self, unknown_parameter_message(name))


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class PlaneNode(Node):
    """Dominant ground plane and obstacle mask from a stereo pair.

    Attributes:
        session: The stream's :class:`~domplane_ros.stream.session.StreamSession` (pipeline,
            synchroniser, counters, status).
        slot: The newest-wins hand-over to the worker; ``slot.dropped`` counts the pairs
            replaced before the worker took them (their stream gaps and resets are kept in the
            pair that replaced them: a search longer than ``pipeline.max_stamp_jump_s`` does
            not drop the warm start).

    Raises:
        ConfigError: At construction, when a parameter (from a params file or overrides) is
            invalid; the message names it.

    """

    def __init__(self, **kwargs: Any) -> None:
        """Declare parameters, build the session, publishers, subscriptions and timers."""
        super().__init__('plane_node', **kwargs)
        self._values = self._declare_parameters()
        config = PlaneNodeConfig.from_flat(self._values)
        self.slot: NewestSlot[Pair] = NewestSlot(merge=merge_dropped)
        self._stopping = False
        self._throttle = Throttle(_THROTTLE_S)
        self._qos_warned: set[str] = set()
        self._camera_info = CameraInfoTracker()
        self._make_publishers()
        self._subs = self._make_subscriptions(config)
        topics = tuple(sub.topic_name for sub in self._subs)
        self.session = StreamSession(config, topics, start=time.monotonic())
        self.add_pre_set_parameters_callback(self._refuse_unknown)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._diag_timer = self.create_timer(config.transport.diagnostics_period_s,
                                             self.publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name='plane_node_worker',
                                        daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'plane_node ready: {topics[0]} + {topics[1]}, '
            f'{config.transport.image_transport}, '
            f'{"reliable" if config.transport.reliable else "best-effort"} QoS, '
            f'potential {config.estimator.potential}')

    @property
    def config(self) -> PlaneNodeConfig:
        """Return the configuration in force."""
        return self.session.config

    @property
    def pipeline(self) -> PlanePipeline:
        """Return the session's pipeline."""
        return self.session.pipeline

    def _make_publishers(self) -> None:
        self._pub_result = self.create_publisher(DiagnosticArray, 'plane/result', 10)
        self._pub_h = self.create_publisher(Float64MultiArray, 'plane/homography', 10)
        self._pub_mask = self.create_publisher(Image, 'plane/mask', 10)
        self._pub_debug = self.create_publisher(Image, 'plane/debug_image', 2)
        self._pub_parallax = self.create_publisher(Image, 'plane/parallax', 2)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)

    def _make_subscriptions(self, config: PlaneNodeConfig) -> list[Any]:
        transport = config.transport
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=transport.depth,
            reliability=(ReliabilityPolicy.RELIABLE if transport.reliable
                         else ReliabilityPolicy.BEST_EFFORT),
            durability=DurabilityPolicy.VOLATILE)
        # image_transport's convention: the compressed stream of a (remapped) image topic T
        # is T/compressed, so remapping left/image_raw serves both transports.
        compressed = transport.image_transport == 'compressed'
        # Raw images arrive serialised (raw=True) and are read in place (ros/wire.py): rclpy
        # would turn every one into a Python message, also those the hand-over drops.
        subs = [
            self.create_subscription(
                CompressedImage if compressed else Image,
                (self.resolve_topic_name(f'{side}/image_raw') + '/compressed' if compressed
                 else f'{side}/image_raw'),
                ((lambda msg, s=side: self.on_image(s, msg)) if compressed
                 else (lambda raw, s=side: self._on_serialised_image(s, raw))), qos,
                event_callbacks=SubscriptionEventCallbacks(
                    incompatible_qos=lambda info, s=side: self._on_incompatible_qos(s, info)),
                raw=not compressed)
            for side in SIDES]
        self._camera_info_sub = None
        if transport.camera_info_topic:
            self._camera_info_sub = self.create_subscription(
                CameraInfo, transport.camera_info_topic, self._on_camera_info,
                qos_profile_sensor_data)
        self._joint_sub = None
        if config.head.joint_states_topic:
            # Sensor-data QoS matches both reliable and best-effort publishers.
            self._joint_sub = self.create_subscription(
                JointState, config.head.joint_states_topic, self._on_joint_state,
                qos_profile_sensor_data)
        return subs

    # --- Parameters -------------------------------------------------------------------------
    def _declare_parameters(self) -> dict[str, Any]:
        values: dict[str, Any] = {}
        for spec in PARAMETERS:
            default: Any = spec.default
            if isinstance(default, list) and not default:
                default = None   # unset: an empty list has no type to declare
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

    def _refuse_unknown(self, parameter_list: list[Parameter]) -> list[Parameter]:
        # A pre-set callback runs before rclpy's own undeclared check, which refuses an
        # undeclared name with 'Invalid access to undeclared parameter(s): []' (its generator
        # is spent by then): ros2 param set gets the name and the nearest declared one instead.
        for param in parameter_list:
            if not self.has_parameter(param.name):
                raise UnknownParameterError(param.name)
        return list(parameter_list)

    def _check_unknown_overrides(self) -> None:
        overrides = getattr(self, '_parameter_overrides', {}) or {}
        unknown = sorted(name for name in overrides
                         if name not in PARAMETERS_BY_NAME and name != 'use_sim_time')
        if unknown:
            raise ConfigError(unknown_parameter_message(unknown[0]))

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        trial = dict(self._values)
        for param in params:
            if param.name == 'use_sim_time':
                continue
            spec = PARAMETERS_BY_NAME.get(param.name)
            if spec is None:
                return SetParametersResult(successful=False,
                                           reason=unknown_parameter_message(param.name))
            if param.name in READ_ONLY:
                return SetParametersResult(
                    successful=False, reason=f'{param.name!r} only takes effect at start-up')
            value = _plain(param.value)
            if value is None and isinstance(spec.default, list):
                value = []   # unset again: back to the default, empty
            try:
                trial[param.name] = check_value(spec, value)
            except ConfigError as err:
                return SetParametersResult(successful=False, reason=str(err))
        try:
            config = PlaneNodeConfig.from_flat(trial)
        except ConfigError as err:
            return SetParametersResult(successful=False, reason=str(err))
        self.session.update_config(config)
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
            f'{self.session.activity.topics[side]}: a publisher offers QoS incompatible with '
            f'this subscription ({wanted}; policy id {getattr(info, "last_policy_kind", "?")}); '
            'no images will arrive from it. Set qos.reliable to match the camera driver.')

    def _warn_input(self, message: str, key: str | None = None) -> None:
        """Log an input problem, throttled per kind of problem (``key``, or the message's)."""
        if self._throttle.due(key or problem_key(message), time.monotonic()):
            self.get_logger().warning(message)

    def on_image(self, side: str, msg: Image) -> None:
        """Take one image (the subscriptions' callback): pair it, hand pairs to the worker."""
        now = time.monotonic()
        last = self.session.activity.last_seen(side)
        if last is not None and now - last > self.config.transport.silence_s:
            self.get_logger().info(f'images on {self.session.activity.topics[side]} again '
                                   f'after {now - last:.1f} s')
        pairs, warnings = self.session.receive(side, _stamp_ns(msg), msg, now)
        for warning in warnings:
            self._warn_input(warning)
        for pair in pairs:
            self.slot.put(pair)

    def _incompatible_qos_hint(self, silent_topics: Sequence[str]) -> str:
        """Say which silent topics had a publisher of incompatible QoS ('' if none).

        The log said it once, at discovery; the status says it while the silence lasts.
        """
        topics = [self.session.activity.topics[side] for side in SIDES if side in self._qos_warned
                  and self.session.activity.topics[side] in silent_topics]
        if not topics:
            return ''
        wanted = 'reliable' if self.config.transport.reliable else 'best effort'
        return (f'a publisher on {", ".join(topics)} offers QoS incompatible with this '
                f'{wanted} subscription: set qos.reliable to match it')

    def _on_serialised_image(self, side: str, raw: bytes) -> None:
        """Take one serialised image: read its fields in place, then as :meth:`on_image`."""
        try:
            msg = image_from_cdr(raw)
        except Exception as err:  # noqa: B902 - rclpy raises its own types for bad bytes
            error = f'{self.session.activity.topics[side]}: undecodable image message: {err}'
            self.session.note_undecodable(error)
            self._warn_input(error, key='undecodable ' + side)
            return
        self.on_image(side, msg)

    def _on_camera_info(self, msg: CameraInfo) -> None:
        """Narrow the prior from the left camera's K (once per distinct K)."""
        try:
            model = camera_model(msg)
        except ValueError as err:
            self._warn_input(f'{self.config.transport.camera_info_topic}: {err}; ignored, the '
                             'prior stays as configured', key='camera_info')
            return
        tolerance = self.config.transport.camera_info_focal_tolerance
        values = self._camera_info.new_values(model, tolerance)
        if values is None:
            return
        configured = self.config.prior.focal_px
        results = self.set_parameters([Parameter(name, value=value)
                                       for name, value in values.items()])
        failed = [r.reason for r in results if not r.successful]
        if failed:
            self.get_logger().error(f'camera_info not applied to the prior: {failed[0]}')
            return
        note = ('' if configured[0] <= model.focal_px <= configured[1] else
                f"; K's focal length is outside the configured [{configured[0]:g}, "
                f'{configured[1]:g}]')
        self.get_logger().info(self._camera_info.describe(model, values, tolerance) + note)

    def _on_joint_state(self, msg: JointState) -> None:
        warning = self.session.joints.observe(msg.velocity, msg.name, time.monotonic())
        if warning:
            self._warn_input(warning, key='implausible joint speed')

    @property
    def implausible_joint_states(self) -> int:
        """Return how many joint states were flagged implausible so far."""
        return self.session.joints.implausible_count

    def joint_speed(self) -> float | None:
        """Return the head's latest largest joint speed in rad/s, or None if none is recent.

        Implausible speeds (above ``head.max_joint_velocity``) are never returned.
        """
        return self.session.joints.speed(time.monotonic())

    def implausible_joint_speed(self) -> float | None:
        """Return a recent joint speed above ``head.max_joint_velocity`` (rad/s), or None."""
        return self.session.joints.implausible_speed(time.monotonic())

    # --- Processing ----------------------------------------------------------------------
    def _work(self) -> None:
        while (pair := self.slot.take()) is not None:
            try:
                self.process_pair(pair)
            except Exception as err:  # noqa: B902 - the worker must survive any one frame
                if self._stopping or not self.context.ok():
                    # Shutdown (Ctrl-C, SIGTERM, destroy_node) while a pair was in flight:
                    # its outputs can no longer be published. Not an error.
                    self.get_logger().info(
                        'shutting down: the pair in flight (stamp '
                        f'{pair.left_stamp_ns / 1e9:.3f} s) was cut short, nothing published')
                    return
                error = self.session.note_internal_error(err)
                self.get_logger().error(f'frame failed: {error}',
                                        throttle_duration_sec=_THROTTLE_S)

    def process_pair(self, pair: Pair) -> None:
        """Process one pair and publish its outputs (the worker's step; it may raise)."""
        frame = self.session.process(pair, self.joint_speed(), publish=self._publish)
        if frame is None:
            kind = self.session.last_decode_error.kind
            if self._throttle.due('decode ' + kind, time.monotonic()):
                self.get_logger().error(self.session.last_error)

    def process_pending(self) -> bool:
        """Process the pair waiting in :attr:`slot` in this thread, if any.

        For tests and tools that drive the node step by step after :meth:`stop_worker`.

        Returns:
            Whether a pair was waiting.

        """
        pair = self.slot.take_nowait()
        if pair is not None:
            self.process_pair(pair)
        return pair is not None

    def _publish(self, frame: ProcessedPair) -> None:
        result = frame.result
        for warning in result.warnings:
            self._warn_input(warning)
        if frame.image_warning:
            self._warn_input(frame.image_warning, key='mono16 range')
        header = frame.pair.left.header
        if frame.publishable:
            self._pub_h.publish(homography_msg(result.homography))
        else:
            self._warn_input(f'no plane: {result.reason}',
                             key='no plane ' + problem_key(result.reason))
        self._pub_result.publish(result_msg(header, self.get_fully_qualified_name(), frame))
        self._pub_mask.publish(image_msg(result.mask, header, 'mono8'))
        if self._pub_debug.get_subscription_count() > 0:
            rgb = debug_overlay(frame.left, result)
            self._pub_debug.publish(image_msg(rgb, header, 'rgb8'))
        if self._pub_parallax.get_subscription_count() > 0:
            self._pub_parallax.publish(parallax_msg(parallax_image(result), header))

    # --- Diagnostics ---------------------------------------------------------------------
    def publish_diagnostics(self) -> None:
        """Publish the status now (the diagnostics timer's callback); a new period starts."""
        level, message, values = self.session.status(
            time.monotonic(), dropped_busy=self.slot.dropped, joint_speed=self.joint_speed(),
            implausible_joint_speed=self.implausible_joint_speed(),
            # Counted only with a joint topic, as in the replay.
            implausible_joint_states=(self.implausible_joint_states
                                      if self._joint_sub is not None else None),
            silence_hint=self._incompatible_qos_hint)
        if message.startswith('no images on '):
            self.get_logger().warning(message, throttle_duration_sec=_THROTTLE_S)
        fastest = max(camera[2] for camera in self.session.last_cameras)
        slop_s = self.config.sync.slop_s
        if fastest > 0 and slop_s >= 0.5 / fastest:
            self.get_logger().warning(
                f'sync.slop_s {slop_s:g} s is not below half the frame period '
                f'({fastest:.0f} images/s): a frame whose partner was lost can be paired with '
                f'the next frame of the other camera; set sync.slop_s below {0.5 / fastest:.4f}',
                throttle_duration_sec=60.0)
        self._pub_diag.publish(diagnostics_msg(
            self.get_clock().now().to_msg(), STATUS_NAME, self.get_fully_qualified_name(),
            level, message, values))

    def stop_worker(self) -> None:
        """Stop the worker thread; pairs then wait in :attr:`slot` (see process_pending)."""
        self._stopping = True
        self.slot.close()
        if self._worker.is_alive() and self._worker is not threading.current_thread():
            self._worker.join(timeout=5.0)
            if self._worker.is_alive():
                self.get_logger().info('shutting down: the pair in flight was cut short after '
                                       '5 s, nothing more is published')

    def destroy_node(self) -> None:
        """Stop the worker thread, then destroy the node."""
        self.stop_worker()
        super().destroy_node()


def _plain(value: Any) -> Any:
    """Return ROS parameter values as plain Python (array.array -> list)."""
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return value.tolist()
    return value


def main(args: list[str] | None = None) -> int:
    """Run plane_node until Ctrl-C or an external shutdown.

    Args:
        args: The command line (``sys.argv`` when None); ``-h`` or ``--help`` before
            ``--ros-args`` prints the usage and the parameters and starts no node.

    Returns:
        0 on a clean shutdown (Ctrl-C included) or after ``--help``, 2 on an invalid
        parameter, parameters file or ROS argument (one line on stderr).

    """
    if wants_help(sys.argv if args is None else args):
        print(usage())
        return 0
    try:
        check_params_files(sys.argv if args is None else args)
        init_rclpy(args)
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
