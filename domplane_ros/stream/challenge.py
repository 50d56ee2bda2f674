"""The challenge of a lock, spread over pairs so that no pair pays for all of it.

Every ``verification.challenge_period`` locked pairs the pipeline lets other planes challenge
the lock (a lock that slid into a look-alike is not caught by its own verification). The
challengers are the coarse photometric alignment's planes and the prior's best-screened
candidates, each refined on the features and verified. Done in one pair that cost 250-350 ms
at 640 x 480 (eight to ten warm pairs), so the challenge is a queue of tasks, one per locked
pair, each bounded by one refinement or one screening (measured 10-45 ms):

1. ``coarse``: the coarse alignment of this pair in two steps, its forward DIS flow here
   (the pipeline runs the ``screen`` task in the same pair), then a ``coarse step`` task,
   the backward flow and the fits (at 640x480 about 9 + 5 and 9 + 4 ms CPU, where the
   alignment alone was 22-27 ms and the screening 14-15); its planes, moved through the
   cameras' motion since the pair they were aligned on, become ``coarse start`` tasks,
   except starts within :data:`NEAR_LOCK_PX` of the lock or of a start already queued (they
   converge to the lock or to the same plane: measured, starts 1.8 to 11.8 px from the lock
   ended within 0.22 px of it);
2. one ``coarse start`` per pair: refined from the start moved through the cameras' motion
   since (``H' = M_right H M_left^-1``, as the lock's prediction), verified, and taken if it
   beats the lock; without a motion the coarse starts are dropped;
3. ``screen``: the prior's screening on this pair, the short way
   (:meth:`~domplane_ros.core.estimator.TwoStep.best_screened`); its best
   :data:`PRIOR_STARTS` candidates (fixed homographies of the camera model, no motion)
   become ``prior start`` tasks.

A challenger that wins ends the challenge; so do a lost lock and a reset.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Generator, Iterable

from domplane_ros.core.homography import corner_distance_px
from domplane_ros.core.tracking import predict_plane_homography
import numpy as np

COARSE = 'coarse'
COARSE_STEP = 'coarse step'
SCREEN = 'screen'
COARSE_START = 'coarse start'
PRIOR_START = 'prior start'
# Prior candidates (best screening energy first) refined as challengers beside the coarse
# alignment's planes: the coarse flow misses floors that the prior's screening finds.
PRIOR_STARTS = 2
# A challenger's start this close to the lock at the image corners (pixels) is not refined:
# it would converge to the lock (the default potential's basin is ~10 px, docs/BENCHMARKS.md);
# a look-alike one plank or tile off lies 20-80 px away.
NEAR_LOCK_PX = 8.0


@dataclass
class Task:
    """One step of a challenge: its kind and, for a start, the (3, 3) start homography.

    A ``coarse step`` holds the alignment's remaining steps (a generator) and the cameras'
    motion ``(M_left, M_right)`` since the pair it aligns.
    """

    kind: str
    start: np.ndarray | None = None
    steps: Generator[None, None, np.ndarray] | None = None
    motions: tuple[np.ndarray, np.ndarray] = (np.eye(3), np.eye(3))


class Challenge:
    """The pending tasks of one challenge of the lock (see the module docstring)."""

    def __init__(self) -> None:
        """Start with the coarse alignment, then the prior's screening."""
        self._tasks: deque[Task] = deque([Task(COARSE), Task(SCREEN)])

    @property
    def done(self) -> bool:
        """Return True when no task is left."""
        return not self._tasks

    def next_task(self) -> Task | None:
        """Return the next task, or None when the challenge is done."""
        return self._tasks.popleft() if self._tasks else None

    def follow(self, motions: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Move the queued coarse starts through the cameras' motion (drop them without one).

        Args:
            motions: ``(M_left, M_right)`` (3, 3) float64 from the previous pair to this one,
                or None.

        """
        kept: deque[Task] = deque()
        for task in self._tasks:
            if task.kind == COARSE_STEP:
                if motions is None:
                    continue
                task = Task(COARSE_STEP, steps=task.steps, motions=(
                    motions[0] @ task.motions[0], motions[1] @ task.motions[1]))
            elif task.kind == COARSE_START:
                moved = None if motions is None else predict_plane_homography(
                    task.start, motions[0], motions[1])
                if moved is None:
                    continue
                task = Task(COARSE_START, moved)
            kept.append(task)
        self._tasks = kept

    def align(self, task: Task, lock: np.ndarray, size: tuple[int, int]) -> bool:
        """Run one step of the coarse alignment; queue it again, or its planes as starts.

        Args:
            task: A ``coarse step`` task (its steps generator and motion since).
            lock: (3, 3) float64 the lock's homography in this pair.
            size: ``(width, height)`` of the images, pixels.

        Returns:
            Whether the alignment is done (its planes queued).

        """
        assert task.kind == COARSE_STEP and task.steps is not None
        try:
            next(task.steps)
        except StopIteration as done:
            moved = (predict_plane_homography(plane, *task.motions) for plane in done.value)
            self.add_coarse_starts([m for m in moved if m is not None], lock, size)
            return True
        self._tasks.appendleft(task)
        return False

    def take(self, kind: str) -> bool:
        """Remove the first queued task of ``kind`` (to run now); return whether it was there."""
        for task in self._tasks:
            if task.kind == kind:
                self._tasks.remove(task)
                return True
        return False

    def add_coarse_starts(self, starts: Iterable[np.ndarray], lock: np.ndarray,
                          size: tuple[int, int]) -> int:
        """Queue the coarse alignment's planes, next, except those near the lock or each other.

        Args:
            starts: (3, 3) float64 planes of the coarse alignment of this pair.
            lock: (3, 3) float64 the lock's homography in this pair.
            size: ``(width, height)`` of the images, pixels.

        Returns:
            The number of starts queued.

        """
        new = [Task(COARSE_START, start) for start in distinct_starts(starts, size, lock)]
        self._tasks.extendleft(reversed(new))
        return len(new)

    def add_prior_starts(self, starts: Iterable[np.ndarray]) -> None:
        """Queue the prior's best-screened candidates, last."""
        self._tasks.extend(Task(PRIOR_START, np.asarray(s, np.float64)) for s in starts)


def distinct_starts(starts: Iterable[np.ndarray], size: tuple[int, int],
                    lock: np.ndarray | None = None) -> list[np.ndarray]:
    """Return the starts, in order, without those near the lock or an earlier start.

    Near: within :data:`NEAR_LOCK_PX` at the image corners; such starts converge to the same
    plane (measured: starts 1.8 to 11.8 px from a lock ended within 0.22 px of it).

    Args:
        starts: (3, 3) float64 start homographies.
        size: ``(width, height)`` of the images, pixels.
        lock: Optional (3, 3) float64 homography whose neighbours are left out too.

    Returns:
        The kept starts as (3, 3) float64 arrays.

    """
    kept: list[np.ndarray] = []
    others = [] if lock is None else [lock]
    for start in starts:
        start = np.asarray(start, np.float64)
        if all(corner_distance_px(start, other, *size) >= NEAR_LOCK_PX for other in others):
            others.append(start)
            kept.append(start)
    return kept
