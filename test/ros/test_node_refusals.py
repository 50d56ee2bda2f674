"""The live node over DDS says when a lock was lost and re-found in the same pair.

The node runs with the documented default prior; the pairs are sent one at a time (each
waits for its mask), so the node sees every pair in order, as the replay does.
"""

from __future__ import annotations

import json
import time

from diagnostic_msgs.msg import DiagnosticArray
from domplane_ros.sim.rigs import plane_error_px
from rclpy.parameter import Parameter
from test_node import _image, Harness
from truth import drifting_lock_frames

STAMP0_NS = 1_700_000_000_000_000_000
PERIOD_NS = 33_333_333


def _stamps(messages) -> list[int]:
    return [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in messages]


def _send(h: Harness, frame, stamp: int) -> None:
    for _attempt in range(5):   # a pair lost on the best-effort link is sent again
        h.pub_left.publish(_image(frame.left, stamp, 'left_cam'))
        h.pub_right.publish(_image(frame.right, stamp + 1000, 'right_cam'))
        deadline = time.monotonic() + 8.0
        while time.monotonic() < deadline and stamp not in _stamps(h.masks):
            h.executor.spin_once(timeout_sec=0.02)
        if stamp in _stamps(h.masks):
            return
    raise AssertionError(f'no mask for the pair stamped {stamp}')


def test_node_diagnostics_name_a_lock_refused_and_refound_in_one_pair(ros_context):
    # Pair 4's warm plane slid off the floor: the lock's reference refuses it and the search
    # in the same pair publishes the floor (truth.drifting_lock_frames).
    frames = drifting_lock_frames()[:5]
    h = Harness(ros_context, [Parameter('diagnostics.period_s', value=0.2)])
    results: list[DiagnosticArray] = []
    h.driver.create_subscription(DiagnosticArray, 'plane/result', results.append, 10)
    try:
        h.wait_for_subscribers()
        for i, frame in enumerate(frames):
            _send(h, frame, STAMP0_NS + i * PERIOD_NS)
        last = STAMP0_NS + 4 * PERIOD_NS
        # The worker records its result just after publishing: wait for it.
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and (h.node.session.last_result is None or
                                               h.node.session.last_result.stamp_ns != last):
            time.sleep(0.005)
        result = h.node.session.last_result
        assert result.stamp_ns == last and result.ok
        assert plane_error_px(frames[4], result.homography) < 1.0
        # A status built after the last pair was processed shows it.
        h.diagnostics.clear()
        deadline = time.monotonic() + 10.0
        values: dict[str, str] = {}
        while time.monotonic() < deadline:
            h.executor.spin_once(timeout_sec=0.05)
            if h.diagnostics:
                values = {kv.key: kv.value for kv in h.diagnostics[-1].status[0].values}
                if values.get('processed pairs') == '5':
                    break
        assert values.get('processed pairs') == '5', values
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and last not in _stamps(results):
            h.executor.spin_once(timeout_sec=0.02)
    finally:
        h.close()
    # The pair's own result says it too: a plane, the lock lost and its refusals.
    pair = [r for r in results if _stamps([r]) == [last]]
    assert pair, _stamps(results)
    per_pair = {kv.key: kv.value for kv in pair[-1].status[0].values}
    assert per_pair['plane'] == 'true' and per_pair['lock_lost'] == str(result.lock_lost)
    assert json.loads(per_pair['refusals']) == [str(r) for r in result.refusals]
    assert any(r.startswith('reference: ') for r in json.loads(per_pair['refusals']))
    lost = values['lock lost (last frame)']
    assert lost.startswith('reference: plane not verified: score '), values
    assert lost == str(result.lock_lost)
    assert values['last lock lost'] == lost
    assert values['locks lost (reference)'] == '1'
    assert values['locks re-found in the same pair'] == '1'
    assert values['planes refused (reference)'] == '1'
    assert all(values[f'locks lost ({kind})'] == '0'
               for kind in ('bottom', 'drop', 'gate', 'cut', 'view change', 'challenger',
                            'tracking', 'reset')), values
    assert values['re-initialisations'] == '2', values
