"""StreamSession, the bookkeeping shared by the node and the replay, without ROS or DDS."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

from domplane_ros.config import PlaneNodeConfig, SyncConfig
from domplane_ros.stream.health import INPUT_COUNTER_NAMES
from domplane_ros.stream.session import LATENCY_WINDOW, StreamSession
from domplane_ros.stream.status import ERROR, WARN
import numpy as np
import pytest

T0 = 1_700_000_000 * 10**9


def _msg(stamp_ns, encoding='mono8', seed=0, shape=(48, 64)):
    """Return a duck-typed image message (what the decoder reads, nothing more)."""
    height, width = shape
    data = np.random.default_rng(seed).integers(0, 256, height * width, np.uint8).tobytes()
    stamp = SimpleNamespace(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return SimpleNamespace(header=SimpleNamespace(stamp=stamp, frame_id='cam'),
                           height=height, width=width, step=width, encoding=encoding,
                           is_bigendian=0, data=data)


def _feed(session, k, now, encoding='mono8', right_offset_ns=0):
    stamp = T0 + k * 10**8
    pairs = []
    for side, offset in (('left', 0), ('right', right_offset_ns)):
        new, _ = session.receive(side, stamp + offset, _msg(stamp + offset, encoding, k),
                                 now)
        pairs += new
    return [session.process(pair) for pair in pairs]


def test_one_owner_of_the_input_counts():
    session = StreamSession()
    assert session.pipeline.counts is session.counts
    assert session.pipeline.checks.counts is session.counts
    assert session.stamp_checks.counts is session.counts
    with pytest.raises(KeyError):
        session.counts.add('no_such_counter')
    with pytest.raises(TypeError):
        session.counts['stamp_zero'] = 3     # read-only but for add()


def test_pairs_decode_errors_and_the_status_are_counted_once():
    session = StreamSession(start=0.0)
    frames = [f for k in range(3) for f in _feed(session, k, now=0.1 * k)]
    assert len(frames) == 3 and all(f is not None for f in frames)
    counters = session.counters
    assert (counters.pairs, counters.processed, counters.decode_errors) == (3, 3, 0)
    assert session.last_result is frames[-1].result and len(session.latencies_ms) == 3
    # Undecodable pairs: counted by kind, no result, ERROR after three in a row.
    for k in range(3, 6):
        assert _feed(session, k, now=0.1 * k, encoding='nv12') == [None]
    assert counters.decode_errors == 3 and session.counts['decode_encoding'] == 3
    assert session.last_result is None and "unsupported encoding 'nv12'" in session.last_error
    assert counters.consecutive_failures >= 3
    level, message, values = session.status(now=1.0, dropped_busy=2)
    values = dict(values)
    assert level == ERROR and message.startswith('no plane for ')
    assert values['pairs'] == '6' and values['processed pairs'] == '3'
    assert values['dropped pairs (busy)'] == '2' and values['decode errors'] == '3'
    assert values['decode errors (encoding)'] == '3'
    assert values['input rate [pairs/s]'] == '6.00'          # 6 pairs over 1 s since start
    assert values['/left/image_raw images received'] == '6'
    assert values['/left/image_raw rate [images/s]'] == '6.00'
    assert values['/left/image_raw last image age [s]'] == '0.50'
    assert set(INPUT_COUNTER_NAMES.values()) <= set(values)
    # The next period starts at the status.
    _, _, values = session.status(now=2.0)
    assert dict(values)['/left/image_raw rate [images/s]'] == '0.00'


def test_stamp_warnings_reach_the_next_status_once():
    session = StreamSession(start=0.0)
    for k in range(12):   # the right camera 50 ms late: nothing pairs (slop 10 ms)
        assert _feed(session, k, now=0.01 * k, right_offset_ns=50_000_000) == []
    level, message, values = session.status(now=1.0)
    assert level == WARN and 'differs by 50.0 ms > sync.slop_s 10 ms' in message
    assert int(dict(values)['frames unpaired: stamp skew > slop']) >= 1
    assert 'differs' not in session.status(now=2.0)[1]


def test_publish_runs_before_the_pair_is_counted_and_inside_the_latency():
    session = StreamSession()
    seen = []

    def publish(frame):
        seen.append((session.counters.processed, frame.publishable, frame.latency_ms))

    pairs, _ = session.receive('left', T0, _msg(T0), 0.0)
    pairs += session.receive('right', T0, _msg(T0), 0.0)[0]
    frame = session.process(pairs[0], publish=publish)
    assert seen == [(0, frame.publishable, frame.latency_ms)]
    assert session.counters.processed == 1
    assert session.latencies_ms[-1] >= frame.latency_ms
    assert session.latencies_ms.maxlen == LATENCY_WINDOW


def test_a_new_sync_config_gets_new_stamp_checks_and_keeps_the_counts():
    session = StreamSession()
    session.receive('left', 0, _msg(0), 0.0)
    assert session.counts['stamp_zero'] == 1
    old_sync = session.sync
    config = PlaneNodeConfig(sync=SyncConfig(slop_s=0.02, queue_size=5))
    session.update_config(config)
    assert session.config is config and session.pipeline.config is config
    assert session.sync is not old_sync and session.sync.slop_ns == 20_000_000
    assert session.stamp_checks.slop_ns == 20_000_000
    assert session.stamp_checks.counts is session.counts
    session.receive('right', 0, _msg(0), 0.0)
    assert session.counts['stamp_zero'] == 2


def test_a_replay_clock_in_nanoseconds_starts_at_the_first_image():
    session = StreamSession(tick_s=1e-9)
    _feed(session, 0, now=T0)
    _feed(session, 1, now=T0 + 10**8)
    # No previous status: the camera rates are the pair rate the replay measured.
    _, _, values = session.status(now=T0 + 3 * 10**8, rate=7.5)
    values = dict(values)
    assert values['input rate [pairs/s]'] == '7.50'
    assert values['/right/image_raw rate [images/s]'] == '7.50'
    assert values['/right/image_raw last image age [s]'] == '0.20'
    _feed(session, 5, now=T0 + 5 * 10**8)
    _, _, values = session.status(now=T0 + 5 * 10**8, rate=5.0)
    assert dict(values)['/right/image_raw rate [images/s]'] == '5.00'   # 1 image in 0.2 s


def test_a_status_built_while_a_pair_is_processed_shows_a_consistent_state():
    # The diagnostics timer may build a status while the worker processes a pair: the
    # pipeline's lock state then already changes (locked before the pair's mask is computed)
    # while the last result is still the previous one. The status shows the last result with
    # the state the pipeline had after it, never the live state beside an older result
    # (seen over DDS as 'locked' beside warm start 'none').
    session = StreamSession(start=0.0)
    seen = []
    process = session.pipeline.process

    def midway(*args, **kwargs):
        real = session.pipeline._state
        session.pipeline._state = 'locked'  # as while a pair that locks is being processed
        seen.append(dict(session.status(0.05)[2]))
        session.pipeline._state = real
        return process(*args, **kwargs)

    session.pipeline.process = midway
    _feed(session, 0, now=0.0)
    assert seen[0]['lock state'] == 'searching' and seen[0]['warm start'] == 'none'
    values = dict(session.status(0.1)[2])
    assert values['lock state'] == session.pipeline.state
    assert values['warm start'] == (session.last_result.warm_start or 'none')


def test_a_pair_that_did_not_decode_passes_its_gap_on():
    # The stamp jump is the cameras' gap before a pair (Pair.gap_ns); a pair that did not
    # decode never reaches the pipeline, so its gap (here 30 s) goes on with the next pair,
    # whose own gap (33 ms) would otherwise hide it.
    config = PlaneNodeConfig()
    config = replace(config, pipeline=replace(config.pipeline, max_stamp_jump_s=1.0))
    session = StreamSession(config, start=0.0)
    ms = 10**6
    for t_ms, encoding in ((0, 'mono8'), (33, 'mono8'), (30_000, 'nv12'), (30_033, 'mono8')):
        for side in ('left', 'right'):
            pairs, _ = session.receive(side, T0 + t_ms * ms,
                                       _msg(T0 + t_ms * ms, encoding, t_ms), t_ms * 1e-3)
        (pair,) = pairs
        frame = session.process(pair)
        assert (frame is None) == (encoding == 'nv12')
    assert session.counters.decode_errors == 1
    assert session.counts['stamp_jumps'] == 1
    assert frame.result.reinitialised
    assert 'stamp jumped forward by 30.0 s' in ' '.join(frame.result.warnings)
