"""The swap tested, not assumed absent: planes of swapped cameras as rivals of a search.

The prior's camera model (:mod:`domplane_ros.core.prior`) describes a correctly ordered head.
On a periodic floor seen by swapped cameras that model still has look-alikes, one or more
periods off, that pass the verification (measured on the tuning seeds 30-129: a tiled floor
268 px off and a checker floor 238 px off, scores 0.27), while the plane of the swapped
cameras, which nothing looked for, explains the image as well or better. So a search also
looks for it: the prior's candidates inverted
(:func:`~domplane_ros.core.prior.swapped_candidates`), screened on the same features, the best
refined. The planes found never get published (their disparity shrinks toward the image
bottom); they are *rivals* in :meth:`~domplane_ros.stream.trust.TrustGate.pick`, where a
plane is published only if it explains clearly more of the image than every distinct plane
judged.

Where the swapped floor has too few corners to be refined (a checker of large squares: 11
inliers), its best-screened start is polished photometrically instead
(:meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.polish`).
"""

from __future__ import annotations

from typing import Callable

from domplane_ros.config import EstimatorConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.prior import PriorSearch, swapped_candidates
from domplane_ros.core.result import PlaneEstimate
import numpy as np


def swap_rivals(problem: TwoStep, candidates: np.ndarray, count: int, options: EstimatorConfig,
                threshold_px: float, rejected: Callable[[PlaneEstimate], str],
                polish: Callable[[np.ndarray], np.ndarray]) -> list[np.ndarray]:
    """Return planes of swapped cameras found on this pair's features.

    Args:
        problem: The two-step iteration over this pair's features.
        candidates: (M, 3, 3) float64 prior candidates (correctly ordered head).
        count: Swapped starts refined, best screened first.
        options: Estimator settings.
        threshold_px: Truncation of the screening energy, pixels.
        rejected: Why a refined plane must not be used ('' if it may).
        polish: Photometric polish of a start that could not be refined.

    Returns:
        (3, 3) float64 homographies: the refined planes, or the polished best start when
        none could be refined.

    """
    search = PriorSearch(problem, swapped_candidates(candidates), threshold_px)
    ranked = search.ranked()[:count]
    out = []
    for index in ranked:
        result = problem.estimate(search.candidates[index], options, widen=False)
        if result.ok and not rejected(result):
            out.append(result.homography)
    if not out and ranked:
        out.append(polish(search.candidates[ranked[0]]))
    return out
