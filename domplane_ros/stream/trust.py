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

from domplane_ros.core.verification import (PlaneVerification, swap_evidence,
                                            VerificationConfig, verify_plane)
import numpy as np

# Disparity slope (pixels per row) below which a plane is taken for swapped cameras. True
# ground planes measured at least +0.035 px/row on rendered heads, rough rigs (4 deg roll,
# 2 deg pitch) at least -0.007; a swapped pair at most -0.035.
SWAP_SLOPE = -0.02


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
    """The verification state of one stream: the lock's score history.

    Args:
        config: The verification settings.
        drop_ratio: A locked plane whose score falls below this fraction of the lock's median
            score is refused (the view changed).
        history: Frames of score history kept.

    """

    def __init__(self, config: VerificationConfig, drop_ratio: float = 0.5,
                 history: int = 10) -> None:
        """Start with no lock history."""
        self.config = config
        self.drop_ratio = drop_ratio
        self._scores: deque[float] = deque(maxlen=history)

    def reset(self) -> None:
        """Forget the lock's history (a new search)."""
        self._scores.clear()

    @property
    def lock_score(self) -> float | None:
        """Return the median score of the current lock, or None without a lock."""
        return statistics.median(self._scores) if self._scores else None

    def judge(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
              roi: tuple[float, float, float, float] | None = None,
              locked: bool = False) -> Verdict:
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
        check = verify_plane(left, right, homography, self.config, roi)
        height, width = left.shape
        swap = swap_evidence(homography, width, height)
        if swap.disparity_slope < SWAP_SLOPE:
            return Verdict(False, check, 'left and right cameras appear swapped: the plane\'s '
                           f'disparity shrinks toward the image bottom '
                           f'({swap.disparity_slope:+.3f} px per row); swap the image topics',
                           swapped=True)
        if not check.accepted:
            return Verdict(False, check, f'plane not verified: {check.reason} (score '
                           f'{check.score:.2f}, confidence {check.confidence:.2f})')
        lock = self.lock_score
        if locked and lock is not None and check.score < self.drop_ratio * lock:
            return Verdict(False, check, f'plane not verified: score {check.score:.2f} fell '
                           f'below {self.drop_ratio:g} x the lock\'s {lock:.2f} (view changed)')
        return Verdict(True, check, '')

    def record(self, verdict: Verdict) -> None:
        """Add an accepted plane's score to the lock's history."""
        if verdict.accepted:
            self._scores.append(verdict.score)
