"""Verify, then publish: the gate every plane passes before anything downstream sees it.

The point energy cannot tell a look-alike plane from the floor, so every plane the pipeline
would publish is checked here by evidence the corners do not use
(:func:`~domplane_ros.core.verification.verify_plane`: the share of the image's texture that
this plane, and not the same plane moved slightly, explains) and by the geometry of a ground
plane (:func:`~domplane_ros.core.verification.swap_evidence`: its disparity must grow toward
the image bottom, or left and right are swapped).

While locked, a plane must also keep its score: a score that falls below a fraction of the
lock's recent median means the view changed under the warm start (a cut, a saccade, a camera
re-plugged) even if the new score still passes the absolute threshold. Every
``challenge_period`` locked frames a *challenger*, the best plane of the coarse photometric
alignment (:class:`~domplane_ros.core.coarse.CoarseAligner`), is refined and verified; if it
explains clearly more of the image than the lock, the lock is replaced.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
import statistics
from typing import Sequence

from domplane_ros.config import VerificationSettings
from domplane_ros.core.coarse import CoarseAligner, CoarseConfig
from domplane_ros.core.result import PlaneEstimate
from domplane_ros.core.verification import (PlaneVerification, swap_evidence,
                                            VerificationConfig, verify_plane)
import numpy as np

# Least disparity slope (pixels per row, roll-invariant; see swap_evidence) of a ground plane
# seen by a correctly ordered head: true planes measured at least +0.052 on rendered heads,
# rough rigs included; swapped cameras at most -0.052; a wall facing the head has about 0. It
# equals the least baseline over camera height the check admits (the prior's default
# minimum is 0.05).
MIN_GROUND_SLOPE = 0.02
# A published plane must score at least this fraction of every verified plane of swapped
# cameras on the same pair; else the swapped plane explains the image and the others are its
# look-alikes (measured: the true plane outscores its look-alikes on 398 of 400 pairs).
SWAP_DOMINANCE = 1.0
# A challenger replaces the lock only if its score is this many times the lock's: a plane a
# fraction of a pixel away scores about the same and must not churn the lock.
CHALLENGE_MARGIN = 1.2
# Working width limits of the verification, pixels.
MIN_WORKING_WIDTH = 64
MAX_WORKING_WIDTH = 480


@dataclass(frozen=True)
class Verdict:
    """The gate's decision on one plane.

    Attributes:
        accepted: Publish it.
        verification: The photometric verification (score, confidence, fractions).
        reason: Empty when accepted, else one line saying why not.
        swapped: The plane looks like one of swapped left and right cameras.
    """

    accepted: bool
    verification: PlaneVerification
    reason: str
    swapped: bool = False

    @property
    def confidence(self) -> float:
        """Return the verification confidence in [0, 1] (0 for a swapped plane)."""
        return 0.0 if self.swapped else self.verification.confidence

    @property
    def score(self) -> float:
        """Return the verification score in [0, 1]."""
        return self.verification.score


class TrustGate:
    """The verification state of one stream: settings, the lock's score history, the challenger.

    Args:
        settings: The ``verification.*`` parameters.
        history: Frames of score history kept.

    """

    def __init__(self, settings: VerificationSettings, history: int = 10) -> None:
        """Start with no lock history."""
        self.settings = settings
        self._configs: dict[int, VerificationConfig] = {}
        self._coarse = CoarseAligner(CoarseConfig(width_px=settings.coarse_width_px))
        self._scores: deque[float] = deque(maxlen=history)
        self._locked_frames = 0

    def config(self, width: int) -> VerificationConfig:
        """Return the verification settings for images ``width`` pixels wide."""
        if width not in self._configs:
            working = int(min(MAX_WORKING_WIDTH, max(MIN_WORKING_WIDTH,
                                                     round(self.settings.scale * width))))
            self._configs[width] = VerificationConfig(
                working_width_px=min(working, width),
                reject_score=self.settings.min_score - 0.1,
                accept_score=self.settings.min_score + 0.1)
        return self._configs[width]

    def reset(self) -> None:
        """Forget the lock's history (a new search)."""
        self._scores.clear()
        self._locked_frames = 0

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
                compared with the lock's median too.

        Returns:
            The :class:`Verdict`.

        """
        check = verify_plane(left, right, homography, self.config(left.shape[1]), roi)
        height, width = left.shape
        swap = swap_evidence(homography, width, height)
        slope = swap.disparity_slope
        if slope < -MIN_GROUND_SLOPE:
            return Verdict(False, check, "left and right cameras appear swapped: the plane's "
                           f'disparity shrinks toward the image bottom ({slope:+.3f} px per '
                           'row); swap the image topics', swapped=True)
        if slope < MIN_GROUND_SLOPE:
            return Verdict(False, check, 'not a ground plane: its disparity does not grow '
                           f'toward the image bottom ({slope:+.3f} px per row < '
                           f'{MIN_GROUND_SLOPE}); a wall or the far field?')
        if not check.accepted:
            return Verdict(False, check, f'plane not verified: {check.reason} (score '
                           f'{check.score:.2f} < verification.min_score '
                           f'{self.settings.min_score:g})')
        lock = self.lock_score
        if locked and lock is not None and check.score < self.settings.drop_ratio * lock:
            return Verdict(False, check, f'plane not verified: score {check.score:.2f} fell '
                           f'below verification.drop_ratio {self.settings.drop_ratio:g} x the '
                           f"lock's {lock:.2f} (the view changed)")
        return Verdict(True, check, '')

    def record(self, verdict: Verdict) -> None:
        """Add a published plane's score to the lock's history."""
        if verdict.accepted:
            self._scores.append(verdict.score)
            self._locked_frames += 1

    def coarse_candidates(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return (K, 3, 3) planes of the coarse photometric alignment (K = 0 if disabled)."""
        if not self.settings.coarse_candidates or left.shape != right.shape:
            return np.zeros((0, 3, 3))
        return self._coarse.candidates(left, right)

    def challenge_due(self) -> bool:
        """Return whether the lock is challenged in this frame."""
        period = self.settings.challenge_period
        return period > 0 and self._locked_frames > 0 and self._locked_frames % period == 0

    def pick(self, left: np.ndarray, right: np.ndarray, estimates: Sequence[PlaneEstimate],
             roi: Sequence[float] | None = None
             ) -> tuple[PlaneEstimate | None, Verdict | None, str]:
        """Verify every estimate and return the best verified one.

        Candidates are ranked by the verification score, not by the point energy: a plane one
        tile or plank off can have the lower energy, never the higher score (measured on the
        same pair). Planes within 0.5 px of one already judged are not verified again.

        Returns:
            The best verified estimate and its verdict (None, None if none verified) and, if
            none verified, why (the swap reason if any plane looked swapped).

        """
        best: tuple[PlaneEstimate, Verdict] | None = None
        reasons: list[Verdict] = []
        judged: list[np.ndarray] = []
        height, width = left.shape
        corners = np.array([[0, 0, 1], [width - 1, 0, 1], [width - 1, height - 1, 1],
                            [0, height - 1, 1]], np.float64).T
        for estimate in estimates:
            mapped = estimate.homography @ corners
            mapped = mapped[:2] / mapped[2]
            if any(np.max(np.abs(mapped - other)) < 0.5 for other in judged):
                continue
            judged.append(mapped)
            verdict = self.judge(left, right, estimate.homography, roi)
            if not verdict.accepted:
                reasons.append(verdict)
            elif best is None or verdict.score > best[1].score:
                best = (estimate, verdict)
        swapped = [v for v in reasons if v.swapped and v.verification.accepted]
        top_swap = max((v.score for v in swapped), default=0.0)
        if best is not None and best[1].score >= SWAP_DOMINANCE * top_swap:
            return best[0], best[1], ''
        if swapped:
            # The image is explained better by a plane of swapped cameras: what passes the
            # ground check is a look-alike (measured: a checker floor one period off).
            return None, None, max(swapped, key=lambda v: v.score).reason
        if not reasons:
            return None, None, ''
        closest = max(reasons, key=lambda v: v.score)
        return None, None, closest.reason

    def beats(self, challenger: Verdict, lock: Verdict) -> bool:
        """Return whether a challenger explains clearly more of the image than the lock."""
        return challenger.accepted and challenger.score > CHALLENGE_MARGIN * lock.score
