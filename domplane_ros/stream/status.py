"""The plane_node status, shared by the live node and the offline replay (no ROS imports)."""

from __future__ import annotations

import json
import math
from typing import Any, Callable, Mapping, Sequence

from domplane_ros.stream.candidates import PHOTOMETRIC
from domplane_ros.stream.health import input_diagnostic_values
from domplane_ros.stream.refusals import lock_lost_text, RefusalCounts, refusals_text
import numpy as np

# diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2
STATUS_NAME = 'plane_node: dominant plane'
# Level ERROR after this many pairs in a row without a plane.
FAILURES_FOR_ERROR = 3
JOINT_SPEED_KEY = 'head joint speed [rad/s]'


# What ``plane sought`` says for each ``verification.plane``.
PLANE_SOUGHT = {'ground': 'ground (swapped cameras detected)',
                'any': 'any (ground and swap checks off: swapped cameras not detected)'}


def plane_status(*, rate: float, latencies_ms: Sequence[float], pairs: int, processed: int,
                 dropped_busy: int, dropped_sync: int, decode_errors: int, lock_state: str,
                 reinitialisations: int, consecutive_failures: int, last_result: Any,
                 last_error: str, input_counts: Sequence[Mapping[str, int]] = (),
                 input_warning: str = '', cameras: Sequence[tuple[str, int, float, float]] = (),
                 silence_s: float = math.inf, joint_speed: float | None = None,
                 implausible_joint_speed: float | None = None,
                 implausible_joint_states: int | None = None, plane: str = 'ground',
                 image_warning: str = '',
                 silence_hint: Callable[[Sequence[str]], str] | None = None,
                 refusals: RefusalCounts | None = None
                 ) -> tuple[int, str, list[tuple[str, str]]]:
    """Return the node's diagnostics status.

    Args:
        rate: Stereo pairs per second over the last period.
        latencies_ms: Recent per-pair processing latencies, milliseconds.
        pairs: Pairs made by the synchroniser.
        processed: Pairs processed.
        dropped_busy: Pairs replaced before the worker took them.
        dropped_sync: Frames dropped by the synchroniser.
        decode_errors: Images rejected by the decoder.
        lock_state: The pipeline's lock state (``'locked'``, ``'tracking'``, ``'searching'``).
        reinitialisations: Prior searches started.
        consecutive_failures: Processed pairs in a row without a plane.
        last_result: The last ``FrameResult``, or None (also if the last pair did not decode).
        last_error: The last error message ('' if none).
        input_counts: Input problem counts (:mod:`~domplane_ros.stream.health`), summed.
        input_warning: An input problem seen since the last status that did not fail a pair
            (a zero stamp, a stamp jump, stamp skew beyond the slop); it makes an OK status a
            WARN and is appended to the message.
        cameras: Per camera ``(topic, images received, images per second over the last
            period, seconds since its last image (or since start))``; wall time in the node,
            header-stamp time in the replay.
        silence_s: A camera silent for longer than this makes the status WARN, naming it.
        joint_speed: The head's largest joint speed in rad/s, or None without joint input.
        implausible_joint_speed: A recent joint speed above ``head.max_joint_velocity``
            (rad/s), ignored as a hint; shown instead of the joint speed.
        implausible_joint_states: Joint states with such a speed so far, or None without
            joint input (``head.joint_states_topic`` not set: then the key ``joint states
            implausible`` is left out, in the node and the replay alike).
        plane: ``verification.plane``; shown as ``plane sought``, with what ``any`` turns off.
        image_warning: The last pair's image warning (mono16 data far below
            ``image.mono16_bits``), shown as ``image warning`` ('none' if '').
        silence_hint: Given the silent cameras' topics, why they may be silent ('' if the
            adapter knows nothing; the node: a publisher with incompatible QoS), said after
            the silence.
        refusals: Lock losses and refusals since start (:mod:`~domplane_ros.stream.refusals`);
            with the last result's lock loss they follow ``re-initialisations`` (None: no keys).

    Returns:
        ``(level, message, values)``: level 0 OK, 1 WARN (a silent camera, no input, the last
        pair had no plane, or an input warning) or 2 ERROR (``FAILURES_FOR_ERROR`` pairs in a
        row without a plane, also while the cameras are silent after them); a one-line
        message; key/value pairs as strings. Silence or no input after pairs without a plane
        says both: ``no images on ... for 3.0 s; last pairs: no plane for 3 pairs: ...``.

    """
    level, message = _level_and_message(rate, consecutive_failures, last_result,
                                        _failure_reason(last_result, last_error), lock_state,
                                        cameras, silence_s, silence_hint)
    if input_warning:
        level = max(level, WARN)
        message += f'; {input_warning}'
    values = [
        ('input rate [pairs/s]', format_number(rate)),
        *_latency_values(latencies_ms),
        ('pairs', pairs),
        ('processed pairs', processed),
        ('dropped pairs (busy)', dropped_busy),
        ('dropped frames (sync)', dropped_sync),
        ('decode errors', decode_errors),
        ('lock state', lock_state),
        ('plane sought', PLANE_SOUGHT.get(plane, plane)),
        *_result_values(last_result, joint_speed, implausible_joint_speed),
        *([('joint states implausible', implausible_joint_states)]
          if implausible_joint_states is not None else []),
        ('re-initialisations', reinitialisations),
        *(refusals.diagnostic_values(getattr(last_result, 'lock_lost', None))
          if refusals is not None else []),
        ('last error', last_error or 'none'),
        ('image warning', image_warning or 'none'),
    ]
    values += input_diagnostic_values(*input_counts) + _camera_values(cameras)
    return level, message, [(key, str(value)) for key, value in values]


