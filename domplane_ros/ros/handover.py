"""The newest-wins hand-over from the image callbacks to the node's worker (no ROS imports).

Callbacks must stay cheap and stale pairs must not queue up: :class:`NewestSlot` holds at most
one item. :meth:`NewestSlot.put` replaces an item the worker has not taken yet (and counts it
as dropped; a ``merge`` function can carry what the dropped item knew into the new one);
:meth:`NewestSlot.take` blocks until there is an item and returns the newest.
"""

from __future__ import annotations

import threading
from typing import Callable, Generic, TypeVar

T = TypeVar('T')


class NewestSlot(Generic[T]):
    """A one-item hand-over between threads where the newest item wins.

    Attributes:
        put_count: Items put so far.
        dropped: Items replaced before they were taken.

    """

    def __init__(self, merge: Callable[[T, T], T] | None = None) -> None:
        """Start empty and open.

        Args:
            merge: ``merge(replaced, new)`` returns the item to keep when ``new`` replaces an
                item not taken yet (None: keep ``new`` as it is).

        """
        self._merge = merge
        self._cv = threading.Condition()
        self._item: T | None = None
        self._closed = False
        self.put_count = 0
        self.dropped = 0

    def put(self, item: T) -> bool:
        """Hand over ``item``, replacing one not taken yet.

        Returns:
            True if an item was replaced (and counted in :attr:`dropped`).

        """
        with self._cv:
            replaced = self._item is not None
            if replaced:
                self.dropped += 1
                if self._merge is not None:
                    item = self._merge(self._item, item)
            self._item = item
            self.put_count += 1
            self._cv.notify()
        return replaced

    def take(self, timeout: float | None = None) -> T | None:
        """Wait for an item and return it (the newest put).

        Args:
            timeout: Longest wait in seconds (None: until an item comes or the slot closes).

        Returns:
            The item, or None if the slot was closed or the wait timed out.

        """
        with self._cv:
            self._cv.wait_for(lambda: self._item is not None or self._closed, timeout)
            if self._closed:
                return None
            item, self._item = self._item, None
            return item

    def take_nowait(self) -> T | None:
        """Return the item waiting (None if there is none), also after :meth:`close`."""
        with self._cv:
            item, self._item = self._item, None
            return item

    @property
    def pending(self) -> bool:
        """Return whether an item waits to be taken."""
        with self._cv:
            return self._item is not None

    def close(self) -> None:
        """Wake every waiting :meth:`take` with None; later takes return None at once."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()
