"""The estimators' result values: a success, or a failure that carries its reason.

Failure is a value, not an exception (scikit-image's ``FailedEstimation``): degenerate data
gives a :class:`FailedEstimate` that is false in a boolean context and says why, so no caller
ever sees a non-finite matrix. Programming errors (wrong shapes or types) raise ``ValueError``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PlaneEstimate:
    """A successful dominant-plane estimate.

    Attributes:
        homography: (3, 3) float64, left pixel to right pixel, ``H[2, 2] == 1``.
        inliers: (N,) bool, left points on the plane (a right point within the threshold).
        matches: (N,) int64, index of each left point's closest right point.
        residuals_px: (N,) float64 final distance from each prediction to its closest point.
        iterations: Two-step iterations used, over all stages.
        energy_trace: (K,) float64 joint energy after every local step.
        stage_trace: (K,) int64 graduated non-convexity stage of each energy value.
        converged: Whether the last stage met a tolerance before the iteration cap.
        final_energy: Last value of the energy trace.
        potential: Name of the potential used.
        candidates_tried: Prior candidates that got the full iteration (0 for a warm start).
        line_inliers: (K,) bool, left segments on the plane (a right line within the
            threshold); empty without lines.
        line_matches: (K,) int64, index of each left segment's closest right segment.
        line_residuals_px: (K,) float64 final distance of each predicted segment to its
            closest right line (:mod:`domplane_ros.core.lines`).
        left_lines: (K, 4) float64 the left segments used (zero-length ones dropped).

    """

    homography: np.ndarray
    inliers: np.ndarray
    matches: np.ndarray
    residuals_px: np.ndarray
    iterations: int
    energy_trace: np.ndarray
    stage_trace: np.ndarray
    converged: bool
    final_energy: float
    potential: str
    candidates_tried: int = 0
    line_inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    line_matches: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    line_residuals_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    left_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    ok: bool = field(default=True, init=False)
    reason: str = field(default='', init=False)

    @property
    def n_inliers(self) -> int:
        """Return the number of inlier left features (points plus segments)."""
        return int(np.count_nonzero(self.inliers)) + int(np.count_nonzero(self.line_inliers))

    def __bool__(self) -> bool:
        """Return True: this is a success."""
        return True


@dataclass(frozen=True)
class FailedEstimate:
    """A failed estimate: false in a boolean context, with the reason in words.

    The one failure type of the package: the homography fits of
    :mod:`domplane_ros.core.homography` return it with only a reason, the two-step iteration
    also with what it got to.

    Attributes:
        reason: Why there is no estimate, one line.
        iterations: Two-step iterations run before failing (0 if it did not run).
        energy_trace: (K,) float64 joint energy after every local step (empty if none).
        n_inliers: Inlier features of the last iterate.
        stage_trace: (K,) int64 graduated non-convexity stage of each energy value.

    """

    reason: str
    iterations: int = 0
    energy_trace: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_inliers: int = 0
    stage_trace: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    ok: bool = field(default=False, init=False)
    converged: bool = field(default=False, init=False)

    def __bool__(self) -> bool:
        """Return False: a failure never passes for a result."""
        return False

    def __str__(self) -> str:
        """Return the reason."""
        return self.reason


def better_estimate(a: PlaneEstimate | FailedEstimate,
                    b: PlaneEstimate | FailedEstimate) -> bool:
    """Return True if ``a`` is a better search result than ``b`` (same features).

    A success beats a failure; of two failures, more inliers; of two successes, the lower
    final energy.
    """
    if a.ok != b.ok:
        return bool(a.ok)
    if not a.ok:
        return a.n_inliers > b.n_inliers
    return a.final_energy < b.final_energy
