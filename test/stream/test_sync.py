"""Tests of domplane_ros.stream.sync: approximate-time pairing of left and right messages."""

from __future__ import annotations

from dataclasses import FrozenInstanceError

from domplane_ros.stream.sync import ApproximateTimeSync, Pair, SyncStats
from hypothesis import given, settings
from hypothesis import strategies as st
import pytest

MS = 1_000_000  # Nanoseconds per millisecond.
PERIOD = 33 * MS


def _feed(sync, events):
    """Feed ``(side, stamp_ns, item)`` events; return all pairs made, in order."""
    pairs = []
    for side, stamp, item in events:
        pairs.extend(sync.add(side, stamp, item))
    return pairs


def _check_accounting(sync):
    stats = sync.stats()
    assert stats.accounted == stats.received
    return stats


def test_exact_stamps_pair_one_to_one():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    events = []
    for i in range(10):
        events += [('left', i * PERIOD, f'L{i}'), ('right', i * PERIOD, f'R{i}')]
    pairs = _feed(sync, events)
    assert [(p.left, p.right) for p in pairs] == [(f'L{i}', f'R{i}') for i in range(10)]
    assert all(p.left_stamp_ns == p.right_stamp_ns for p in pairs)
    assert not any(p.after_reset for p in pairs)
    stats = _check_accounting(sync)
    assert stats == SyncStats(received_left=10, received_right=10, pairs_emitted=10)


def test_add_left_and_add_right_are_add():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    assert sync.add_right(100, 'R') == []
    assert sync.add_left(101, 'L') == [Pair(101, 100, 'L', 'R')]


def test_jittered_stamps_within_slop_pair():
    sync = ApproximateTimeSync(slop_s=0.004, queue_size=3)
    jitter = [3, -2, 4, -4, 0, 1, -3, 2]
    events = []
    for i, j in enumerate(jitter):
        events += [('left', i * PERIOD, i), ('right', i * PERIOD + j * MS, i)]
    pairs = _feed(sync, events)
    assert [(p.left, p.right) for p in pairs] == [(i, i) for i in range(len(jitter))]
    assert [p.skew_ns for p in pairs] == [-j * MS for j in jitter]
    assert all(p.stamp_ns == max(p.left_stamp_ns, p.right_stamp_ns) for p in pairs)
    _check_accounting(sync)


def test_stamps_beyond_slop_do_not_pair():
    sync = ApproximateTimeSync(slop_s=0.004, queue_size=3)
    assert sync.add_left(0, 'L0') == []
    assert sync.add_right(5 * MS, 'R0') == []
    stats = _check_accounting(sync)
    assert stats.pairs_emitted == 0 and stats.queued_left == 1 and stats.queued_right == 1


def test_slop_boundary_is_inclusive():
    sync = ApproximateTimeSync(slop_s=0.004, queue_size=3)
    sync.add_left(0, 'L')
    assert len(sync.add_right(4 * MS, 'R')) == 1
    sync.add_left(100 * MS, 'L')
    assert sync.add_right(104 * MS + 1, 'R') == []


def test_closest_match_wins_and_older_messages_are_stale():
    sync = ApproximateTimeSync(slop_s=0.010, queue_size=5)
    for k, stamp in enumerate([0, 6 * MS, 9 * MS, 20 * MS]):
        sync.add_left(stamp, f'L{k}')
    (pair,) = sync.add_right(8 * MS, 'R')
    assert pair.left == 'L2'  # 9 ms is closest to 8 ms.
    stats = _check_accounting(sync)
    assert stats.dropped_stale == 2  # L0 and L1.
    assert stats.queued_left == 1  # L3 (20 ms) is newer than the pair and still waits.


def test_tie_goes_to_newer_message():
    sync = ApproximateTimeSync(slop_s=0.010, queue_size=5)
    sync.add_left(0, 'old')
    sync.add_left(10 * MS, 'new')
    (pair,) = sync.add_right(5 * MS, 'R')
    assert pair.left == 'new'


def test_one_camera_dropping_frames():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=4)
    dropped_right = {2, 3, 7}
    events = []
    for i in range(10):
        events.append(('left', i * PERIOD, i))
        if i not in dropped_right:
            events.append(('right', i * PERIOD + MS, i))
    pairs = _feed(sync, events)
    assert [p.left for p in pairs] == [i for i in range(10) if i not in dropped_right]
    assert all(p.left == p.right for p in pairs)
    stats = _check_accounting(sync)
    # Unpaired left frames are dropped as stale by the next pair, never queued for ever.
    assert stats.dropped_stale == len(dropped_right)
    assert stats.queued_left == 0


