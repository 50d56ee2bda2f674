"""Why a pair's plane was refused and why a lock was lost: kinds, and counts since start.

A refused warm plane does not end a pair: the pipeline searches in the same pair, and what
the search says (a plane, or its own reason) is the pair's outcome. So that the first refusal
is not lost, each pair keeps every refusal that turned its course, and a challenger refused
while the lock stays, in order
(:attr:`~domplane_ros.stream.frame.FrameResult.refusals`), and the lock loss, if any
(:attr:`~domplane_ros.stream.frame.FrameResult.lock_lost`); :class:`RefusalCounts` counts
them since the pipeline started, for ``/diagnostics`` and the replay's summary. No ROS
imports.

Refusal kinds (a refused plane or warm start, :data:`REFUSAL_KINDS`):

* ``reference``: a warm plane scoring under ``trust.LOCK_REFERENCE_RATIO`` x the score the
  lock started from; ``bottom``: explaining under ``trust.LOCK_BOTTOM_RATIO`` x the share of
  the image bottom it started from; ``drop``: scoring under ``verification.drop_ratio`` x the
  lock's recent median.
* ``gate``: a warm plane refused by the rest of the verification gate (not verified, not the
  ground, swapped cameras, ...).
* ``estimate``: a warm estimate refused before the gate (no convergence, an energy jump,
  outside the prior, too little spread, too few features).
* ``cut``: the lock as a warm start, because the previous pair cannot be tracked into this
  one; ``view change``: the lock of a pair with too few corners that its texture refutes.
* ``search``: a search's finished winner, or the search's end without a plane.
* ``challenge``: a challenger that beat the lock, refused once finished as not the prior's
  ground (its roll, slope, or the bands rule: ``TrustGate.ground_refusal``); the lock stays.

Lock-loss kinds (:data:`LOCK_LOSS_KINDS`): the first seven refusal kinds above but ``estimate``
(a warm refusal that starts a search in the same pair), ``challenger`` (a plane that
explained clearly more of the image replaced the lock), ``tracking`` (the lock was carried
``pipeline.max_tracking_frames`` pairs without a plane) and ``reset`` (the warm start was
dropped: a stamp jump or a size change, a reset pair, a changed prior).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import json
from typing import Any, Iterable

REFERENCE = 'reference'
BOTTOM = 'bottom'
DROP = 'drop'
GATE = 'gate'
ESTIMATE = 'estimate'
CUT = 'cut'
VIEW_CHANGE = 'view change'
SEARCH = 'search'
CHALLENGE = 'challenge'
CHALLENGER = 'challenger'
TRACKING_ENDED = 'tracking'
RESET = 'reset'

REFUSAL_KINDS = (REFERENCE, BOTTOM, DROP, GATE, ESTIMATE, CUT, VIEW_CHANGE, SEARCH, CHALLENGE)
LOCK_LOSS_KINDS = (REFERENCE, BOTTOM, DROP, GATE, CUT, VIEW_CHANGE, CHALLENGER,
                   TRACKING_ENDED, RESET)
# The diagnostics key of the pair's lock loss, of the last lock loss, and of the count of
# locks lost to a refusal whose search published a plane in the same pair.
LOCK_LOST_KEY = 'lock lost (last frame)'
LAST_LOCK_LOST_KEY = 'last lock lost'
REFOUND_KEY = 'locks re-found in the same pair'


def lock_lost_key(kind: str) -> str:
    """Return the diagnostics key counting locks lost for ``kind``: ``locks lost (cut)``."""
    return f'locks lost ({kind})'


def refused_key(kind: str) -> str:
    """Return the diagnostics key counting refusals of ``kind``: ``planes refused (drop)``."""
    return f'planes refused ({kind})'


@dataclass(frozen=True)
class Refusal:
    """One refusal (or lock loss): its kind and the one-line reason.

    Attributes:
        kind: One of :data:`REFUSAL_KINDS` or :data:`LOCK_LOSS_KINDS`.
        reason: Why, as the gate or the check said it.

    """

    kind: str
    reason: str

    def __str__(self) -> str:
        """Return ``'kind: reason'``, as the CSV and ``/diagnostics`` show it."""
        return f'{self.kind}: {self.reason}'


def challenger_won(challenger_peak: float, margin: float, lock_peak: float) -> Refusal:
    """Return the lock loss to a challenger (peak scores; ``margin``: the least ratio)."""
    return Refusal(CHALLENGER, 'a challenger explained clearly more of the image (peak score '
                   f"{challenger_peak:.2f} > {margin:g} x the lock's {lock_peak:.2f})")


def challenge_refused(reason: str) -> Refusal:
    """Return the refusal of a challenger that beat the lock but is not the ground."""
    return Refusal(CHALLENGE, f'a challenger beat the lock but is refused: {reason}; '
                   'the lock stays')


def tracking_ended(carried: int, reason: str) -> Refusal:
    """Return the lock loss after ``carried`` pairs without a plane, the last for ``reason``."""
    return Refusal(TRACKING_ENDED, f'{carried} pairs carried without a plane '
                   f'(pipeline.max_tracking_frames); then: {reason}')


def view_changed(reason: str) -> Refusal:
    """Return the refusal of a lock whose corners are gone and that the texture refutes."""
    return Refusal(VIEW_CHANGE, 'the view changed: the lock (its corners gone) and its '
                   f'photometric refinement explain too little of a textured image ({reason})')


def refusals_text(refusals: Iterable[Refusal]) -> str:
    """Return a pair's refusals as the CSV column: a JSON list of ``'kind: reason'``."""
    return json.dumps([str(refusal) for refusal in refusals])


