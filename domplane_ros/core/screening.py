"""Screening: a cheap truncated closest-point energy of many candidate homographies.

A search has hundreds of candidates (the prior's grid, a challenge's prior starts) and can
afford the two-step iteration from a few: each candidate is screened by ``sum_i min(d_i, t)^2``
over the left points, ``d_i`` the distance of a point's prediction to its closest right point
(Fornland & Schnörr's energy at a fixed, wide truncation), the best are refined
(:class:`~domplane_ros.core.prior.PriorSearch`,
:meth:`~domplane_ros.core.estimator.TwoStep.best_screened`). :func:`screen_candidates` ranks
them all (a coarse pass over a distance transform, then the exact energy of the best
:data:`SCREEN_EXACT`), :func:`best_screened` only the best few, cheaper.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
from domplane_ros.core.homography import FAR_PX, MIN_W
import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

__all__ = ['SCREEN_EXACT', 'SHORT_EXACT', 'SHORT_STRIDE', 'best_screened', 'coarse_screening',
           'screen_candidates']


def screen_candidates(candidates: np.ndarray, left_points: np.ndarray, right_tree: cKDTree,
                      threshold_px: float) -> np.ndarray:
    """Score candidates by a cheap truncated closest-point energy (lower is better).

    The energy of a candidate is ``sum_i min(d_i, t)^2`` with ``d_i`` the distance from the
    predicted left point to its closest right point. It is computed in two passes: a coarse
    one for every candidate, reading ``d_i`` from a distance transform of the right points
    rasterised on a grid (:func:`coarse_screening`, off by about a cell), then the exact one
    (one tree query) for the :data:`SCREEN_EXACT` best of the coarse pass. Those get their
    exact energies; the others rank after all of them, in their coarse order.

    Args:
        candidates: (M, 3, 3) float64 homographies.
        left_points: (N, 2) float64 left points.
        right_tree: cKDTree over the right points.
        threshold_px: Truncation ``t`` in pixels.

    Returns:
        (M,) float64 screening energies.

    """
    x, y = _predict_all(candidates, left_points)
    m = candidates.shape[0]
    if m <= SCREEN_EXACT:
        return _exact_energy(x, y, right_tree, threshold_px)
    coarse = _coarse_energy(x, y, right_tree.data, threshold_px)
    best = np.argsort(coarse, kind='stable')[:SCREEN_EXACT]
    costs = coarse + (1.0 + left_points.shape[0] * threshold_px ** 2)
    costs[best] = _exact_energy(x[best], y[best], right_tree, threshold_px)
    return costs


# Candidates screened exactly after the coarse pass (the pipeline refines at most
# prior.refine_best of them, 6 by default).
SCREEN_EXACT = 64
# The lock's challenge needs only its best few (stream/challenge.py PRIOR_STARTS, 2): its
# coarse pass reads every SHORT_STRIDE-th point and its exact pass takes the best
# SHORT_EXACT of that. Measured on 168 warm and cold problems of rendered sequences (random
# and tiled floors, cuts): the best two identical, in order, to :func:`screen_candidates`'s
# on all 168 at 0.39x its CPU time (stride 3 with 16 exact: one of 168 differs).
SHORT_STRIDE = 2
SHORT_EXACT = 16
# Cells of the coarse pass's grid: at most this many along the right points' wider side.
_SCREEN_GRID = 320


def best_screened(candidates: np.ndarray, left_points: np.ndarray, right_tree: cKDTree,
                  threshold_px: float, count: int) -> np.ndarray:
    """Return the indices of the ``count`` candidates of lowest screening energy, a short way.

    The coarse pass of :func:`screen_candidates` over every :data:`SHORT_STRIDE`-th left
    point, then the exact energy over all points for its best :data:`SHORT_EXACT`; the best
    ``count`` of those, lowest exact energy first (ties in the coarse order). For a caller
    that refines only the best few (the lock's challenge), not for the search's ranking.

    Args:
        candidates: (M, 3, 3) float64 homographies.
        left_points: (N, 2) float64 left points.
        right_tree: cKDTree over the right points.
        threshold_px: Truncation ``t`` in pixels.
        count: How many indices to return (at most M).

    Returns:
        (min(count, M),) intp candidate indices.

    """
    if candidates.shape[0] <= SHORT_EXACT:
        shortlist = np.arange(candidates.shape[0])
    else:
        x, y = _predict_all(candidates, left_points[::SHORT_STRIDE])
        coarse = _coarse_energy(x, y, right_tree.data, threshold_px)
        shortlist = np.argsort(coarse, kind='stable')[:SHORT_EXACT]
    x, y = _predict_all(candidates[shortlist], left_points)
    exact = _exact_energy(x, y, right_tree, threshold_px)
    return shortlist[np.argsort(exact, kind='stable')[:count]]


def _predict_all(candidates: np.ndarray, left_points: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Return the (M, N) x and y predictions of every left point under every candidate.

    Two contiguous arrays rather than one (M, N, 2): the passes below read each coordinate
    on its own (the same values as before, about a fifth less screening time).
    """
    n = left_points.shape[0]
    homogeneous = candidates @ np.column_stack([left_points, np.ones(n)]).T  # (M, 3, N)
    w = homogeneous[:, 2]
    w = np.where(np.abs(w) < MIN_W, MIN_W, w)  # as apply_homography: far, finite
    x = np.divide(homogeneous[:, 0], w)
    y = np.divide(homogeneous[:, 1], w)
    np.clip(x, -FAR_PX, FAR_PX, out=x)
    np.clip(y, -FAR_PX, FAR_PX, out=y)
    return x, y


def _exact_energy(x: np.ndarray, y: np.ndarray, right_tree: cKDTree, threshold_px: float
                  ) -> np.ndarray:
    """Return (M,) ``sum min(d, t)^2`` of the (M, N) predictions by one tree query."""
    m, n = x.shape
    d, _ = right_tree.query(np.stack([x.ravel(), y.ravel()], axis=1),
                            distance_upper_bound=threshold_px)
    d = np.minimum(d, threshold_px).reshape(m, n)
    return np.sum(d * d, axis=1)


def coarse_screening(pred: np.ndarray, right_points: np.ndarray, threshold_px: float
                     ) -> np.ndarray:
    """Return (M,) ``sum min(d, t)^2`` with ``d`` read from a distance transform.

    The right points are rasterised on a grid of cells (at most ``_SCREEN_GRID`` along the
    wider side of their bounding box grown by ``t``); ``cv2.distanceTransform`` gives each
    cell's distance to the nearest occupied cell. A prediction outside the grid is at least
    ``t`` from every right point. The distances are off by at most about one cell diagonal.

    Args:
        pred: (M, N, 2) float64 predictions.
        right_points: (K, 2) float64 right points.
        threshold_px: Truncation ``t``, pixels.

    """
    return _coarse_energy(np.ascontiguousarray(pred[..., 0]),
                          np.ascontiguousarray(pred[..., 1]), right_points, threshold_px)


def _coarse_energy(x: np.ndarray, y: np.ndarray, right_points: np.ndarray,
                   threshold_px: float) -> np.ndarray:
    """Return :func:`coarse_screening` of the (M, N) predictions ``x`` and ``y``."""
    low = right_points.min(axis=0) - threshold_px
    high = right_points.max(axis=0) + threshold_px
    cell = max(1.0, float(np.max(high - low)) / _SCREEN_GRID)
    cols, rows = (np.ceil((high - low) / cell).astype(int) + 1)
    occupied = np.full((rows, cols), 255, np.uint8)
    idx = np.rint((right_points - low) / cell).astype(int)
    occupied[idx[:, 1], idx[:, 0]] = 0
    dist = cell * cv2.distanceTransform(occupied, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    # Squared truncated distances, with a border of t all round: a prediction outside the
    # grid is at least t from every right point, so its index is clipped onto the border.
    table = np.full((rows + 2, cols + 2), threshold_px ** 2)
    table[1:-1, 1:-1] = np.minimum(dist, threshold_px) ** 2
    origin = low - cell
    flat = _cell_index(y, origin[1], cell, rows + 1)
    flat *= cols + 2
    flat += _cell_index(x, origin[0], cell, cols + 1)
    return np.sum(table.ravel()[flat], axis=1)


def _cell_index(coordinate: np.ndarray, origin: float, cell: float, last: int) -> np.ndarray:
    """Return the (M, N) intp cells of one coordinate, clipped onto the border [0, last]."""
    grid = np.subtract(coordinate, origin)
    grid /= cell
    np.rint(grid, out=grid)
    np.clip(grid, 0, last, out=grid)
    return grid.astype(np.intp)
