"""A search's winner is published only if it is unique: the uniqueness rules of the pick.

:meth:`~domplane_ros.stream.trust.TrustGate.pick` judges a search's planes and its rivals
(the planes of swapped cameras) and hands the judged planes to :class:`Uniqueness`, which
chooses the winner or says why there is none. The point energy cannot tell a look-alike
plane one period off a periodic floor from the floor, and on such a floor the two explain
about the same share of the image; which one is the floor cannot be told from that pair, so
none is published.

Ground mode (:meth:`Uniqueness.ground_winner`): the verified plane of the highest peak score
wins if its score is at least :data:`~domplane_ros.stream.verdict.CHALLENGE_MARGIN` times
that of every rival (:func:`~domplane_ros.stream.verdict.is_rival`: distinct ground planes and
every plane of swapped cameras). A plane of swapped cameras is no rival when its residual
parallax refutes it (:meth:`Uniqueness.swap_refuted`, :data:`MIN_SWAP_BEYOND`,
:data:`SWAP_BEYOND_RATIO`, :data:`MAX_WINNER_BEYOND`), and a unique winner must also beat
every distinct ground plane of this head on the pixels both see
(:meth:`Uniqueness.shared_rival`, :data:`SHARED_RIVAL_SHARE`).

``verification.plane: any`` (:meth:`Uniqueness.any_winner`): distinct planes are told over
the whole image, a winner must lie on one plane (:data:`MAX_RESIDUAL_FLOW_PX`, after a fit of
two radial lenses; fits through the far field of a room are passed over and do not compete
by their score), and it must be unique in its own region too, against every distinct plane
judged. Nothing here imports ROS.
"""

from __future__ import annotations

from dataclasses import replace
import math
from typing import Callable, Hashable, Sequence

import cv2
from domplane_ros.core.coarse import CoarseAligner
from domplane_ros.core.flatness import one_plane_residual_px
from domplane_ros.core.result import PlaneEstimate
from domplane_ros.core.verification import AgreementMaps, own_region
from domplane_ros.stream.verdict import (BEYOND_RIVAL_SHARE, CHALLENGE_MARGIN, distinct_planes,
                                         is_rival, TWIN_RIVAL_SHARE, Verdict)
import numpy as np

# In ground mode the winner must also beat every distinct plane of this head by
# CHALLENGE_MARGIN over the textured pixels both planes map inside the right image
# (Uniqueness.shared_rival): the score divides by every textured pixel, so a look-alike of
# less disparity, which maps more of the image inside the right one, outscores the truth on a
# floor whose pattern fills the view (measured: a 16 cm checker on a rough rig, tuning seed 48
# of the sized floors, a plane 146 px off at 0.36 against the truth's 0.30; on the pixels both
# see, the two explain as much). Rivals scoring under this share of the winner's are not
# compared (each comparison costs a rival's agreement maps).
SHARED_RIVAL_SHARE = 0.5
# A plane of swapped cameras that would make a search's winner ambiguous is refuted when at
# least MIN_SWAP_BEYOND of the textured flow samples lie beyond it in the swapped reading,
# SWAP_BEYOND_RATIO times the winner's share, and at most MAX_WINNER_BEYOND lie beyond the
# winner (Uniqueness.swap_refuted). Measured on tuning seeds: docs/BENCHMARKS.md, trust round
# 12 (true floors at most 0.004, swapped cameras' floors read as swapped at most 0.013, swapped
# look-alikes on correctly ordered pairs at least 0.018).
MIN_SWAP_BEYOND = 0.01
SWAP_BEYOND_RATIO = 4.0
MAX_WINNER_BEYOND = 0.01
# With verification.plane any, a search's winner must lie on one plane: the median residual
# flow over its supporting pixels (core/flatness.py), after its photometric refinement, at
# most this many pixels. Measured on the rendered boards' tuning seeds (sim/boards.py): the
# published true boards 0.02-0.04 px (12 seeds), the planes through the room behind a board
# that a search published 0.41-1.14 px (seeds 10, 15, 29). The tuning run with it: 17 of 30
# published, 17 correct, 0 wrong (before it: 18, 17 and 1).
MAX_RESIDUAL_FLOW_PX = 0.3