def test_burst_overflows_queue_and_keeps_newest():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    for i in range(8):  # The right camera stalls while the left one keeps publishing.
        sync.add_left(i * PERIOD, i)
    stats = _check_accounting(sync)
    assert stats.queued_left == 3 and stats.dropped_overflow == 5
    assert sync.add_right(0, 'late R0') == []  # L0 was evicted.
    (pair,) = sync.add_right(7 * PERIOD, 'R7')
    assert pair.left == 7
    stats = _check_accounting(sync)
    assert stats.dropped_stale == 3  # L5 and L6, and R0, older than the pair on its side.
    assert stats.queued_left == 0 and stats.queued_right == 0


def test_unpaired_message_waits_then_goes_stale():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    _feed(sync, [('left', 100 * MS, 'L'), ('right', 100 * MS, 'R'), ('left', 200 * MS, 'L2')])
    assert sync.add_right(150 * MS, 'R without partner') == []
    assert _check_accounting(sync).queued_right == 1
    (pair,) = _feed(sync, [('left', 300 * MS, 'L3'), ('right', 301 * MS, 'R3')])
    assert (pair.left, pair.right) == ('L3', 'R3')
    stats = _check_accounting(sync)
    assert stats.dropped_stale == 2  # L2 and the right message without partner.
    assert stats.dropped_unmatched == 0


def test_duplicate_stamp_is_dropped_unmatched():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    sync.add_left(100, 'L')
    sync.add_right(100, 'R')
    assert sync.add_left(100, 'L again') == []
    stats = _check_accounting(sync)
    assert stats.dropped_unmatched == 1 and stats.resets == 0


def test_stamps_going_backwards_reset_and_flag_next_pair():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    t0 = 10_000 * MS
    _feed(sync, [('left', t0, 'L0'), ('right', t0, 'R0'), ('left', t0 + PERIOD, 'L1')])
    # The bag loops: both cameras start again at 0.
    assert sync.add_right(t0 + PERIOD + MS, 'R1 old') == [Pair(
        t0 + PERIOD, t0 + PERIOD + MS, 'L1', 'R1 old', gap_ns=PERIOD)]
    assert sync.add_left(t0 + 2 * PERIOD, 'L2 old') == []  # Queued, waiting for R2.
    assert sync.add_left(0, 'L0 new') == []
    stats = _check_accounting(sync)
    assert stats.resets == 1 and stats.dropped_reset == 1  # L2 old.
    assert sync.add_right(t0 + 2 * PERIOD, 'R2 old') == []  # Cannot pair across the jump.
    (pair,) = sync.add_right(MS, 'R0 new')
    assert (pair.left, pair.right, pair.after_reset) == ('L0 new', 'R0 new', True)
    stats = _check_accounting(sync)
    assert stats.resets == 2  # The right side jumped too.
    (pair,) = _feed(sync, [('left', PERIOD, 'L1 new'), ('right', PERIOD, 'R1 new')])
    assert not pair.after_reset


def test_bag_loop_leaves_no_message_from_before_the_jump():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=5)
    events = []
    for i in range(5):  # First pass; the right camera lags by two frames in delivery.
        events.append(('left', i * PERIOD, ('old', i)))
    for i in range(5):
        events.append(('right', i * PERIOD, ('old', i)))
    for i in range(5):  # Second pass, interleaved normally.
        events += [('left', i * PERIOD, ('new', i)), ('right', i * PERIOD, ('new', i))]
    pairs = _feed(sync, events)
    new_pairs = [p for p in pairs if p.left[0] == 'new' or p.right[0] == 'new']
    assert all(p.left[0] == p.right[0] == 'new' for p in new_pairs)
    assert [p.left[1] for p in new_pairs] == [0, 1, 2, 3, 4]
    assert new_pairs[0].after_reset
    _check_accounting(sync)


def test_external_reset():
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=3)
    sync.add_left(0, 'L')
    sync.reset()
    stats = _check_accounting(sync)
    assert stats.resets == 1 and stats.dropped_reset == 1 and stats.queued_left == 0
    (pair,) = _feed(sync, [('left', PERIOD, 'L'), ('right', PERIOD, 'R')])
    assert pair.after_reset


@pytest.mark.parametrize('order', ['left_first', 'right_first', 'alternating', 'bursts'])
def test_interleaved_arrival_orders_give_the_same_pairs(order):
    n = 12
    lefts = [('left', i * PERIOD + (i % 3) * MS, i) for i in range(n)]
    rights = [('right', i * PERIOD - (i % 2) * MS, i) for i in range(n)]
    if order == 'left_first':
        events = [e for pair in zip(lefts, rights) for e in pair]
    elif order == 'right_first':
        events = [e for pair in zip(rights, lefts) for e in pair]
    elif order == 'alternating':
        events = [e for i, pair in enumerate(zip(lefts, rights))
                  for e in (pair if i % 2 else pair[::-1])]
    else:  # Each side delivers in bursts of three.
        events = []
        for k in range(0, n, 3):
            events += lefts[k:k + 3] + rights[k:k + 3]
    sync = ApproximateTimeSync(slop_s=0.005, queue_size=4)
    pairs = _feed(sync, events)
    assert [(p.left, p.right) for p in pairs] == [(i, i) for i in range(n)]
    _check_accounting(sync)


