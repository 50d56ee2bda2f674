"""Verify, then publish: the gate every plane passes before anything downstream sees it.

The point energy cannot tell a look-alike plane from the floor, so every plane the pipeline
would publish is checked here by evidence the corners do not use
(:func:`~domplane_ros.core.verification.verify_plane`: the share of the image's texture that
this plane, and not the same plane moved slightly, explains) and by the geometry of a ground
plane (:func:`~domplane_ros.core.ground_slope.swap_evidence`: its disparity must grow toward
the image bottom, or left and right are swapped; and, for a plane about to be published,
:meth:`TrustGate.rolled_refusal`: it must grow straight down the image, as under a level head).

A search publishes a plane only if it is *unique*: it must explain clearly more of the image
(:data:`~domplane_ros.stream.verdict.CHALLENGE_MARGIN` times) than every distinct plane the
search found on the same pair, the planes of swapped cameras included. On a periodic floor a
look-alike one period off and the floor (or, with swapped cameras, the swapped floor) explain
about the same share; which one is the floor cannot be told from that pair, so none is
published. :meth:`TrustGate.pick` judges the planes; the rules of uniqueness are
:class:`~domplane_ros.stream.uniqueness.Uniqueness`'s. The confidence says so too: it is the
lesser of the score's confidence and the uniqueness's (:meth:`Verdict.confidence`).

While locked, a plane must also keep its score: a score that falls below a fraction of the
lock's recent median means the view changed under the warm start (a cut, a saccade, a camera
re-plugged) even if the new score still passes the absolute threshold. Every
``challenge_period`` locked frames a *challenger*, the best plane of the coarse photometric
alignment (:class:`~domplane_ros.core.coarse.CoarseAligner`), is refined and verified; if it
explains clearly more of the image than the lock, the lock is replaced.

The planes the gate judges but does not make (the coarse alignment's candidates, a plane's
photometric refinement, its period siblings, a photometric polish) are
:class:`~domplane_ros.stream.coarse_planes.CoarsePlanes`' (:attr:`TrustGate.planes`): they
share the gate's aligner and its memo of the pair of :meth:`TrustGate.begin_pair`.

With ``verification.plane: any`` the plane need not be the ground (a board, a wall): the
disparity-slope, bottom and beyond checks are off (so swapped cameras are not detected: they
cannot be told from one such plane), and a search's winner is judged beside its period
siblings (:meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.siblings`, the plane moved
by its texture's repeats): on a checkerboard a look-alike some squares off wins only if it
explains clearly more than they do (and it must be one plane, unique in its own region:
:meth:`~domplane_ros.stream.uniqueness.Uniqueness.any_winner`). A plane that explains too
little of the image may still be verified by its own region
(:func:`~domplane_ros.stream.ground_rules.own_region_verified`: a board covering a fifth of a
textured room). What a verified plane must show to be the ground (beyond, bands, slope,
roll) are the rules of :mod:`domplane_ros.stream.ground_rules`.
"""

from __future__ import annotations

from collections import deque
import statistics
from typing import Any, Callable, Hashable, Sequence

from domplane_ros.config import MaskConfig, PriorConfig, VerificationSettings
from domplane_ros.core.coarse import CoarseAligner, CoarseConfig
from domplane_ros.core.ground_slope import swap_evidence
from domplane_ros.core.result import PlaneEstimate
from domplane_ros.core.verification import (agreement_maps, AgreementMaps, PlaneVerification,
                                            updated, VerificationConfig, verify_plane,
                                            working_pair)
from domplane_ros.core.working_pair import WorkingPair
from domplane_ros.stream import ground_rules
from domplane_ros.stream.coarse_planes import CoarsePlanes
from domplane_ros.stream.near_field import (MIN_SWAPPED_GROUND, near_field_refusal,
                                            swapped_ground_share)
from domplane_ros.stream.refusals import BOTTOM, DROP, REFERENCE
from domplane_ros.stream.uniqueness import Judged, Pick, Uniqueness
from domplane_ros.stream.verdict import CHALLENGE_MARGIN, Verdict
import numpy as np