# One judged plane: the estimate (None for a rival), its (3, 3) homography, its verdict.
Judged = tuple[PlaneEstimate | None, np.ndarray, Verdict]
# The answer of a pick: the winner and its verdict (None, None if none) and, if none, why.
Pick = tuple[PlaneEstimate | None, Verdict | None, str]
# The gate's memo for the pair of TrustGate.begin_pair: (left, right, key, compute) ->
# compute(), computed once per key for that pair (every time for other images).
PerPair = Callable[[np.ndarray, np.ndarray, Hashable, Callable[[], np.ndarray]], np.ndarray]
# The gate's agreement maps of a plane on a pair, without the peak probes, at the gate's
# verification settings (on the pair's once-shrunk images between begin_pair and end_pair):
# (left, right, homography, roi) -> AgreementMaps.
Maps = Callable[[np.ndarray, np.ndarray, np.ndarray, Sequence[float] | None], AgreementMaps]
# The gate's test that a plane which looks swapped is the floor of swapped cameras read so
# (TrustGate.swap_seen): (homography, roi, (left, right)) -> bool.
SwapSeen = Callable[[np.ndarray, Sequence[float] | None, tuple[np.ndarray, np.ndarray]], bool]


class Uniqueness:
    """The uniqueness rules of a search's pick, over one gate's coarse aligner and memo.

    Args:
        coarse: The gate's photometric alignment (residual parallax, refinement).
        per_pair: The gate's memo for the pair of ``begin_pair`` (:data:`PerPair`).
        maps: The gate's agreement maps of a plane (:data:`Maps`).

    """

    def __init__(self, coarse: CoarseAligner, per_pair: PerPair, maps: Maps,
                 swap_seen: SwapSeen = lambda homography, roi, pair: True) -> None:
        """Keep the gate's aligner, memo and maps; the optical flow is made when first needed."""
        self._coarse = coarse
        self._per_pair = per_pair
        self._maps = maps
        self._swap_seen = swap_seen
        self._flow: cv2.DISOpticalFlow | None = None

    def ground_winner(self, left: np.ndarray, right: np.ndarray, judged: list[Judged],
                      verified: list[Judged], roi: Sequence[float] | None) -> Pick:
        """Return the pick of ``verification.plane: ground``: the best verified plane if unique.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image.
            judged: Every plane judged on the pair, rivals included.
            verified: The accepted ones among them (not empty).
            roi: Region of the left image (fractions), as ``features.roi``.

        Returns:
            The winner and its verdict (uniqueness, ``beyond_rival`` and ``twin_rival`` set), or
            None, None and why the pair is ambiguous.

        """
        height, width = left.shape
        best, best_h, verdict = max(verified, key=lambda item: item[2].peak_score)
        rivals = [(v.score, v.swapped, h) for _, h, v in judged
                  if is_rival(v, h, best_h, width, height)
                  and not self.swap_refuted(left, right, best_h, verdict, h, v)]
        top, top_swapped, top_h = max(rivals, key=lambda item: item[:2],
                                      default=(0.0, False, None))
        # The best plane refused only for the texture beyond it, if it outscores the winner
        # (BEYOND_RIVAL_SHARE): the search compares it with the winner once finished.
        beyond = max((v.score for _, _, v in judged if v.beyond), default=0.0)
        # The best plane of the winner's own ground (the same over the bottom rows) verified but
        # refused though a ground plane, i.e. for its middle band (TWIN_RIVAL_SHARE), if at
        # least that share of the winner's score at the pick (the refusal compares it with the
        # winner's finished score): compared with the winner once finished.
        twin = max((v.score for _, h, v in judged
                    if v.ground and not v.accepted and not v.swapped and v.verification.accepted
                    and not distinct_planes(h, best_h, width, height)), default=0.0)
        verdict = replace(verdict, uniqueness=verdict.score / top if top > 0 else math.inf,
                          beyond_rival=(beyond if beyond >= BEYOND_RIVAL_SHARE * verdict.score
                                        else 0.0),
                          twin_rival=twin if twin >= TWIN_RIVAL_SHARE * verdict.score else 0.0)
        if verdict.uniqueness >= CHALLENGE_MARGIN:
            shared = self.shared_rival(left, right, best_h, verdict, judged, roi)
            if shared:
                return None, None, shared
            return best, verdict, ''
        kind, hint = 'distinct plane', 'a periodic floor?'
        if top_swapped:
            # Named by what it is (the decision is the same): the floor of swapped cameras,
            # or a surface facing the head that only looks swapped (TrustGate.swap_seen).
            seen = self._swap_seen(top_h, roi, (left, right))
            kind, hint = (('plane of swapped cameras', hint) if seen else
                          ('plane whose disparity shrinks toward the image bottom',
                           'read with left and right exchanged it sees no ground: a '
                           'periodic floor, or an obstacle or a wall close ahead?'))
        return None, None, (f'ambiguous: a {kind} explains the image almost as well '
                            f'(score {top:.2f} against {verdict.score:.2f} < '
                            f'{CHALLENGE_MARGIN:g} x; {hint})')

    def shared_rival(self, left: np.ndarray, right: np.ndarray, best_h: np.ndarray,
                     verdict: Verdict, judged: list[Judged], roi: Sequence[float] | None
                     ) -> str:
        """Return why the winner is ambiguous on the pixels it shares with a rival ('' if not).

        See :data:`SHARED_RIVAL_SHARE`. Compared with every distinct ground plane of this head
        judged on the pair that scores at least that share of the winner: the winner's
        supporting pixels among the textured pixels both map inside the right image, each
        counted as in the score, must be at least :data:`CHALLENGE_MARGIN` times the rival's
        there.
        """
        height, width = left.shape
        rivals = [h for _, h, v in judged
                  if v.ground and not v.swapped and v.score >= SHARED_RIVAL_SHARE * verdict.score
                  and distinct_planes(h, best_h, width, height)]
        if not rivals:
            return ''
        mine = self._maps(left, right, best_h, roi)
        for h in rivals:
            theirs = self._maps(left, right, h, roi)
            both = mine.inside & theirs.inside
            # Each pixel counts as in the score (core/verification.py, step 5).
            ours = float(mine.weight[mine.support & both].sum(dtype=np.float64))
            other = float(theirs.weight[theirs.support & both].sum(dtype=np.float64))
            if other * CHALLENGE_MARGIN > ours:
                share = other / max(ours, 1e-9)
                return ('ambiguous: a distinct plane explains the pixels both planes see almost '
                        f'as well ({share:.2f} of the support of the winner there > 1 / '
                        f'{CHALLENGE_MARGIN:g}; a periodic floor?)')
        return ''

    def swap_refuted(self, left: np.ndarray, right: np.ndarray, best: np.ndarray,
                     verdict: Verdict, rival: np.ndarray, rival_verdict: Verdict) -> bool:
        """Return whether a plane of swapped cameras is refuted by its residual parallax.

        Only a swapped plane that would make the winner ambiguous (a score above the
        winner's over :data:`CHALLENGE_MARGIN`) is tested. Nothing is seen beyond the ground
        (:meth:`~domplane_ros.core.coarse.CoarseAligner.beyond_share`): a swapped floor's
        look-alike of a periodic floor leaves the texture that does not repeat (boxes, the
        tiles' shading) beyond it in the swapped reading, the true floor nothing beyond it.
        The swapped plane is refuted when at least :data:`MIN_SWAP_BEYOND` of the texture lies
        beyond it, :data:`SWAP_BEYOND_RATIO` times the winner's share, and at most
        :data:`MAX_WINNER_BEYOND` lies beyond the winner (a winner a few pixels off a faint
        floor has the floor beyond it: tuning faint seed 11, 6 px off, 0.085). Real swapped
        cameras make the swapped plane the truth, with nothing beyond it: not refuted.
        """
        if not rival_verdict.swapped or rival_verdict.score * CHALLENGE_MARGIN <= verdict.score:
            return False
        theirs = self.beyond_share(left, right, rival, True)
        if theirs < MIN_SWAP_BEYOND:
            return False
        mine = self.beyond_share(left, right, best, False)
        return mine <= MAX_WINNER_BEYOND and theirs >= SWAP_BEYOND_RATIO * mine

    def beyond_share(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                     swapped: bool) -> float:
        """Return :meth:`CoarseAligner.beyond_share`, once per plane and pair."""
        key = ('beyond', np.asarray(homography, np.float64).tobytes(), swapped)
        return float(self._per_pair(left, right, key, lambda: np.array(
            self._coarse.beyond_share(left, right, homography, swapped))))

    def any_winner(self, left: np.ndarray, right: np.ndarray, judged: list[Judged],
                   verified: list[Judged], roi: Sequence[float] | None) -> Pick:
        """Return the pick of ``verification.plane: any``.

        The verified planes are taken by peak score; one that is not one plane
        (:meth:`several_planes`: a fit through the room behind a small board, which in a
        textured room explains more of the image than the board) is not the winner, and the
        next is tried. The first that is one plane is published if it is unique (distinct
        planes over the whole image: a board need not be at the bottom): its score at least
        :data:`CHALLENGE_MARGIN` times that of every distinct plane judged that is one plane,
        and its support in its own region (:func:`~domplane_ros.core.verification.own_region`)
        that many times that of every distinct plane judged there, one plane or not (a
        board's own plane refused for the lens it is seen through still beats its
        look-alike some squares off; a fit through the room does not reach into the board).
        Arguments and answer as :meth:`ground_winner`.
        """
        height, width = left.shape
        several = ''
        for best, best_h, verdict in sorted(verified, key=lambda item: -item[2].peak_score):
            several = self.several_planes(left, right, best_h, roi)
            if several:
                continue
            least = verdict.score / CHALLENGE_MARGIN
            rivals = [(h, v) for _, h, v in judged
                      if is_rival(v, h, best_h, width, height, rows=0.0)]
            top = max((v.score for h, v in rivals
                       if v.score <= least
                       or not self.several_planes(left, right, h, roi)),
                      default=0.0)
            verdict = replace(verdict, uniqueness=verdict.score / top if top > 0 else math.inf)
            if verdict.uniqueness < CHALLENGE_MARGIN:
                return None, None, ('ambiguous: a distinct plane explains the image almost '
                                    f'as well (score {top:.2f} against {verdict.score:.2f} < '
                                    f'{CHALLENGE_MARGIN:g} x; a periodic board?)')
            maps = self._maps(left, right, best_h, roi)
            own = own_region(maps)
            mine = int(np.count_nonzero(maps.support & own))
            for h, _ in rivals:
                theirs = int(np.count_nonzero(
                    self._maps(left, right, h, roi).support & own))
                if theirs * CHALLENGE_MARGIN > mine:
                    return None, None, ('ambiguous: a distinct plane explains its region '
                                        f'almost as well ({theirs} against {mine} supporting '
                                        f'pixels < {CHALLENGE_MARGIN:g} x; a periodic board?)')
            return best, verdict, ''
        return None, None, several

    def several_planes(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                       roi: Sequence[float] | None) -> str:
        """Return why a winner of ``verification.plane: any`` is no one plane ('' if it is).

        A plane fitted through surfaces at several depths (the far field of a room) passes
        the verification's working scale; its supporting pixels are then about a pixel off it
        and off its photometric refinement
        (:meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.refined`) alike
        (:func:`~domplane_ros.core.flatness.residual_flow_px` of the refinement). The ground
        checks refuse such planes in ``ground`` mode, so this runs in ``any`` mode only
        (:meth:`any_winner`). Once per plane and pair.
        """
        key = ('flow', np.asarray(homography, np.float64).tobytes())
        residual = float(self._per_pair(left, right, key, lambda: self._residual_flow(
            left, right, homography, roi)))
        if residual <= MAX_RESIDUAL_FLOW_PX:
            return ''
        return (f'not one plane: its supporting pixels are {residual:.2f} px off it '
                f'(median residual flow, after a fit of radial lenses, > '
                f'{MAX_RESIDUAL_FLOW_PX:g}); surfaces at several depths, such as the '
                'room behind a small board?')

    def _residual_flow(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                       roi: Sequence[float] | None) -> np.ndarray:
        """Return the median residual flow (px, 0-d array) of the plane's refinement."""
        if self._flow is None:
            self._flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        maps = self._maps(left, right, homography, roi)
        # A search's candidates are refined only once picked: the plane's photometric
        # refinement is measured, so that a true plane a few tenths of a pixel off (not yet
        # finished) is not refused; a fit through several surfaces stays one.
        refined = self._coarse.refine(left, right, homography)
        return np.array(one_plane_residual_px(
            left, right, homography if refined is None else refined, maps.support, self._flow))