def test_pair_is_frozen():
    pair = Pair(1, 2, 'l', 'r')
    with pytest.raises(FrozenInstanceError):
        pair.left = 'x'


@pytest.mark.parametrize('kwargs,name', [
    ({'slop_s': 0.0, 'queue_size': 1}, 'slop_s'),
    ({'slop_s': -0.1, 'queue_size': 1}, 'slop_s'),
    ({'slop_s': float('inf'), 'queue_size': 1}, 'slop_s'),
    ({'slop_s': float('nan'), 'queue_size': 1}, 'slop_s'),
    ({'slop_s': '0.1', 'queue_size': 1}, 'slop_s'),
    ({'slop_s': True, 'queue_size': 1}, 'slop_s'),
    ({'slop_s': 0.1, 'queue_size': 0}, 'queue_size'),
    ({'slop_s': 0.1, 'queue_size': 2.0}, 'queue_size'),
    ({'slop_s': 0.1, 'queue_size': True}, 'queue_size'),
])
def test_constructor_validates(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ApproximateTimeSync(**kwargs)


@pytest.mark.parametrize('side,stamp,name', [
    ('middle', 0, 'side'), ('left', 1.5, 'stamp_ns'), ('right', None, 'stamp_ns'),
    ('left', True, 'stamp_ns'),
])
def test_add_validates(side, stamp, name):
    sync = ApproximateTimeSync(slop_s=0.01, queue_size=2)
    with pytest.raises(ValueError, match=name):
        sync.add(side, stamp, None)
    assert sync.stats().received == 0


def test_properties():
    sync = ApproximateTimeSync(slop_s=0.0125, queue_size=7)
    assert sync.slop_s == 0.0125 and sync.slop_ns == 12_500_000 and sync.queue_size == 7


# Property test over random arrival sequences.

def _walk(steps):
    """Turn ``(side, advance, jitter, jump)`` steps into ``(side, stamp)`` events."""
    clock = 1000
    events = []
    for side, advance, jitter, jump in steps:
        clock = max(10, clock - 500) if jump else clock + advance
        events.append((side, clock + jitter))
    return events


_events = st.one_of(
    # Arbitrary stamps: mostly jumps back and forth.
    st.lists(st.tuples(st.sampled_from(['left', 'right']),
                       st.integers(min_value=0, max_value=10**6)), max_size=120),
    # One jittered clock for both sides, mostly going forward, jumping back one step in ten.
    st.lists(st.tuples(st.sampled_from(['left', 'right']),
                       st.integers(min_value=0, max_value=30),
                       st.integers(min_value=0, max_value=4),
                       st.sampled_from([False] * 9 + [True])),
             min_size=20, max_size=150).map(_walk),
)


@settings(max_examples=300, deadline=None)
@given(events=_events, slop_ns=st.integers(min_value=1, max_value=30),
       queue_size=st.integers(min_value=1, max_value=6))
def test_random_sequences_keep_the_invariants(events, slop_ns, queue_size):
    sync = ApproximateTimeSync(slop_s=slop_ns * 1e-9, queue_size=queue_size)
    assert sync.slop_ns == slop_ns
    seen_items = set()
    last = {'left': None, 'right': None}
    resets_seen = 0
    for index, (side, stamp) in enumerate(events):
        for pair in sync.add(side, stamp, (side, index)):
            assert abs(pair.left_stamp_ns - pair.right_stamp_ns) <= slop_ns
            assert pair.left[0] == 'left' and pair.right[0] == 'right'
            assert pair.left not in seen_items and pair.right not in seen_items
            seen_items.update((pair.left, pair.right))
            assert pair.left_stamp_ns == events[pair.left[1]][1]
            assert pair.right_stamp_ns == events[pair.right[1]][1]
            stats = sync.stats()
            if stats.resets != resets_seen:  # Strictly increasing only between resets.
                resets_seen = stats.resets
                last = {'left': None, 'right': None}
                assert pair.after_reset
            for pair_side, stamp_ns in (('left', pair.left_stamp_ns),
                                        ('right', pair.right_stamp_ns)):
                assert last[pair_side] is None or stamp_ns > last[pair_side]
                last[pair_side] = stamp_ns
        stats = sync.stats()
        assert stats.queued_left <= queue_size and stats.queued_right <= queue_size
        assert stats.accounted == stats.received == index + 1
    stats = sync.stats()
    assert stats.received_left == sum(1 for side, _ in events if side == 'left')
    assert 2 * stats.pairs_emitted == len(seen_items)