# Least disparity slope (pixels per row, roll-invariant; see swap_evidence) of a ground plane
# seen by a correctly ordered head: true planes measured at least +0.052 on rendered heads,
# rough rigs included; swapped cameras at most -0.052; a wall facing the head has about 0. A
# floor's slope is about b/h cos(tilt) less a vergence term, not b/h alone: over the
# renderer's set-ups of the default prior (tuning seeds 0-129 and 7000-13029, review of
# session 15) 110 of 6160 true floors lie under 0.04 and 4 under this 0.02 (least 0.016;
# 0.007 at a corner of the prior: f 400, b/h 0.05, tilt 50 deg, vergence 4 deg).
MIN_GROUND_SLOPE = 0.02
# Where a search ends on planes that look swapped, at most this many of them (the best
# scoring) are read swapped (TrustGate.swap_seen, one mask each) to name the refusal.
SWAP_SEEN_TRIED = 3
# A published plane must explain at least this share of the textured pixels in the lowest
# third of the region (PlaneVerification.bottom_score): the ground seen from above fills the
# bottom of the image. Measured on the tuning seeds 30-129 (cold, rough, swapped, faint tiles):
# the true planes published scored at least 0.16 there (1st percentile), the planes through
# boxes above a floor that passed the verification 0.0.
MIN_BOTTOM_SCORE = 0.05
# ... and at least this share of its own score: the ground explains the bottom of the image at
# least about as well as the whole (true planes of 100 rendered tuning scenes: 0.37 and more,
# median above 1), a plane through a far wall or the boxes' faces mostly above it (measured:
# 0.10, a wall plane on a faint tiled floor, tuning seed 212, 8 px off the floor).
MIN_BOTTOM_SHARE = 0.25
# A held lock is also held against its reference (TrustGate.lock_reference): the verification
# of the plane it started from, i.e. the first plane published after a search (a search's
# finished winner) or a challenger that replaced the lock. A warm plane scoring under
# LOCK_REFERENCE_RATIO x that score, or explaining under LOCK_BOTTOM_RATIO x the share of the
# image bottom that it explained (PlaneVerification.bottom_score), is refused: the pipeline
# then searches in the same pair. The lock's history (the rolling median of its own last
# scores, verification.drop_ratio) follows a plane whose score falls slowly pair by pair and
# never fires; the reference does not move with it. The scene itself changes the true plane's
# score over a lock (measured below), so the ratios are loose: they catch a lock that slid off
# the floor, not a pixel of bias. False: the history alone, as before session 17.
LOCK_REFERENCE = True
LOCK_REFERENCE_RATIO = 0.7
LOCK_BOTTOM_RATIO = 0.4
# Working width limits of the verification, pixels.
MIN_WORKING_WIDTH = 64
MAX_WORKING_WIDTH = 480


