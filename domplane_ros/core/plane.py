"""The one-call API: the dominant plane's homography from two feature sets.

:func:`estimate_plane` builds the two-step problem
(:class:`~domplane_ros.core.estimator.TwoStep`) from the features and runs it from a warm
start, or, without one, from the best candidates of the prior's search
(:class:`~domplane_ros.core.prior.PriorSearch`). The stream (:mod:`domplane_ros.stream`)
uses the same two parts with its own search and verification.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from domplane_ros.config import EstimatorConfig, PriorConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.homography import as_homography
from domplane_ros.core.prior import prior_candidates, PriorSearch
from domplane_ros.core.result import FailedEstimate, PlaneEstimate

__all__ = ['estimate_plane']


def _options(options: EstimatorConfig | None, overrides: dict[str, Any]) -> EstimatorConfig:
    base = options if options is not None else EstimatorConfig()
    return replace(base, **overrides) if overrides else base


def estimate_plane(left_points: Any, right_points: Any, init: Any = None,
                   options: EstimatorConfig | None = None, *,
                   prior: PriorConfig | None = None,
                   image_size: tuple[int, int] | None = None,
                   left_lines: Any = None, right_lines: Any = None,
                   **overrides: Any) -> PlaneEstimate | FailedEstimate:
    """Estimate the dominant plane's homography from two feature sets without correspondences.

    The features are points, line segments, or both (a joint energy in which a segment
    weighs ``options.line_weight`` times a point).

    Args:
        left_points: (N, 2) float64 left image points (x, y); None or (0, 2) with lines only.
        right_points: (M, 2) float64 right image points.
        init: Optional (3, 3) (or 9 values, row-major) initial homography: the warm start.
            Without it, candidates from ``prior`` are screened and the best few iterated.
        options: Estimator settings; keyword ``overrides`` (e.g. ``potential='huber'``,
            ``lambda_weight=0.3``, ``threshold_px=2.0``, ``max_iterations=50``,
            ``line_weight=0.5``) replace fields of it.
        prior: Camera set-up ranges, used when ``init`` is None (defaults to
            ``PriorConfig()``).
        image_size: ``(width, height)`` of the left image, needed with the prior (principal
            point at its centre).
        left_lines: Optional (K, 4) float64 left segments ``(x1, y1, x2, y2)``
            (:func:`domplane_ros.core.lines.detect_lines`).
        right_lines: Optional (L, 4) float64 right segments.
        **overrides: Fields of :class:`~domplane_ros.config.EstimatorConfig`.

    Returns:
        :class:`PlaneEstimate`, or :class:`FailedEstimate` with the reason (too few,
        repeated, collinear or non-finite points; fewer than 4 segments or segments all
        concurrent or parallel; a singular initial homography; too few inliers).

    Raises:
        ValueError: If the arrays do not have shape (N, 2) (points) or (N, 4) (segments),
            ``init`` is not 3x3, an override is invalid, or neither ``init`` nor
            ``image_size`` is given.

    """
    options = _options(options, overrides)
    if init is None and image_size is None:
        raise ValueError('give an initial homography (init) or the image_size for the prior')
    problem = TwoStep.from_features(left_points, right_points, left_lines, right_lines,
                                    options.line_weight)
    if isinstance(problem, FailedEstimate):
        return problem
    if init is not None:
        return problem.estimate(as_homography(init, 'init'), options)
    prior = prior or PriorConfig()
    search = PriorSearch(problem, prior_candidates(prior, *image_size),
                         prior.screen_threshold_px)
    order = search.ranked()[:prior.refine_best]
    best, _ = search.refine(order, options)
    assert best is not None
    return replace(best, candidates_tried=len(order)) if best.ok else best