def format_number(value: float, decimals: int = 2) -> str:
    """Format a diagnostics number: fixed decimals up to 1e6, else 4 significant digits.

    A value from the wire (a joint velocity of 1e308, a stamp years off) stays short:
    ``format_number(1e308)`` is ``'1.000e+308'``, not 309 digits.

    Args:
        value: The number.
        decimals: Decimals below 1e6.

    Returns:
        The text (``'nan'``, ``'inf'`` or ``'-inf'`` for non-finite values).

    """
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    if abs(value) >= 1e6:
        return f'{value:.3e}'
    return f'{value:.{decimals}f}'


def _camera_values(cameras: Sequence[tuple[str, int, float, float]]) -> list[tuple[str, Any]]:
    values: list[tuple[str, Any]] = []
    for topic, received, camera_rate, age in cameras:
        values += [(f'{topic} images received', received),
                   (f'{topic} rate [images/s]', format_number(camera_rate)),
                   (f'{topic} last image age [s]', format_number(age))]
    return values


def _failure_reason(result: Any, last_error: str) -> str:
    """Return the last pair's failure: the pipeline's reason or (not decoded) the last error."""
    return result.reason if result is not None and not result.ok else last_error


def _level_and_message(rate: float, consecutive_failures: int, result: Any, reason: str,
                       lock_state: str, cameras: Sequence[tuple[str, int, float, float]],
                       silence_s: float,
                       silence_hint: Callable[[Sequence[str]], str] | None = None
                       ) -> tuple[int, str]:
    """Return the status's level and message: no input first, with the last pairs' state.

    Silence (or no pairs) after pairs without a plane keeps the worse level and both
    reasons: the cameras stopping does not hide that the last pairs had no plane.
    """
    silent = [(topic, age) for topic, _, _, age in cameras if age > silence_s]
    no_input = ''
    if silent:
        no_input = 'no images on ' + ', '.join(
            f'{topic} for {format_number(age, 1)} s' for topic, age in silent)
        hint = silence_hint([topic for topic, _ in silent]) if silence_hint else ''
        if hint:
            no_input += '; ' + hint
    elif rate == 0.0:
        no_input = 'no stereo pairs received'
    level, message = _plane_level_and_message(consecutive_failures, result, reason, lock_state)
    if not no_input:
        return level, message
    if level == OK:
        return WARN, no_input
    return max(level, WARN), f'{no_input}; last pairs: {message}'


def _plane_level_and_message(consecutive_failures: int, result: Any, reason: str,
                             lock_state: str) -> tuple[int, str]:
    """Return the level and message of the last pairs' plane state."""
    if consecutive_failures >= FAILURES_FOR_ERROR:
        return ERROR, f'no plane for {consecutive_failures} pairs: {reason}'
    if consecutive_failures > 0 or (result is not None and not result.ok):
        return WARN, f'no plane: {reason}'
    return OK, 'plane ' + lock_state


