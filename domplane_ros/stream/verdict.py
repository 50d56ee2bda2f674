"""The gate's decision on one plane, and when two planes compete for uniqueness.

:class:`Verdict` is what :class:`~domplane_ros.stream.trust.TrustGate` says of a plane (publish
it or why not, its confidence, its uniqueness among the planes judged on the same pair);
:func:`is_rival` and :func:`distinct_planes` say which judged planes a winner must beat by
:data:`CHALLENGE_MARGIN`. Nothing here imports ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math

from domplane_ros.core.verification import PlaneVerification
import numpy as np

# A challenger replaces the lock only if its score is this many times the lock's: a plane a
# fraction of a pixel away scores about the same and must not churn the lock.
CHALLENGE_MARGIN = 1.2
# Two planes are distinct when they map the bottom of the image (a 5 x 5 grid over the lowest
# 40 % of the rows, where the ground is) more than this many pixels apart (median); closer
# ones are the same plane refined differently (starts 1.8-11.8 px apart converge to the same
# plane, stream/challenge.py NEAR_LOCK_PX). The median, not the largest: two fits of the same
# floor, 0.6 and 0.8 px from the truth over it, were measured 8-20 px apart where they
# extrapolate beyond it.
DISTINCT_PX = 8.0
# The first row (share of the height) of that grid for the ground: the lowest 40 %.
GROUND_ROWS = 0.6
# A search's winner, finished (the configured tolerance, the polish, the photometric
# refinement), must score at least this share of every plane of its pick refused only for the
# texture beyond it (``Verdict.beyond``: a plane through obstacles above the floor, or the
# floor fitted a pixel or two off; ``Verdict.beyond_rival``, stream/search.py): else the image
# is explained better by a plane the gate refused, and the winner is not the ground's best
# fit. Measured: tuning lighting seed 168, the floor fitted 1.35 px off at 0.465 refused for
# 3 % of the texture beyond it, beside which a plane 5.5 px off, 0.293 finished, was published.
# Compared before the finish it lost correct planes (a review, session 14: 5 of 1,200 pairs,
# e.g. cold 7024, a pick 6.4 px off at 0.39 that finished 0.13 px off at 0.70).
BEYOND_RIVAL_SHARE = 1.0
# Likewise a search's winner, once finished, must score at least this share of every plane of
# its pick that maps the image bottom as it does (not distinct_planes) and was verified but
# refused though a ground plane (``Verdict.ground``: in a search only for the band between the
# top and bottom it explains, ground_rules.MIN_MIDDLE_SHARE; ``Verdict.twin_rival``,
# stream/search.py): else the winner is a
# partial fit of a ground that explains the image clearly better (CHALLENGE_MARGIN times) but
# was refused, and which of the two is the floor cannot be told. Such a plane is no rival for
# uniqueness (the same plane by the bottom rows). Measured: rendered held-out ahead 23025, a
# box close ahead filling the middle of the view; the floor (0.15 px off, score 0.63) was
# refused for its middle band (91 % of the top and 71 % of the bottom explained, 26 %
# between), and a plane 12.6 px off (10.7 px finished, 0.37: 1.69 times less), within 8 px of
# it over the bottom rows, was published. A share of 1 (any twin scoring more) also refused
# four planes published under 5 px on the tuning seeds 0-39 (ahead 10 and 23, floors 1,
# floors_rough 1: 0.65, 1.71, 0.21 and 1.36 px off, twins 1.05-1.18 times their score); the
# margin keeps them (docs/BENCHMARKS.md round 29).
TWIN_RIVAL_SHARE = 1.0 / CHALLENGE_MARGIN


@dataclass(frozen=True)
class Verdict:
    """The gate's decision on one plane.

    Attributes:
        accepted: Publish it.
        verification: The photometric verification (score, confidence, fractions).
        reason: Empty when accepted, else one line saying why not.
        swapped: The plane looks like one of swapped left and right cameras.
        uniqueness: Its score over the best score of a distinct plane judged on the same pair
            (:meth:`TrustGate.pick`); inf when there was none.
        ground: False for a plane refused as no ground plane (a wall, a plane through boxes
            above the floor): it does not compete with ground planes for uniqueness. A plane
            refused for the band between the top and bottom it explains (a far wall aliasing
            a periodic floor, ``ground_rules.MIN_MIDDLE_SHARE``) keeps True: a look-alike of the
            floor that explains as much still makes the pair ambiguous.
        beyond: Refused (``ground`` False) only for the texture that lies beyond it.
        beyond_rival: The best score of a plane judged beside a search's winner and refused
            only for the texture beyond it, if at least :data:`BEYOND_RIVAL_SHARE` x the
            winner's score (:meth:`Uniqueness.ground_winner`), else 0: the winner finished
            must score at least that share of it to be published.
        twin_rival: The best score of a plane judged beside a search's winner, the same plane
            as it over the image bottom (not :func:`distinct_planes`), verified but refused
            though a ground plane (for its middle band), if at least :data:`TWIN_RIVAL_SHARE`
            x the winner's score at the pick, else 0: the winner finished must score at least
            that share of it to be published.
        lock_refusal: For a locked plane refused by a hold of the lock, which one:
            ``'drop'`` (its recent median, ``verification.drop_ratio``), ``'reference'`` or
            ``'bottom'`` (the plane it started from, ``trust.LOCK_REFERENCE``); else ''
            (:mod:`domplane_ros.stream.refusals`).
    """

    accepted: bool
    verification: PlaneVerification
    reason: str
    swapped: bool = False
    uniqueness: float = math.inf
    ground: bool = True
    beyond: bool = False
    beyond_rival: float = 0.0
    twin_rival: float = 0.0
    lock_refusal: str = ''

    @property
    def confidence(self) -> float:
        """Return the confidence in [0, 1]: 0 for a swapped plane, else the lesser of two.

        The verification's confidence (0.5 at ``verification.min_score``, 1 at 0.1 above
        it) and the uniqueness's: 0.5 at :data:`CHALLENGE_MARGIN` (the least a search
        publishes), 0 at a tie with a distinct plane, 1 at twice the margin above 1.
        """
        if self.swapped:
            return 0.0
        unique = float(np.clip((self.uniqueness - 1.0) / (2.0 * (CHALLENGE_MARGIN - 1.0)),
                               0.0, 1.0)) if math.isfinite(self.uniqueness) else 1.0
        return min(self.verification.confidence, unique)

    def with_pick(self, pick: Verdict) -> Verdict:
        """Return this verdict with what the pick found beside its plane: ``pick``'s.

        The fields set by :meth:`Uniqueness.ground_winner` (``uniqueness``, ``beyond_rival``,
        ``twin_rival``): a finished or refined plane is judged again alone, and keeps what
        its candidate was compared with.
        """
        return replace(self, uniqueness=pick.uniqueness, beyond_rival=pick.beyond_rival,
                       twin_rival=pick.twin_rival)

    @property
    def score(self) -> float:
        """Return the verification score in [0, 1]."""
        return self.verification.score

    @property
    def peak_score(self) -> float:
        """Return the verification's peak score in [0, 1] (ranks planes a few px apart)."""
        return self.verification.peak_score


