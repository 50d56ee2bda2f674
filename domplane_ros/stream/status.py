"""The plane_node status, shared by the live node and the offline replay (no ROS imports)."""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from domplane_ros.stream.health import input_diagnostic_values
import numpy as np

# diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2
STATUS_NAME = 'plane_node: dominant plane'
# Level ERROR after this many pairs in a row without a plane.
FAILURES_FOR_ERROR = 3


def plane_status(*, rate: float, latencies_ms: Sequence[float], pairs: int, processed: int,
                 dropped_busy: int, dropped_sync: int, decode_errors: int, lock_state: str,
                 reinitialisations: int, consecutive_failures: int, last_result: Any,
                 last_error: str, input_counts: Sequence[Mapping[str, int]] = (),
                 input_warning: str = '', cameras: Sequence[tuple[str, int, float, float]] = (),
                 silence_s: float = math.inf, joint_speed: float | None = None
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
        lock_state: The pipeline's lock state: ``'locked'``, ``'tracking'`` or
            ``'searching'``.
        reinitialisations: Prior searches started.
        consecutive_failures: Processed pairs in a row without a plane.
        last_result: The last :class:`~domplane_ros.stream.pipeline.FrameResult`, or None (also
            when the last pair could not be decoded).
        last_error: The last error message ('' if none).
        input_counts: Counts of input problems (see :mod:`domplane_ros.stream.health`), summed and
            shown one key per kind.
        input_warning: An input problem seen since the last status that did not fail a pair
            (a zero stamp, a stamp jump, stamp skew beyond the slop); it makes an OK status a
            WARN and is appended to the message.
        cameras: Per camera ``(topic, images received, images per second over the last
            period, seconds since its last image (or since start))``; wall time in the node,
            header-stamp time in the replay.
        silence_s: A camera silent for longer than this makes the status WARN, naming it.
        joint_speed: The head's largest joint speed in rad/s, or None without joint input.

    Returns:
        ``(level, message, values)``: level 0 OK, 1 WARN (a silent camera, no input, the last
        pair had no plane, or an input warning) or 2 ERROR (``FAILURES_FOR_ERROR`` pairs in a
        row without a plane); a one-line message; key/value pairs as strings.

    """
    lat = np.asarray(latencies_ms, dtype=np.float64) if len(latencies_ms) else np.zeros(1)
    result = last_result
    # The last pair's failure: the pipeline's reason, or (no result: it was not decoded) the
    # last error.
    reason = result.reason if result is not None and not result.ok else last_error
    silent = [(topic, age) for topic, _, _, age in cameras if age > silence_s]
    if silent:
        level, message = WARN, 'no images on ' + ', '.join(
            f'{topic} for {age:.1f} s' for topic, age in silent)
    elif rate == 0.0:
        level, message = WARN, 'no stereo pairs received'
    elif consecutive_failures >= FAILURES_FOR_ERROR:
        level, message = ERROR, f'no plane for {consecutive_failures} pairs: {reason}'
    elif consecutive_failures > 0 or (result is not None and not result.ok):
        level, message = WARN, f'no plane: {reason}'
    else:
        level, message = OK, 'plane ' + lock_state
    if input_warning:
        level = max(level, WARN)
        message += f'; {input_warning}'
    ok = result is not None and result.ok
    values = [
        ('input rate [pairs/s]', f'{rate:.2f}'),
        ('processing latency median [ms]', f'{np.median(lat):.2f}'),
        ('processing latency p95 [ms]', f'{np.percentile(lat, 95):.2f}'),
        ('pairs', pairs),
        ('processed pairs', processed),
        ('dropped pairs (busy)', dropped_busy),
        ('dropped frames (sync)', dropped_sync),
        ('decode errors', decode_errors),
        ('lock state', lock_state),
        ('warm start', (result.warm_start or 'none') if result is not None else 'none'),
        ('prior candidates (last frame)', result.candidates if result is not None else 0),
        ('head joint speed [rad/s]', 'n/a' if joint_speed is None else f'{joint_speed:.3f}'),
        ('inliers', result.n_inliers if result is not None else 0),
        ('final energy', f'{result.estimate.final_energy:.4g}' if ok else 'n/a'),
        ('converged', bool(ok and result.estimate.converged)),
        ('re-initialisations', reinitialisations),
        ('last error', last_error or 'none'),
    ]
    values += input_diagnostic_values(*input_counts)
    for topic, received, camera_rate, age in cameras:
        values += [(f'{topic} images received', received),
                   (f'{topic} rate [images/s]', f'{camera_rate:.2f}'),
                   (f'{topic} last image age [s]', f'{age:.2f}')]
    return level, message, [(key, str(value)) for key, value in values]