def lock_lost_text(lock_lost: Refusal | None) -> str:
    """Return a pair's lock loss as the CSV column and result value: ``'kind: reason'`` or ''."""
    return str(lock_lost) if lock_lost is not None else ''


@dataclass
class RefusalCounts:
    """Lock losses and refusals counted since start (every kind present, 0 included).

    Attributes:
        locks_lost: Locks lost per kind (:data:`LOCK_LOSS_KINDS`).
        planes_refused: Refusals per kind (:data:`REFUSAL_KINDS`).
        refound: Locks lost to a refusal (not to a challenger, a reset or the end of the
            tracking pairs) whose search published a plane in the same pair.
        last_lock_lost: The last lock loss, or None.

    """

    locks_lost: dict[str, int] = field(
        default_factory=lambda: dict.fromkeys(LOCK_LOSS_KINDS, 0))
    planes_refused: dict[str, int] = field(
        default_factory=lambda: dict.fromkeys(REFUSAL_KINDS, 0))
    refound: int = 0
    last_lock_lost: Refusal | None = None

    def add(self, lock_lost: Refusal | None, refusals: Iterable[Refusal],
            published: bool) -> None:
        """Count one pair's lock loss (None: none) and refusals; ``published``: it has a plane."""
        for refusal in refusals:
            self.planes_refused[refusal.kind] += 1
        if lock_lost is not None:
            self.locks_lost[lock_lost.kind] += 1
            self.last_lock_lost = lock_lost
            if published and lock_lost.kind in REFUSAL_KINDS:
                self.refound += 1

    def diagnostic_values(self, lock_lost: Refusal | None) -> list[tuple[str, Any]]:
        """Return the diagnostics values; ``lock_lost``: the shown pair's lock loss.

        Keys: :data:`LOCK_LOST_KEY` and :data:`LAST_LOCK_LOST_KEY` (``'kind: reason'`` or
        ``none``), one :func:`lock_lost_key` per lock-loss kind, :data:`REFOUND_KEY`, one
        :func:`refused_key` per refusal kind.
        """
        last = self.last_lock_lost
        return [
            (LOCK_LOST_KEY, str(lock_lost) if lock_lost is not None else 'none'),
            (LAST_LOCK_LOST_KEY, str(last) if last is not None else 'none'),
            *[(lock_lost_key(kind), self.locks_lost[kind]) for kind in LOCK_LOSS_KINDS],
            (REFOUND_KEY, self.refound),
            *[(refused_key(kind), self.planes_refused[kind]) for kind in REFUSAL_KINDS],
        ]

    def summary_lines(self) -> list[str]:
        """Return the replay summary's lines: locks lost and planes refused, by kind."""
        return [_count_line('  locks lost:      ', self.locks_lost)
                + f', re-found in the same pair {self.refound}',
                _count_line('  planes refused:  ', self.planes_refused)]


def _count_line(head: str, counts: dict[str, int]) -> str:
    total = sum(counts.values())
    kinds = ', '.join(f'{kind} {count}' for kind, count in counts.items() if count)
    return head + (f'{total} ({kinds})' if total else '0')