def is_rival(verdict: Verdict, homography: np.ndarray, best: np.ndarray, width: int,
             height: int, rows: float = GROUND_ROWS) -> bool:
    """Return whether a judged plane competes with the best for uniqueness.

    A plane of swapped cameras always does (the other hypothesis about the head, however
    close it maps: measured, a checker's swapped floor 0.6 px from the truth and a look-alike
    9 px off it, within 8 px of each other at the image bottom); a plane of this head only
    when distinct; walls and planes through obstacles never (``Verdict.ground``; a plane
    refused for the texture beyond it is held against the finished winner instead,
    :data:`BEYOND_RIVAL_SHARE`).
    """
    return verdict.ground and (verdict.swapped
                               or distinct_planes(homography, best, width, height, rows))


def distinct_planes(first: np.ndarray, second: np.ndarray, width: int, height: int,
                    rows: float = GROUND_ROWS) -> bool:
    """Return whether two planes map the image > DISTINCT_PX apart (median).

    Over a 5 x 5 grid from row ``rows * (height - 1)`` to the bottom: the ground's rows
    (:data:`GROUND_ROWS`), or the whole image (0) for ``verification.plane: any``, where the
    plane may be anywhere.
    """
    xs, ys = np.meshgrid(np.linspace(0, width - 1, 5), np.linspace(rows * (height - 1),
                                                                   height - 1, 5))
    points = np.column_stack([xs.ravel(), ys.ravel(), np.ones(xs.size)]).T
    a, b = first @ points, second @ points
    with np.errstate(divide='ignore', invalid='ignore'):
        distance = np.median(np.linalg.norm(a[:2] / a[2] - b[:2] / b[2], axis=0))
    return not distance <= DISTINCT_PX
