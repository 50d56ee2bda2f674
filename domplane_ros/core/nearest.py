"""Exact closest-point queries that re-use an earlier answer where it cannot have changed.

The two-step iteration asks, at every step, for the closest right point of every predicted
left point, and after the first few steps the predictions hardly move. :class:`NearestPoints`
queries a point's two closest right points once and records how far its prediction may move
before another right point could be the closest: half the gap between the two distances
(after a move ``d`` the closest is at most ``r1 + d`` away and every other point at least
``r2 - d``). Later calls query the tree again only for the predictions that moved further than
that since their last query; the others keep their closest point, its distance recomputed
exactly. The answers are those of a fresh ``cKDTree.query`` (up to exact ties).

With a bound (``distance_upper_bound``: points with nothing closer than the bound get distance
inf and index -1), the query looks further than the bound by ``max(bound, REACH_MARGIN_PX)``,
so that a prediction with nothing within that reach keeps "nothing within the bound" while it
moves less than the margin.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ['NearestPoints', 'REACH_MARGIN_PX']

# A bounded query looks this much further than the bound (at least the bound itself), so a
# point with nothing within reach keeps 'nothing within the bound' while it moves less.
REACH_MARGIN_PX = 8.0


class NearestPoints:
    """Closest points of a fixed set, for predictions that move a little between calls.

    Args:
        points: (M, 2) float64 points (the right image's).
        tree: A ``cKDTree`` over ``points`` (built here when not given).

    """

    def __init__(self, points: np.ndarray, tree: cKDTree | None = None) -> None:
        """Keep the points and their tree; nothing is cached yet."""
        self.points = points
        self.tree = tree if tree is not None else cKDTree(points)
        # The points and one spare row, which index -1 (no closest point) reads.
        self._padded = np.vstack([points, np.zeros((1, 2))])
        # Per bound: (reference predictions, closest index or -1, squared radius of validity).
        self._cache: dict[float | None, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.queried = 0

    def query(self, pred: np.ndarray, bound: float | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """Return the closest distances and indices of (N, 2) predictions.

        Args:
            pred: (N, 2) float64 finite predictions.
            bound: Optional distance from which a point counts as having no closest point
                (distance inf, index -1), as ``cKDTree.query``'s ``distance_upper_bound``.

        Returns:
            ``(distances, indices)``, (N,) float64 and (N,) int64.

        """
        r, idx, _ = self.query_closest(pred, bound)
        return r, idx

    def query_closest(self, pred: np.ndarray, bound: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return :meth:`query`'s distances and indices, and the (N, 2) closest points.

        A prediction without a closest point (index -1) gets a meaningless closest point.
        """
        n = pred.shape[0]
        cached = self._cache.get(bound)
        if cached is None or cached[0].shape[0] != n:
            cached = (pred.copy(), np.full(n, -1, np.int64), np.zeros(n))
            self._cache[bound] = cached
            stale = np.arange(n)
        else:
            moved = pred - cached[0]
            stale = np.flatnonzero(np.einsum('ij,ij->i', moved, moved) >= cached[2])
        if stale.size:
            self._refresh(pred, stale, bound, *cached)
        idx = cached[1]
        near = self._padded[idx]
        diff = pred - near
        r = np.sqrt(np.einsum('ij,ij->i', diff, diff))
        missing = idx < 0
        if bound is not None:
            missing |= r >= bound
        r[missing] = np.inf
        out = np.where(missing, -1, idx)
        return r, out, near

    def _refresh(self, pred: np.ndarray, stale: np.ndarray, bound: float | None,
                 ref: np.ndarray, idx: np.ndarray, radius_sq: np.ndarray) -> None:
        """Query the stale predictions' two closest points and record their validity."""
        self.queried += stale.size
        reach = np.inf if bound is None else bound + max(bound, REACH_MARGIN_PX)
        d, i = self.tree.query(pred[stale], k=2, distance_upper_bound=reach)
        found = i[:, 0] < self.points.shape[0]
        second = np.where(np.isfinite(d[:, 1]), d[:, 1], reach)
        ref[stale] = pred[stale]
        idx[stale] = np.where(found, i[:, 0], -1)
        radius = np.where(found, 0.5 * (second - d[:, 0]),
                          reach - (bound if bound is not None else 0.0))
        radius_sq[stale] = radius * radius
