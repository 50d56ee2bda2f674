"""NewestSlot, the node's newest-wins hand-over, in milliseconds and without DDS."""

from __future__ import annotations

import threading
import time

from domplane_ros.ros.handover import NewestSlot


def test_put_replaces_the_waiting_item_and_counts_a_drop():
    slot: NewestSlot[int] = NewestSlot()
    assert slot.put(1) is False
    assert slot.put(2) is True
    assert slot.put(3) is True
    assert slot.pending
    assert slot.take(timeout=0) == 3      # the newest wins
    assert not slot.pending
    assert (slot.put_count, slot.dropped) == (3, 2)
    assert slot.take(timeout=0) is None   # nothing waits: a timed-out take gives None


def test_take_blocks_until_a_put_and_close_wakes_it():
    slot: NewestSlot[str] = NewestSlot()
    got = []
    taker = threading.Thread(target=lambda: got.append(slot.take()))
    taker.start()
    time.sleep(0.02)
    assert taker.is_alive() and not got    # blocked: nothing to take
    slot.put('pair')
    taker.join(1.0)
    assert got == ['pair'] and slot.dropped == 0
    taker = threading.Thread(target=lambda: got.append(slot.take()))
    taker.start()
    slot.close()
    taker.join(1.0)
    assert not taker.is_alive() and got == ['pair', None]
    slot.put('late')
    assert slot.take() is None             # closed: take returns at once
    assert slot.take_nowait() == 'late'    # but a stopped worker's caller can still take it


def test_a_slow_taker_gets_the_newest_and_every_item_is_taken_or_dropped():
    slot: NewestSlot[int] = NewestSlot()
    taken: list[int] = []

    def worker():
        while (item := slot.take()) is not None:
            time.sleep(0.002)              # slower than the producer
            taken.append(item)

    thread = threading.Thread(target=worker)
    thread.start()
    for k in range(200):
        slot.put(k)
        time.sleep(0.0002)
    deadline = time.monotonic() + 2.0
    while slot.pending and time.monotonic() < deadline:
        time.sleep(0.001)
    time.sleep(0.01)
    slot.close()
    thread.join(1.0)
    assert taken[-1] == 199                # the newest item reached the worker
    assert taken == sorted(taken)          # in order, stale ones skipped
    assert slot.dropped > 0 and len(taken) + slot.dropped == slot.put_count == 200