class TrustGate:
    """The verification state of one stream: settings, the lock's score history, the challenger.

    Args:
        settings: The ``verification.*`` parameters.
        history: Frames of score history kept.
        prior: The camera set-up ranges (their focal lengths and principal point: the roll of
            a ground plane, :meth:`rolled_refusal`); None: the default prior.
        mask: The mask's settings (a new plane's own mask, :meth:`near_field_refusal`);
            None: the defaults.

    """

    def __init__(self, settings: VerificationSettings, history: int = 10,
                 prior: PriorConfig | None = None, mask: MaskConfig | None = None) -> None:
        """Start with no lock history."""
        self.settings = settings
        self.prior = prior if prior is not None else PriorConfig()
        self.mask = mask if mask is not None else MaskConfig()
        self._configs: dict[int, VerificationConfig] = {}
        self._coarse = CoarseAligner(CoarseConfig(width_px=settings.coarse_width_px))
        self._scores: deque[float] = deque(maxlen=history)
        self._locked_frames = 0
        self._reference: PlaneVerification | None = None
        self._pair: tuple[np.ndarray, np.ndarray] | None = None
        self._working: WorkingPair | None = None
        self._levels: tuple[np.ndarray, np.ndarray, int] | None = None
        self._memo: dict[Any, np.ndarray] = {}
        self._verified: dict[tuple[bytes, Any, int], PlaneVerification] = {}
        self._uniqueness = Uniqueness(self._coarse, self._per_pair, self._maps,
                                      self.swap_seen)
        # The pair's photometric planes (coarse candidates, refinements, siblings, polish),
        # on this gate's aligner, memo and verification.
        self.planes = CoarsePlanes(settings, self._coarse, self._per_pair, self._maps,
                                   self._verify, self.config)

    def begin_pair(self, left: np.ndarray, right: np.ndarray,
                   levels: tuple[np.ndarray, np.ndarray, int] | None = None) -> None:
        """Shrink this pair once for every plane judged on it until :meth:`end_pair`.

        Only for these very arrays, which must not change until then; planes judged on other
        images are verified as without it. The results are the same either way. ``levels``
        (the pair ``cv2.pyrDown`` L times, and L: the pipeline's working level) spares the
        shrink those halvings (:func:`~domplane_ros.core.verification.working_pair`).
        """
        self._pair, self._working, self._levels = (left, right), None, levels
        self._memo = {}
        self._verified = {}

    def end_pair(self) -> None:
        """Forget the pair of :meth:`begin_pair`."""
        self._pair = self._working = self._levels = None
        self._memo = {}
        self._verified = {}

    def _per_pair(self, left: np.ndarray, right: np.ndarray, key: Hashable,
                  compute: Callable[[], np.ndarray]) -> np.ndarray:
        """Return ``compute()``, once per key for the pair of :meth:`begin_pair`."""
        if self._pair is None or self._pair[0] is not left or self._pair[1] is not right:
            return compute()
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    def _working_for(self, left: np.ndarray, right: np.ndarray,
                     config: VerificationConfig) -> WorkingPair | None:
        """Return the pair of :meth:`begin_pair` shrunk once for ``config``; None for others."""
        if self._pair is None or self._pair[0] is not left or self._pair[1] is not right:
            return None
        if self._working is None or self._working.width != config.working_width_px:
            self._working = working_pair(left, right, config, self._levels)
        return self._working

    def _maps(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
              roi: Sequence[float] | None) -> AgreementMaps:
        """Return a plane's agreement maps without the peak probes (for the pick's rules)."""
        config = self.config(left.shape[1])
        return agreement_maps(left, right, homography, config, roi,
                              self._working_for(left, right, config), peak=False)

    def _verify(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                roi: Sequence[float] | None) -> PlaneVerification:
        config = self.config(left.shape[1])
        working = self._working_for(left, right, config)
        if working is None:
            return verify_plane(left, right, homography, config, roi, None,
                                **self._own_region)
        # The same plane judged twice on one pair (a search picked again with its rivals
        # refined further, a finished plane that did not move) is verified once.
        key = (np.asarray(homography, np.float64).tobytes(),
               None if roi is None else tuple(roi), config.working_width_px)
        if key not in self._verified:
            self._verified[key] = verify_plane(left, right, homography, config, roi, working,
                                               **self._own_region)
        return self._verified[key]

    @property
    def _own_region(self) -> dict[str, bool]:
        """Return verify_plane's own-region argument: planes ``any`` are judged there too."""
        return {'own_region': True} if self.settings.plane == 'any' else {}

    def config(self, width: int) -> VerificationConfig:
        """Return the verification settings for images ``width`` pixels wide."""
        if width not in self._configs:
            working = int(min(MAX_WORKING_WIDTH, max(MIN_WORKING_WIDTH,
                                                     round(self.settings.scale * width))))
            # Ground planes' scores weight each textured pixel by its contrast (core/
            # verification.py, step 5) and, with verification.covisible (default on since
            # session 20), divide by the textured pixels the plane maps inside the right image
            # (step 7, its floor 0.5): with a vertical offset, a roll or a focal mismatch the
            # near ground leaves the right image and counted against the true plane
            # (docs/BENCHMARKS.md rounds 20 and 21: real texture, KITTI 000046 perturbed,
            # tuning seeds 0-23, default prior, 55 published / 49 correct / 0 wrong -> 100 /
            # 91 / 0). Planes ``any`` (boards) keep the count their own-region rule was
            # measured with.
            self._configs[width] = VerificationConfig(
                working_width_px=min(working, width),
                reject_score=self.settings.min_score - 0.1,
                accept_score=self.settings.min_score + 0.1,
                weight_by_contrast=self.settings.plane != 'any',
                covisible=self.settings.covisible and self.settings.plane != 'any')
        return self._configs[width]

    def reset(self) -> None:
        """Forget the lock's history (a new search)."""
        self._scores.clear()
        self._locked_frames = 0
        self._reference = None

    @property
    def lock_score(self) -> float | None:
        """Return the median score of the current lock, or None without a lock."""
        return statistics.median(self._scores) if self._scores else None

    def judge(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
              roi: Sequence[float] | None = None, locked: bool = False) -> Verdict:
        """Return the verdict on a plane; a locked plane is also held against its history.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image.
            homography: (3, 3) float64 left-to-right plane homography.
            roi: Region of the left image (fractions), as ``features.roi``.
            locked: The plane continues the current lock (warm start), so its score is
                compared with the lock's median too, and it is published if accepted: its
                roll is checked too (:meth:`rolled_refusal`).

        Returns:
            The :class:`Verdict`.

        """
        check = self._verify(left, right, homography, roi)
        if self.settings.plane == 'any':
            return self._judge_any(check, locked)
        height, width = left.shape
        swap = swap_evidence(homography, width, height)
        slope = swap.disparity_slope
        least = max(MIN_BOTTOM_SCORE, MIN_BOTTOM_SHARE * check.score)
        bottom = ('not the ground: the plane explains '
                  f'{100 * check.bottom_score:.0f} % of the bottom of the image '
                  f'(< {100 * least:.0f} %); a wall or a plane through obstacles?')
        if slope < -MIN_GROUND_SLOPE and check.accepted and check.bottom_score < least:
            # Verified over the image but not over its bottom: a wall or the faces of
            # boxes whose slope tips below zero (measured: a far wall on a faint tiled floor,
            # -0.03 px per row, 2 % of the bottom), not the floor of swapped cameras, which
            # fills the bottom like any floor. Neither a swap report nor a rival of the floor.
            return Verdict(False, check, bottom, ground=False)
        if slope < -MIN_GROUND_SLOPE:
            return Verdict(False, check, "left and right cameras appear swapped: the plane's "
                           f'disparity shrinks toward the image bottom ({slope:+.3f} px per '
                           'row); swap the image topics', swapped=True)
        if slope < MIN_GROUND_SLOPE:
            return Verdict(False, check, 'not a ground plane: its disparity does not grow '
                           f'toward the image bottom ({slope:+.3f} px per row < '
                           f'{MIN_GROUND_SLOPE}); a wall or the far field?', ground=False)
        if not check.accepted:
            return Verdict(False, check, f'plane not verified: {check.reason} (score '
                           f'{check.score:.2f} < verification.min_score '
                           f'{self.settings.min_score:g})')
        if check.bottom_score < least:
            return Verdict(False, check, bottom, ground=False)
        verdict = ground_rules.one_surface(check) or self._held(check, locked)
        if verdict.accepted and locked:
            # Last: a warm pair's plane is published if accepted (a search's is checked
            # once finished, PlaneSearch; its unfinished candidates never).
            rolled = self.ground_refusal(homography, width, height, check)
            if rolled:
                return Verdict(False, check, rolled, ground=False)
        return verdict

    def ground_refusal(self, homography: np.ndarray, width: int, height: int,
                       check: PlaneVerification | None = None) -> str:
        """Return why a plane about to be published is not the prior's ground ('' if it is).

        Its roll (:meth:`rolled_refusal`), its disparity slope (:meth:`slope_refusal`) and,
        given its verification ``check``, the bands it explains (:meth:`bands_refusal`).
        """
        return (self.rolled_refusal(homography, width, height)
                or self.slope_refusal(homography, width, height)
                or (self.bands_refusal(check) if check is not None else ''))

    def bands_refusal(self, check: PlaneVerification) -> str:
        """Return :func:`~domplane_ros.stream.ground_rules.bands_refusal` ('' if none)."""
        return ground_rules.bands_refusal(check, self.settings)

    def slope_refusal(self, homography: np.ndarray, width: int, height: int) -> str:
        """Return :func:`~domplane_ros.stream.ground_rules.slope_refusal` ('' if none)."""
        return ground_rules.slope_refusal(homography, width, height, self.settings, self.prior)

    def rolled_refusal(self, homography: np.ndarray, width: int, height: int) -> str:
        """Return :func:`~domplane_ros.stream.ground_rules.rolled_refusal` ('' if none)."""
        return ground_rules.rolled_refusal(homography, width, height, self.settings,
                                           self.prior)

    def near_field_refusal(self, homography: np.ndarray,
                           roi: Sequence[float] | None = None) -> str:
        """Return why a new ground plane's own mask refutes it ('' if it does not).

        :func:`~domplane_ros.stream.near_field.near_field_refusal` on the pair of
        :meth:`begin_pair` (at its working level): the bottom third of the view (of ``roi``)
        must not be mostly obstacle. For new planes only (a search's winner, a challenger),
        never a held lock's; never with ``verification.plane: any`` or without a pair.
        """
        if self.settings.plane == 'any' or self._pair is None:
            return ''
        left, right, level = self._working_level()
        return near_field_refusal(left, right, float(1 << level), homography, self.mask,
                                  self.prior, roi, self.settings.max_near_obstacle)

    def _working_level(self) -> tuple[np.ndarray, np.ndarray, int]:
        """Return the pair of :meth:`begin_pair` at the pipeline's working level, and L."""
        if self._levels is not None:
            return self._levels
        assert self._pair is not None
        return self._pair[0], self._pair[1], 0

    def swap_seen(self, homography: np.ndarray, roi: Sequence[float] | None = None,
                  pair: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
        """Return whether a plane that looks swapped is the floor of swapped cameras.

        Its swapped reading's own mask must mark at least :data:`MIN_SWAPPED_GROUND` of the
        bottom third (of ``roi``) plane
        (:func:`~domplane_ros.stream.near_field.swapped_ground_share`, on the pair of
        :meth:`begin_pair` at its working level, once per plane and pair). A surface facing
        the head fills the view with the same disparity slope but is no ground read either
        way: it is not reported as a swap (it still counts as a rival in a pick, only named
        otherwise). True without a pair, or when ``pair`` (the images judged) is not the pair
        of :meth:`begin_pair` (no evidence against it).
        """
        if self._pair is None or (pair is not None and (pair[0] is not self._pair[0]
                                                        or pair[1] is not self._pair[1])):
            return True
        left, right, level = self._working_level()
        key = ('swapped ground', np.asarray(homography, np.float64).tobytes(),
               None if roi is None else tuple(roi))
        share = float(self._per_pair(*self._pair, key, lambda: np.array(swapped_ground_share(
            left, right, float(1 << level), homography, self.mask, self.prior, roi))))
        return share >= MIN_SWAPPED_GROUND

    def _judge_any(self, check: PlaneVerification, locked: bool) -> Verdict:
        """Return the verdict of ``verification.plane: any``: no ground or swap checks.

        The plane need not be the ground, so neither the sign of its disparity slope nor
        what it explains at the image bottom nor what lies beyond it says anything; the
        verification and the lock's history still do.
        """
        if not check.accepted and ground_rules.own_region_verified(check):
            # A board covering a fifth of a textured room: little of the image's texture, but
            # nearly all of its own region's.
            check = updated(check, accepted=True, reason='',
                            confidence=ground_rules.own_region_confidence(check))
        if not check.accepted:
            return Verdict(False, check, f'plane not verified: {check.reason} (score '
                           f'{check.score:.2f} < verification.min_score '
                           f'{self.settings.min_score:g}; its own region '
                           f'{100 * check.region_fraction:.0f} % of the image, score '
                           f'{check.region_score:.2f})')
        return self._held(check, locked)

    def _held(self, check: PlaneVerification, locked: bool) -> Verdict:
        """Return the verdict on a verified plane: a locked one must keep its score."""
        lock = self.lock_score
        if locked and lock is not None and check.score < self.settings.drop_ratio * lock:
            return Verdict(False, check, f'plane not verified: score {check.score:.2f} fell '
                           f'below verification.drop_ratio {self.settings.drop_ratio:g} x the '
                           f"lock's {lock:.2f} (the view changed)", lock_refusal=DROP)
        return (self._below_reference(check) if locked else None) or Verdict(True, check, '')

    def record(self, verdict: Verdict) -> None:
        """Add a published plane's score to the lock's history (the first: its reference)."""
        if verdict.accepted:
            self._scores.append(verdict.score)
            self._locked_frames += 1
            if self._reference is None:
                self._reference = verdict.verification

    @property
    def lock_reference(self) -> PlaneVerification | None:
        """Return the verification the current lock started from (:data:`LOCK_REFERENCE`)."""
        return self._reference

    def take_lock(self, other: TrustGate) -> None:
        """Hold the lock of ``other`` (the gate of the settings before a change) from now on.

        Its score history, locked pairs and reference (:data:`LOCK_REFERENCE`) are this
        gate's: only for scores measured alike (the same ``scale`` and ``plane``).
        """
        self._scores = deque(other._scores, maxlen=self._scores.maxlen)
        self._locked_frames = other._locked_frames
        self._reference = other._reference

    def lock_lost(self) -> None:
        """Forget the lock's reference: the next published plane (a search's) starts a lock.

        The score history is kept (:meth:`reset` forgets both).
        """
        self._reference = None

    def _below_reference(self, check: PlaneVerification) -> Verdict | None:
        """Return the refusal of a warm plane that lost its lock's score or bottom, else None.

        See :data:`LOCK_REFERENCE`: a ground plane scoring under :data:`LOCK_REFERENCE_RATIO`
        x the score the lock started from, or explaining under :data:`LOCK_BOTTOM_RATIO` x
        the share of the image bottom it explained, has slid off the plane it locked on (or
        the view changed): refused, the pipeline searches.
        """
        reference = self._reference
        if not LOCK_REFERENCE or reference is None or self.settings.plane == 'any':
            return None
        if check.score < LOCK_REFERENCE_RATIO * reference.score:
            return Verdict(False, check, f'plane not verified: score {check.score:.2f} fell '
                           f'below {LOCK_REFERENCE_RATIO:g} x the {reference.score:.2f} the '
                           'lock started from (a drifting lock?)', lock_refusal=REFERENCE)
        if check.bottom_score < LOCK_BOTTOM_RATIO * reference.bottom_score:
            return Verdict(False, check, 'not the ground: the plane explains '
                           f'{100 * check.bottom_score:.0f} % of the bottom of the image, under '
                           f'{LOCK_BOTTOM_RATIO:g} x the {100 * reference.bottom_score:.0f} % '
                           'the lock started from (a drifting lock?)', lock_refusal=BOTTOM)
        return None

    def challenge_due(self) -> bool:
        """Return whether the lock is challenged in this frame."""
        period = self.settings.challenge_period
        return period > 0 and self._locked_frames > 0 and self._locked_frames % period == 0

    def pick(self, left: np.ndarray, right: np.ndarray, estimates: Sequence[PlaneEstimate],
             roi: Sequence[float] | None = None,
             rivals: Sequence[np.ndarray] | Callable[[], Sequence[np.ndarray]] | None = None
             ) -> Pick:
        """Verify every estimate and return the best verified one, if it is unique.

        Candidates are ranked by the verification (its peak score), not by the point energy:
        a plane one tile or plank off can have the lower energy, never the higher score
        (measured on the same pair). Planes within 0.5 px of one already judged are not
        verified again. The best is published only if its score is at least
        :data:`CHALLENGE_MARGIN` times that of every distinct plane judged (verified or not;
        walls and planes through obstacles do not compete), of every plane of swapped cameras
        judged (distinct or not) and of every plane of ``rivals``: (3, 3) homographies judged
        only as rivals, never published (the swapped cameras' planes,
        :mod:`domplane_ros.stream.swap`), or a callable giving them, called only once a plane
        is verified. The rules of uniqueness:
        :meth:`~domplane_ros.stream.uniqueness.Uniqueness.ground_winner` and, with
        ``verification.plane: any``,
        :meth:`~domplane_ros.stream.uniqueness.Uniqueness.any_winner`.

        Returns:
            The best verified estimate and its verdict (None, None if none verified or it is
            not unique) and, if none, why (the swap reason if one of the best planes that
            looked swapped is the floor of swapped cameras read so, :meth:`swap_seen`; a
            surface facing the head if none is).

        """
        judged: list[Judged] = []
        height, width = left.shape
        corners = np.array([[0, 0, 1], [width - 1, 0, 1], [width - 1, height - 1, 1],
                            [0, height - 1, 1]], np.float64).T
        mapped_all: list[np.ndarray] = []
        for estimate in estimates:
            mapped = estimate.homography @ corners
            mapped = mapped[:2] / mapped[2]
            if any(np.max(np.abs(mapped - other)) < 0.5 for other in mapped_all):
                continue
            mapped_all.append(mapped)
            judged.append((estimate, estimate.homography,
                           self.judge(left, right, estimate.homography, roi)))
        verified = [item for item in judged if item[2].accepted]
        reasons = [verdict for _, _, verdict in judged if not verdict.accepted]
        swapped = [(h, v) for _, h, v in judged
                   if not v.accepted and v.swapped and v.verification.accepted]
        if verified:
            rival_planes = rivals() if callable(rivals) else rivals
            judged += [(None, rival, self.judge(left, right, rival, roi))
                       for rival in rival_planes or []]
            pick = (self._uniqueness.any_winner if self.settings.plane == 'any'
                    else self._uniqueness.ground_winner)
            return pick(left, right, judged, verified, roi)
        if swapped:
            # The image is explained better by a plane of swapped cameras: what passes the
            # ground check is a look-alike (measured: a checker floor one period off). Unless
            # no such plane is the floor of swapped cameras read so (swap_seen): a surface
            # facing the head, a wall or an obstacle's face close ahead, fills the view.
            # The best-scoring few only (SWAP_SEEN_TRIED): a mask each.
            swapped.sort(key=lambda item: -item[1].score)
            seen = next((v for h, v in swapped[:SWAP_SEEN_TRIED]
                         if self.swap_seen(h, roi, (left, right))), None)
            if seen is not None:
                return None, None, seen.reason
            return None, None, (
                'not the ground: a surface facing the head fills the view (its disparity '
                'shrinks toward the image bottom, score '
                f'{swapped[0][1].score:.2f}, but with left and right exchanged its own mask '
                'sees no ground either); a wall or an obstacle close ahead?')
        if not reasons:
            return None, None, ''
        closest = max(reasons, key=lambda v: v.score)
        return None, None, closest.reason

    def beats(self, challenger: Verdict, lock: Verdict) -> bool:
        """Return whether a challenger explains clearly more of the image than the lock.

        Compared by the peak score: the challenger is often a plane a few pixels from the
        lock, which the score's wider sideways probes tell apart less well.
        """
        return (challenger.accepted
                and challenger.peak_score > CHALLENGE_MARGIN * lock.peak_score)