def _latency_values(latencies_ms: Sequence[float]) -> list[tuple[str, str]]:
    lat = np.asarray(latencies_ms, dtype=np.float64) if len(latencies_ms) else np.zeros(1)
    return [('processing latency median [ms]', format_number(np.median(lat))),
            ('processing latency p95 [ms]', format_number(np.percentile(lat, 95)))]


def _joint_speed_text(speed: float | None, implausible: float | None) -> str:
    if implausible is not None:
        return f'implausible: {format_number(implausible, 3)} (ignored)'
    return 'n/a' if speed is None else format_number(speed, 3)


def _result_values(result: Any, joint_speed: float | None,
                   implausible_joint_speed: float | None = None) -> list[tuple[str, Any]]:
    """Return the last result's keys, from 'warm start' to 'converged'.

    'plane confidence' is the published plane's verification confidence in [0, 1] (0.5 at
    ``verification.min_score``); 0 when no plane was published.
    """
    ok = result is not None and result.ok
    # A photometric plane (too few corners) has no point energy: 'n/a', not 0.
    energy = ok and result.estimate.potential != PHOTOMETRIC
    return [
        ('warm start', (result.warm_start or 'none') if result is not None else 'none'),
        ('plane confidence', f'{result.confidence:.2f}' if ok else '0.00'),
        ('prior candidates (last frame)', result.candidates if result is not None else 0),
        (JOINT_SPEED_KEY, _joint_speed_text(joint_speed, implausible_joint_speed)),
        ('inliers', result.n_inliers if result is not None else 0),
        ('final energy', f'{result.estimate.final_energy:.4g}' if energy else 'n/a'),
        ('converged', bool(ok and result.estimate.converged)),
    ]


# The reason's hint for swapped cameras names the node's and the replay's inputs, the image
# topics (stream/trust.py); plane_pair's inputs are its LEFT and RIGHT arguments.
SWAP_HINT_TOPICS = 'swap the image topics'
SWAP_HINT_ARGUMENTS = 'swap the LEFT and RIGHT arguments'


def reason_for_arguments(reason: str) -> str:
    """Return a reason as plane_pair prints it: the swap hint names its arguments, not topics.

    The reason itself (CSV, ``plane/result``, ``/diagnostics``) is the same for every tool;
    only the hint at its end changes.
    """
    return reason.replace(SWAP_HINT_TOPICS, SWAP_HINT_ARGUMENTS)


RESULT_STATUS_NAME = 'plane'
"""``DiagnosticStatus.name`` of the per-pair result (``plane/result``)."""


def result_status(frame: Any) -> tuple[int, str, list[tuple[str, str]]]:
    """Return the per-pair result's level, message and values (``plane/result``).

    The level is OK with a published plane, WARN without; the message is the lock state
    (and the reason when there is no plane). The values, all strings: ``state`` (locked,
    tracking, searching), ``plane`` (true or false), ``confidence`` (0 to 1; 0 without a
    plane), ``homography`` (a JSON list of the 9 row-major values of H, left pixel to right
    pixel with ``H[2][2] = 1``; ``[]`` without a plane), ``reason`` ('' with a plane),
    ``lock_lost`` (why the lock held before the pair was lost in it, ``kind: reason``, '' if
    not; a lock lost and re-found in the same pair has a plane and this) and ``refusals``
    (every refusal of the pair, a JSON list of ``kind: reason``; the replay CSV's columns).

    Args:
        frame: A :class:`~domplane_ros.stream.session.ProcessedPair` (``result``,
            ``publishable``).

    Returns:
        ``(level, message, values)``; the node and the replay build their message from it.

    """
    result = frame.result
    plane = bool(frame.publishable)
    values = ([float(v) for v in np.asarray(result.homography, dtype=np.float64).ravel()]
              if plane else [])
    reason = '' if plane else (result.reason or 'homography not finite')
    message = result.state if plane else f'{result.state}: {reason}'
    return (OK if plane else WARN, message, [
        ('state', result.state),
        ('plane', 'true' if plane else 'false'),
        ('confidence', repr(float(result.confidence) if plane else 0.0)),
        ('homography', json.dumps(values)),
        ('reason', reason),
        ('lock_lost', lock_lost_text(result.lock_lost)),
        ('refusals', refusals_text(result.refusals))])
