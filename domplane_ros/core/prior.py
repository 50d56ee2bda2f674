"""Initial homographies from rough ranges of the camera set-up (Fornland & Schnörr, sec. 2.4).

The camera model (shared with the scene renderer in :mod:`domplane_ros.sim.model`):

* Left camera frame: x right, y down, z forward (optical axis). Principal point at the image
  centre unless ``prior.principal_point_px`` gives it, square pixels, focal length ``f`` in
  pixels: ``K = [[f, 0, cx], [0, f, cy], [0, 0, 1]]``.
* The plane lies at height ``h`` below the left camera. The camera is tilted toward it by
  ``tilt`` (positive looks down), so the plane's unit normal in left-camera coordinates is
  ``n = (0, cos(tilt), sin(tilt))`` and the plane is ``n . X = h``.
* The right camera's centre is ``C = (b, 0, 0)`` in left-camera coordinates, and it is yawed
  toward the left camera by the vergence ``v`` (positive converges):
  ``X_right = R_v (X_left - C)`` with ``R_v = [[cos v, 0, sin v], [0, 1, 0], [-sin v, 0, cos v]]``.

A plane point then maps from the left to the right image by
``H = K R_v (I - C n^T / h) K^-1``, which depends on ``b`` and ``h`` only through ``b / h``.

The search (:class:`PriorSearch`) screens every candidate by a cheap truncated
closest-feature energy and runs the full two-step iteration from the best few; the one-shot
estimator refines them all at once, the pipeline a few per frame.
"""

from __future__ import annotations

import functools
import math
from typing import Callable, Collection, Iterable, Sequence, TYPE_CHECKING

import cv2
from domplane_ros.core.homography import FAR_PX, MIN_W
from domplane_ros.core.result import better_estimate, FailedEstimate, PlaneEstimate
import numpy as np

if TYPE_CHECKING:
    from domplane_ros.config import EstimatorConfig, PriorConfig
    from domplane_ros.core.estimator import TwoStep
    from scipy.spatial import cKDTree


def plane_homography(focal_px: float, baseline_over_height: float, tilt_deg: float,
                     vergence_deg: float, width: int, height: int,
                     principal_px: Sequence[float] = ()) -> np.ndarray:
    """Return the left-to-right homography of the ground plane for one camera set-up.

    Args:
        focal_px: Focal length in pixels (both cameras).
        baseline_over_height: Stereo baseline divided by the camera height above the plane.
        tilt_deg: Tilt of the cameras toward the plane, degrees (positive looks down).
        vergence_deg: Yaw of the right camera toward the left one, degrees.
        width: Image width in pixels.
        height: Image height in pixels.
        principal_px: Principal point ``(cx, cy)`` in pixels; empty: the image centre.

    Returns:
        (3, 3) float64 homography with ``H[2, 2] == 1``, mapping left pixels (x, y, 1) to
        right pixels.

    Raises:
        ValueError: If a value is non-finite, the focal length or image size is not
            positive, or the plane normal is degenerate.

    """
    values = (focal_px, baseline_over_height, tilt_deg, vergence_deg)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f'camera set-up values must be finite, got {values!r}')
    if focal_px <= 0 or width <= 0 or height <= 0:
        raise ValueError(
            f'focal_px, width and height must be positive, got {focal_px}, {width}, {height}')
    k = intrinsics(focal_px, width, height, principal_px)
    tilt = math.radians(tilt_deg)
    verg = math.radians(vergence_deg)
    normal = np.array([0.0, math.cos(tilt), math.sin(tilt)])
    centre = np.array([baseline_over_height, 0.0, 0.0])
    r_v = np.array([[math.cos(verg), 0.0, math.sin(verg)],
                    [0.0, 1.0, 0.0],
                    [-math.sin(verg), 0.0, math.cos(verg)]])
    h = k @ r_v @ (np.eye(3) - np.outer(centre, normal)) @ np.linalg.inv(k)
    if abs(h[2, 2]) < 1e-12:
        raise ValueError('degenerate camera set-up: H[2, 2] is zero')
    return h / h[2, 2]


def intrinsics(focal_px: float, width: int, height: int,
               principal_px: Sequence[float] = ()) -> np.ndarray:
    """Return the (3, 3) calibration matrix; the principal point is the image centre unless given.

    Raises:
        ValueError: If ``principal_px`` is neither empty nor two finite numbers.

    """
    if len(principal_px) == 0:
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    elif len(principal_px) == 2 and all(math.isfinite(v) for v in principal_px):
        cx, cy = (float(v) for v in principal_px)
    else:
        raise ValueError(f'principal point must be empty or (cx, cy), got {principal_px!r}')
    return np.array([[focal_px, 0.0, cx],
                     [0.0, focal_px, cy],
                     [0.0, 0.0, 1.0]])


def _samples(bounds: tuple[float, float], count: int) -> np.ndarray:
    low, high = bounds
    if high <= low or count == 1:
        return np.array([0.5 * (low + high)])
    return np.linspace(low, high, count)


def prior_candidates(prior: PriorConfig, width: int, height: int) -> np.ndarray:
    """Return candidate homographies on a grid over the camera set-up ranges.

    Each range gets ``prior.samples`` evenly spaced values (one, its middle, if it is a
    single value), and every combination gives one candidate
    ``H = K R_v (I - C n^T / h) K^-1``.

    Args:
        prior: The camera set-up ranges.
        width: Left image width in pixels.
        height: Left image height in pixels.

    Returns:
        (M, 3, 3) float64 candidate homographies, ``H[2, 2] == 1``.

    Raises:
        ValueError: If the image size is not positive.

    """
    if width <= 0 or height <= 0:
        raise ValueError(f'image size must be positive, got {width}x{height}')
    # The grid depends only on the (frozen, hashable) prior and the size: computed once per
    # process, so a fresh pipeline's cold start does not pay for it again.
    return _candidate_grid(prior, int(width), int(height)).copy()


