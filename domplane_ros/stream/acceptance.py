"""The acceptance checks a plane passes before the pipeline may keep it.

Enough features to try; a finite, invertible homography; inliers spread over the region of
interest (``pipeline.min_inlier_spread``); no energy jump against the last good plane
(``pipeline.max_energy_ratio``); image corners mapped within the prior's reach
(``pipeline.check_prior_bounds``). Each check returns its reason ('' when it passes) and, where
asked, counts the failure in the stream's :class:`~domplane_ros.stream.health.InputCounts`. The
photometric verification comes after these (:mod:`domplane_ros.stream.trust`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

from domplane_ros.config import PlaneNodeConfig, PriorConfig
from domplane_ros.core.features import Features, roi_to_pixels
from domplane_ros.core.homography import apply_homography
from domplane_ros.core.lines import endpoints
from domplane_ros.core.prior import search_candidates
from domplane_ros.core.result import PlaneEstimate
from domplane_ros.stream.health import homography_problem, inlier_spread, InputCounts
import numpy as np

# Margin (fraction of the image diagonal) around the image-corner positions that the prior's
# candidates reach; a homography moving a corner beyond it violates the prior.
_PRIOR_BOUNDS_MARGIN = 0.15


class AcceptanceChecks:
    """The pipeline's acceptance checks, with the prior-bounds cache per image size.

    Args:
        counts: Where failures are counted.
        config: Returns the pipeline's current configuration.

    """

    def __init__(self, counts: InputCounts, config: Callable[[], PlaneNodeConfig]) -> None:
        """Start with an empty bounds cache."""
        self.counts = counts
        self._config = config
        self._bounds_cache: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def clear(self) -> None:
        """Forget the cached prior bounds (the prior changed)."""
        self._bounds_cache.clear()

    def too_few_reason(self, feats: Features) -> str:
        """Return why the features are too few to try an estimate ('' if they are enough)."""
        min_inliers = self._config().estimator.min_inliers
        if feats.n_left < min_inliers:
            return f'too few left features: {feats.n_left} < min_inliers {min_inliers}'
        if feats.n_right < 4:
            return f'too few right features: {feats.n_right}'
        return ''

    def rejection_reason(self, estimate: PlaneEstimate, feats: Features,
                         size: tuple[int, int], bounds: bool = True) -> str:
        """Return why a search result must not be accepted ('' if it may be; not counted).

        ``bounds=False`` skips the prior-bounds check (the coarse alignment's planes need no
        camera model; the verification and the swap check judge them).
        """
        return ((self.bounds_reason(estimate.homography, size, count=False) if bounds else '')
                or self.input_problem(estimate, feats.left_points, size, count=False))

    def count_rejection(self, reason: str) -> None:
        """Count a search's final rejection reason once, under its kind."""
        for needle, key in (('outside the prior', 'outside_prior'),
                            ('degenerate geometry', 'degenerate_geometry')):
            if needle in reason:
                self.counts.add(key)
                return
        self.counts.add('invalid_homography')

    def input_problem(self, estimate: PlaneEstimate, left_pts: np.ndarray,
                      size: tuple[int, int], count: bool = True) -> str:
        """Return why a converged estimate must not be published ('' if it may be)."""
        problem = homography_problem(estimate.homography)
        if problem:
            if count:
                self.counts.add('invalid_homography')
            return problem
        min_spread = self._config().pipeline.min_inlier_spread
        if min_spread > 0:
            x0, y0, x1, y1 = roi_to_pixels(self._config().features.roi, *size)
            # Inlier corners and the endpoints of inlier segments.
            inliers = np.concatenate([
                left_pts[estimate.inliers],
                endpoints(estimate.left_lines[estimate.line_inliers])])
            spread = inlier_spread(inliers, float((x1 - x0) * (y1 - y0)))
            if spread < min_spread:
                if count:
                    self.counts.add('degenerate_geometry')
                return (f'degenerate geometry: the inliers span {100 * spread:.2f} % of the '
                        f'region of interest (< pipeline.min_inlier_spread {min_spread:g}); '
                        'collinear or packed in one patch, they do not constrain the plane')
        return ''

    def suspicion_reason(self, estimate: PlaneEstimate, n_points: int, size: tuple[int, int],
                         last_energy_per_point: float | None, energy: bool = True,
                         count: bool = True) -> str:
        """Return why an estimate should not be trusted ('' if it can be)."""
        cfg = self._config().pipeline
        if energy and last_energy_per_point is not None:
            per_point = estimate.final_energy / max(n_points, 1)
            limit = cfg.max_energy_ratio * max(last_energy_per_point, 1e-3)
            if per_point > limit:
                return (f'energy jump: {per_point:.3g} per point > {cfg.max_energy_ratio} x '
                        f'last {last_energy_per_point:.3g}')
        return self.bounds_reason(estimate.homography, size, count)

    def bounds_reason(self, homography: np.ndarray, size: tuple[int, int],
                      count: bool = True) -> str:
        """Return why a homography is outside the prior ('' if it is inside or unchecked)."""
        if self._config().pipeline.check_prior_bounds:
            low, high = self.prior_bounds(size)
            corners = _image_corners(*size)
            mapped = apply_homography(homography, corners)
            if np.any(mapped < low) or np.any(mapped > high):
                if count:
                    self.counts.add('outside_prior')
                return 'homography outside the prior: an image corner maps beyond its range'
        return ''

    def prior_bounds(self, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Return the low and high image-corner positions the prior's candidates reach."""
        if size not in self._bounds_cache:
            cfg = self._config()
            cands = search_candidates(_bounds_prior(cfg.prior), *size, cfg.verification.plane)
            corners = _image_corners(*size)
            mapped = np.stack([apply_homography(h, corners) for h in cands])
            margin = _PRIOR_BOUNDS_MARGIN * float(np.hypot(*size))
            self._bounds_cache[size] = (mapped.min(axis=0) - margin,
                                        mapped.max(axis=0) + margin)
        return self._bounds_cache[size]


def _bounds_prior(prior: PriorConfig) -> PriorConfig:
    """Return the prior sampled at its range ends and middle, for the bounds check."""
    return replace(prior, samples=3)


def _image_corners(width: int, height: int) -> np.ndarray:
    return np.array([[0.0, 0.0], [width - 1.0, 0.0], [width - 1.0, height - 1.0],
                     [0.0, height - 1.0]])
