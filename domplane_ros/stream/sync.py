"""Approximate-time pairing of left and right camera messages.

:class:`ApproximateTimeSync` pairs messages from two streams by their stamps, greedily and with
bounded memory, so that the live node and the offline replay pair frames the same way. It is
pure Python and imports no ROS package; items are opaque.

Policy, applied each time a message arrives on one side:

1. Reset. If its stamp is older than the previous stamp received on its side (a clock reset,
   or a bag that loops), the queues are cleared (counted in ``dropped_reset``), ``resets`` is
   incremented, and the next pair emitted has ``after_reset=True`` so that the pipeline can
   drop its warm start. Only the other side's messages within ``slop`` of the new stamp are
   kept, as they may be its partner from the new stream (when the other side jumped first).
   The message is then handled as the first one of a new stream. Each side detects its own
   jump, so a bag loop on both cameras counts two resets, and no message from before the jump
   survives on either side. (The previous stamp received on a side is never older than the
   last one emitted there, so a stamp older than the last pair always resets.) DDS and rosbag2
   deliver each topic in order, so an out-of-order stamp is taken for a jump.
2. Duplicate. If its stamp equals the last stamp emitted on its side, pairing it would break
   the order of that side's pairs: it is dropped and counted in ``dropped_unmatched``.
3. Match. Otherwise it is paired at once with the queued message of the other side whose stamp
   is closest to its own, within ``slop`` (ties go to the newer message). Every queued message
   on either side that is not newer than the pair is dropped and counted in ``dropped_stale``:
   newest data wins, and each side's emitted stamps strictly increase.
4. Queue. With no match the message is queued on its side. A queue holds at most
   ``queue_size`` messages; when it is full the oldest one is evicted and counted in
   ``dropped_overflow``.

Every message received is, at any time, in exactly one of: an emitted pair, a drop counter,
or a queue (see :meth:`SyncStats.accounted`).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, replace
import math
import numbers
import threading
from typing import Any, Literal

Side = Literal['left', 'right']
_SIDES: tuple[Side, Side] = ('left', 'right')
_OTHER: dict[str, Side] = {'left': 'right', 'right': 'left'}


@dataclass(frozen=True)
class Pair:
    """A left and a right message paired by their stamps.

    Attributes:
        left_stamp_ns: Stamp of the left message in nanoseconds.
        right_stamp_ns: Stamp of the right message in nanoseconds.
        left: The left item, as given to :meth:`ApproximateTimeSync.add`.
        right: The right item, as given to :meth:`ApproximateTimeSync.add`.
        after_reset: True for the first pair emitted after a reset (stamps went backwards),
            so that state carried across frames (a warm start) should be dropped.
        gap_ns: The cameras' own gap before this pair: its left stamp minus the left stamp of
            the pair emitted before it (None for the first pair and after a reset). A consumer
            that drops pairs (newest-wins) folds the dropped pairs' gaps in with
            :func:`merge_dropped`, so a gap stays visible however many pairs were dropped.

    """

    left_stamp_ns: int
    right_stamp_ns: int
    left: Any
    right: Any
    after_reset: bool = False
    gap_ns: int | None = None

    @property
    def stamp_ns(self) -> int:
        """Stamp of the pair: the later of the two stamps, in nanoseconds."""
        return max(self.left_stamp_ns, self.right_stamp_ns)

    @property
    def skew_ns(self) -> int:
        """Signed stamp difference ``left_stamp_ns - right_stamp_ns`` in nanoseconds."""
        return self.left_stamp_ns - self.right_stamp_ns


@dataclass(frozen=True)
class SyncStats:
    """Counters of an :class:`ApproximateTimeSync`, since it was made.

    Attributes:
        received_left: Left messages given to the synchroniser.
        received_right: Right messages given to the synchroniser.
        pairs_emitted: Pairs returned (each holds one left and one right message).
        dropped_unmatched: Messages dropped on arrival because they could never be paired
            (a stamp equal to the last one emitted on its side).
        dropped_overflow: Messages evicted from a full queue.
        dropped_stale: Queued messages dropped because a newer pair was emitted.
        dropped_reset: Queued messages dropped by a reset.
        resets: Times the stamps went backwards and the queues were cleared.
        queued_left: Left messages waiting in the queue now.
        queued_right: Right messages waiting in the queue now.

    """

    received_left: int = 0
    received_right: int = 0
    pairs_emitted: int = 0
    dropped_unmatched: int = 0
    dropped_overflow: int = 0
    dropped_stale: int = 0
    dropped_reset: int = 0
    resets: int = 0
    queued_left: int = 0
    queued_right: int = 0

    @property
    def received(self) -> int:
        """Messages received on both sides."""
        return self.received_left + self.received_right

    @property
    def dropped(self) -> int:
        """Messages dropped for any reason."""
        return (self.dropped_unmatched + self.dropped_overflow + self.dropped_stale
                + self.dropped_reset)

    @property
    def accounted(self) -> int:
        """Messages paired, dropped or queued; always equal to :attr:`received`."""
        return 2 * self.pairs_emitted + self.dropped + self.queued_left + self.queued_right


def merge_dropped(dropped: Pair, newer: Pair) -> Pair:
    """Return ``newer`` carrying what a consumer must not lose when it drops ``dropped``.

    A newest-wins hand-over (the node's worker busy with a search) replaces a pair not taken
    yet by the newer one; the stream's events between them still count: a reset before the
    dropped pair (``after_reset``) and the longest gap (``gap_ns``). A gap not known on either
    (None: a first pair, a pair after a reset) leaves it unknown, so the consumer measures the
    jump from the last pair it processed.
    """
    gaps = (dropped.gap_ns, newer.gap_ns)
    return replace(newer, after_reset=dropped.after_reset or newer.after_reset,
                   gap_ns=None if None in gaps else max(gaps))


class ApproximateTimeSync:
    """Greedy approximate-time synchroniser for a stereo pair of message streams.

    Thread-safe: a lock guards the state, so the left and right callbacks may run on different
    threads of a multi-threaded executor.

    Example:
        >>> sync = ApproximateTimeSync(slop_s=0.01, queue_size=5)
        >>> sync.add_left(1_000_000_000, 'L0')
        []
        >>> [(p.left, p.right) for p in sync.add_right(1_002_000_000, 'R0')]
        [('L0', 'R0')]

    """

    def __init__(self, slop_s: float, queue_size: int) -> None:
        """Make an empty synchroniser.

        Args:
            slop_s: Largest stamp difference of a pair, in seconds; finite and > 0. It is
                rounded to whole nanoseconds.
            queue_size: Most messages kept waiting per side; an int >= 1.

        Raises:
            ValueError: If ``slop_s`` is not a finite number > 0, or ``queue_size`` is not an
                int >= 1.

        """
        if (isinstance(slop_s, bool) or not isinstance(slop_s, numbers.Real)
                or not math.isfinite(slop_s) or slop_s <= 0):
            raise ValueError(f'slop_s must be a finite number > 0, got {slop_s!r}')
        if (isinstance(queue_size, bool) or not isinstance(queue_size, numbers.Integral)
                or queue_size < 1):
            raise ValueError(f'queue_size must be an int >= 1, got {queue_size!r}')
        self._slop_s = float(slop_s)
        self._slop_ns = int(round(self._slop_s * 1e9))
        self._queue_size = int(queue_size)
        self._lock = threading.Lock()
        # Per side: stamps and items in increasing stamp order (parallel lists).
        self._stamps: dict[str, list[int]] = {side: [] for side in _SIDES}
        self._items: dict[str, list[Any]] = {side: [] for side in _SIDES}
        self._last_emitted: dict[str, int | None] = dict.fromkeys(_SIDES)
        self._last_received: dict[str, int | None] = dict.fromkeys(_SIDES)
        self._last_pair_left: int | None = None
        self._reset_pending = False
        self._counts = {
            'received_left': 0, 'received_right': 0, 'pairs_emitted': 0,
            'dropped_unmatched': 0, 'dropped_overflow': 0, 'dropped_stale': 0,
            'dropped_reset': 0, 'resets': 0,
        }

    @property
    def slop_s(self) -> float:
        """Largest stamp difference of a pair, in seconds."""
        return self._slop_s

    @property
    def slop_ns(self) -> int:
        """Largest stamp difference of a pair, in nanoseconds (rounded)."""
        return self._slop_ns

    @property
    def queue_size(self) -> int:
        """Most messages kept waiting per side."""
        return self._queue_size

    def add_left(self, stamp_ns: int, item: Any) -> list[Pair]:
        """Add a left message; see :meth:`add`.

        Args:
            stamp_ns: The message stamp in nanoseconds.
            item: The message or anything else to carry into the pair.

        Returns:
            The pairs made (none or one).

        """
        return self.add('left', stamp_ns, item)

    def add_right(self, stamp_ns: int, item: Any) -> list[Pair]:
        """Add a right message; see :meth:`add`.

        Args:
            stamp_ns: The message stamp in nanoseconds.
            item: The message or anything else to carry into the pair.

        Returns:
            The pairs made (none or one).

        """
        return self.add('right', stamp_ns, item)

    def add(self, side: Side, stamp_ns: int, item: Any) -> list[Pair]:
        """Add a message on one side and return the pairs it completes.

        Args:
            side: ``'left'`` or ``'right'``.
            stamp_ns: The message stamp in nanoseconds (an integer).
            item: The message or anything else to carry into the pair.

        Returns:
            The pairs made, in emission order: none or one with the policy in the module
            docstring.

        Raises:
            ValueError: If ``side`` is not ``'left'`` or ``'right'``, or ``stamp_ns`` is not
                an int.

        """
        if side not in _OTHER:
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, numbers.Integral):
            raise ValueError(
                f'stamp_ns must be an int (nanoseconds), got {type(stamp_ns).__name__}')
        with self._lock:
            return self._add(side, int(stamp_ns), item)

    def reset(self) -> None:
        """Clear both queues and forget the last pair, as when a stamp goes backwards.

        The cleared messages are counted in ``dropped_reset``, ``resets`` is incremented and
        the next pair has ``after_reset=True``.
        """
        with self._lock:
            self._reset()

    def stats(self) -> SyncStats:
        """Return a snapshot of the counters.

        Returns:
            The counters and the current queue lengths.

        """
        with self._lock:
            return SyncStats(
                queued_left=len(self._stamps['left']),
                queued_right=len(self._stamps['right']),
                **self._counts)

    def _reset(self, jumped_side: str | None = None, stamp_ns: int = 0) -> None:
        """Clear the queues and the last pair; see the module docstring.

        Args:
            jumped_side: The side whose stamp went back to ``stamp_ns``; None clears all.
            stamp_ns: The new stamp on ``jumped_side``.

        """
        for side in _SIDES:
            stamps, items = self._stamps[side], self._items[side]
            if jumped_side is None or side == jumped_side:
                keep = []
            else:
                keep = [i for i, stamp in enumerate(stamps)
                        if abs(stamp - stamp_ns) <= self._slop_ns]
            self._counts['dropped_reset'] += len(stamps) - len(keep)
            self._stamps[side] = [stamps[i] for i in keep]
            self._items[side] = [items[i] for i in keep]
            self._last_emitted[side] = None
        self._last_pair_left = None
        self._counts['resets'] += 1
        self._reset_pending = True

    def _add(self, side: str, stamp_ns: int, item: Any) -> list[Pair]:
        other = _OTHER[side]
        self._counts['received_' + side] += 1

        previous = self._last_received[side]
        self._last_received[side] = stamp_ns
        if previous is not None and stamp_ns < previous:
            self._reset(side, stamp_ns)
        if stamp_ns == self._last_emitted[side]:
            self._counts['dropped_unmatched'] += 1
            return []

        match = self._closest(other, stamp_ns)
        if match is None:
            self._enqueue(side, stamp_ns, item)
            return []

        other_stamp = self._stamps[other][match]
        other_item = self._items[other][match]
        # Drop everything on the other side up to and including the match (the match itself is
        # emitted, not dropped), and everything on this side not newer than the new message.
        self._counts['dropped_stale'] += match
        del self._stamps[other][:match + 1]
        del self._items[other][:match + 1]
        own_stale = bisect.bisect_right(self._stamps[side], stamp_ns)
        self._counts['dropped_stale'] += own_stale
        del self._stamps[side][:own_stale]
        del self._items[side][:own_stale]

        self._last_emitted[side] = stamp_ns
        self._last_emitted[other] = other_stamp
        self._counts['pairs_emitted'] += 1
        after_reset, self._reset_pending = self._reset_pending, False
        left_stamp = stamp_ns if side == 'left' else other_stamp
        previous, self._last_pair_left = self._last_pair_left, left_stamp
        gap = None if previous is None else left_stamp - previous
        if side == 'left':
            pair = Pair(stamp_ns, other_stamp, item, other_item, after_reset, gap)
        else:
            pair = Pair(other_stamp, stamp_ns, other_item, item, after_reset, gap)
        return [pair]

    def _closest(self, side: str, stamp_ns: int) -> int | None:
        """Index of the queued message on ``side`` closest to ``stamp_ns`` within slop."""
        stamps = self._stamps[side]
        best: int | None = None
        best_distance = self._slop_ns + 1
        for index, stamp in enumerate(stamps):
            distance = abs(stamp - stamp_ns)
            if distance <= best_distance and distance <= self._slop_ns:
                # '<=' with increasing stamps: a tie goes to the newer message.
                best, best_distance = index, distance
        return best

    def _enqueue(self, side: str, stamp_ns: int, item: Any) -> None:
        stamps, items = self._stamps[side], self._items[side]
        index = bisect.bisect_right(stamps, stamp_ns)
        stamps.insert(index, stamp_ns)
        items.insert(index, item)
        if len(stamps) > self._queue_size:
            del stamps[0]
            del items[0]
            self._counts['dropped_overflow'] += 1