def swapped_candidates(candidates: np.ndarray) -> np.ndarray:
    """Return the candidates' planes seen by the same heads with left and right exchanged.

    A head whose image topics are swapped maps the floor from its given left image to its
    given right one by ``H^-1``: the inverse of a candidate of the prior's camera model. These
    hypotheses let a search test the swap explicitly rather than hope a look-alike of the
    correctly ordered model scores lower than the plane it did not look for.

    Args:
        candidates: (M, 3, 3) float64 homographies (:func:`prior_candidates`).

    Returns:
        (M, 3, 3) float64 inverses, ``H[2, 2] == 1``.

    """
    inverse = np.linalg.inv(candidates)
    return inverse / inverse[:, 2:3, 2:3]


def leaning_candidates(candidates: np.ndarray, height: int) -> np.ndarray:
    """Return the candidates' planes mirrored top to bottom: planes leaning toward the head.

    The prior's camera model describes a plane below the head (its disparity grows toward the
    image bottom). Mirroring the image rows (``y -> height - 1 - y``, on both images) keeps
    the baseline's side and turns each such plane into one above or in front of the head
    whose disparity grows toward the image *top*: a ceiling, or a board or wall leaning its
    top toward the cameras, which ``verification.plane: any`` looks for as well. The
    principal point is mirrored with the rows.

    Args:
        candidates: (M, 3, 3) float64 homographies (:func:`prior_candidates`).
        height: Image height in pixels.

    Returns:
        (M, 3, 3) float64 homographies ``F H F`` with ``F`` the row mirror, ``H[2, 2] == 1``.

    """
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, height - 1.0], [0.0, 0.0, 1.0]])
    mirrored = flip @ candidates @ flip
    return mirrored / mirrored[:, 2:3, 2:3]


def search_candidates(prior: PriorConfig, width: int, height: int, plane: str = 'ground'
                      ) -> np.ndarray:
    """Return the candidates a search screens for ``verification.plane`` (ground or any).

    ``ground``: :func:`prior_candidates`; ``any``: those followed by their
    :func:`leaning_candidates` (twice as many).
    """
    candidates = prior_candidates(prior, width, height)
    if plane == 'ground':
        return candidates
    return np.concatenate([candidates, leaning_candidates(candidates, height)])


@functools.lru_cache(maxsize=16)
def _candidate_grid(prior: PriorConfig, width: int, height: int) -> np.ndarray:
    out = [plane_homography(f, bh, tilt, verg, width, height, prior.principal_point_px)
           for f in _samples(prior.focal_px, prior.samples)
           for bh in _samples(prior.baseline_over_height, prior.samples)
           for tilt in _samples(prior.tilt_deg, prior.samples)
           for verg in _samples(prior.vergence_deg, prior.samples)]
    return np.stack(out)


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


class PriorSearch:
    """The prior search over one feature set: screen every candidate, refine the best.

    One search serves :func:`~domplane_ros.core.plane.estimate_plane` (the best
    ``prior.refine_best`` at once) and the pipeline (a few per frame, new features each
    frame). The feature set's search structures (the right points' KD-tree, the line matcher,
    the refiner) live in ``problem``, built once and shared by the screening and every
    refinement.

    Args:
        problem: The two-step iteration over the feature set
            (:meth:`~domplane_ros.core.estimator.TwoStep.from_features`).
        candidates: (M, 3, 3) float64 candidate homographies (:func:`prior_candidates`).
        threshold_px: Truncation of the screening energy, pixels.

    """

    def __init__(self, problem: TwoStep, candidates: np.ndarray, threshold_px: float) -> None:
        """Screen every candidate."""
        self.problem = problem
        self.candidates = candidates
        self.costs = problem.screening_energy(candidates, threshold_px)

    def ranked(self, skip: Collection[int] = ()) -> list[int]:
        """Return the candidates' indices, lowest screening energy first, leaving out ``skip``.

        Ties keep the index order.
        """
        return [int(i) for i in np.argsort(self.costs, kind='stable') if int(i) not in skip]

    def refine(self, indices: Iterable[int], options: EstimatorConfig,
               rejection: Callable[[PlaneEstimate], str] | None = None,
               best: PlaneEstimate | FailedEstimate | None = None
               ) -> tuple[PlaneEstimate | FailedEstimate | None, str]:
        """Run the full iteration from each candidate of ``indices``; keep the best result.

        Args:
            indices: Candidates to refine.
            options: Estimator settings.
            rejection: Optional check of a successful result: it returns why the result must
                not be taken (``''`` if it may); a rejected result is dropped.
            best: The best result so far (from earlier frames' candidates), if any; a
                candidate replaces it only if it is better.

        Returns:
            The best result that was not rejected (see
            :func:`~domplane_ros.core.result.better_estimate`), None if there was none, and
            the reason of the last rejection (``''`` if none was rejected).

        """
        rejected = ''
        for index in indices:
            result = self.problem.estimate(self.candidates[index], options, widen=False)
            reason = rejection(result) if rejection is not None and result.ok else ''
            if reason:
                rejected = reason
            elif best is None or better_estimate(result, best):
                best = result
        return best, rejected
