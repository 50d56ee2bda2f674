"""Corner detection spread over the image by a grid.

The estimator needs well-localised corners that repeat in both images, spread over the floor
rather than piled up on the most textured obstacle. :func:`detect_corners` computes the
Shi-Tomasi (minimum eigenvalue) corner response once over the region of interest, keeps the
local maxima above ``quality_level`` times the strongest response that are also the strongest
within ``min_distance_px``, and then takes corners round-robin over the grid cells: first the
best corner of every cell, then the second best, and so on. Every cell thus gets an equal
share of ``max_points``, and cells with too few corners give the rest of their share to the
others. The chosen corners are refined to sub-pixel accuracy (a parabola fit of the response
peak, then ``cv2.cornerSubPix``).
"""

from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import cv2
from domplane_ros.config import FeatureConfig
from domplane_ros.core.image import check_gray
import numpy as np

# Corner responses at or below this are noise-free flat image regions (cv2.cornerMinEigenVal
# normalises gradients of 8-bit images to [0, 1], so a one-grey-level step is ~1e-6).
_MIN_RESPONSE = 1e-7
# Three iterations are enough: the start is within a pixel of the corner (measured).
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 3, 0.1)


class Features(NamedTuple):
    """One stereo pair's features (no correspondences between the images).

    Attributes:
        left_points: (N, 2) float64 left corners ``(x, y)``.
        right_points: (M, 2) float64 right corners.
        left_lines: (K, 4) float64 left segments ``(x1, y1, x2, y2)``.
        right_lines: (L, 4) float64 right segments.

    """

    left_points: np.ndarray
    right_points: np.ndarray
    left_lines: np.ndarray
    right_lines: np.ndarray

    @property
    def n_left(self) -> int:
        """Return the number of left features (corners plus segments)."""
        return int(self.left_points.shape[0] + self.left_lines.shape[0])

    @property
    def n_right(self) -> int:
        """Return the number of right features (corners plus segments)."""
        return int(self.right_points.shape[0] + self.right_lines.shape[0])


def roi_to_pixels(roi: Sequence[float], width: int, height: int) -> tuple[int, int, int, int]:
    """Convert a fractional region of interest to pixel bounds.

    Args:
        roi: ``(x0, y0, x1, y1)`` as fractions of the image size, ``0 <= x0 < x1 <= 1`` and
            ``0 <= y0 < y1 <= 1``.
        width: Image width in pixels.
        height: Image height in pixels.

    Returns:
        ``(x0, y0, x1, y1)`` integer pixel bounds, end exclusive, clipped to the image.

    Raises:
        ValueError: If ``roi`` does not hold four finite fractions forming a non-empty box.

    """
    x0, y0, x1, y1 = check_roi(roi)
    return (int(math.floor(x0 * width)), int(math.floor(y0 * height)),
            int(math.ceil(x1 * width)), int(math.ceil(y1 * height)))


def check_roi(roi: Sequence[float]) -> tuple[float, float, float, float]:
    """Return a region of interest as four fractions ``(x0, y0, x1, y1)`` of the image size.

    Raises:
        ValueError: If ``roi`` does not hold four finite fractions forming a non-empty box.

    """
    try:
        values = tuple(float(v) for v in roi)
    except (TypeError, ValueError) as err:
        raise ValueError(f'roi must be four numbers (x0, y0, x1, y1), got {roi!r}') from err
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise ValueError(f'roi must be four finite numbers (x0, y0, x1, y1), got {roi!r}')
    x0, y0, x1, y1 = values
    if not (0.0 <= x0 < x1 <= 1.0 and 0.0 <= y0 < y1 <= 1.0):
        raise ValueError(
            f'roi must be fractions with 0 <= x0 < x1 <= 1 and 0 <= y0 < y1 <= 1, got {roi!r}')
    return x0, y0, x1, y1


def gray_roi(gray: np.ndarray, roi: Sequence[float]) -> tuple[int, int, int, int]:
    """Check a grey image and return its region of interest in pixels (:func:`roi_to_pixels`).

    Raises:
        ValueError: If ``gray`` is not a 2-D uint8 array or ``roi`` is invalid.

    """
    check_gray(gray)
    height, width = gray.shape
    return roi_to_pixels(roi, width, height)


def detect_corners(gray: np.ndarray, config: FeatureConfig,
                   roi: Sequence[float] | None = None) -> np.ndarray:
    """Detect corners spread over a grid of cells, refined to sub-pixel accuracy.

    Args:
        gray: (H, W) uint8 image.
        config: Detector settings: ``max_points``, ``quality_level``, ``min_distance_px``,
            ``block_size``, ``grid_rows`` x ``grid_cols`` and the default ``roi``.
        roi: Optional ``(x0, y0, x1, y1)`` region of interest as fractions of the image size;
            overrides ``config.roi``. The grid divides this region.

    Returns:
        (N, 2) float64 corner positions ``(x, y)`` in full-image pixels, ``N <= max_points``,
        in selection order (best corners of every cell first). A flat (for example black)
        image, or an image or region too small for the detector window, gives (0, 2).

    Raises:
        ValueError: If ``gray`` is not a 2-D uint8 array or ``roi`` is invalid.

    """
    x0, y0, x1, y1 = gray_roi(gray, config.roi if roi is None else roi)
    height, width = gray.shape
    empty = np.zeros((0, 2), np.float64)
    block = int(config.block_size)
    # Candidates keep this far from the image border, so the response window and the
    # sub-pixel window stay inside the image.
    border = block // 2 + 2
    box = (max(x0, border), max(y0, border), min(x1, width - border), min(y1, height - border))
    lo_x, lo_y, hi_x, hi_y = box
    if hi_x <= lo_x or hi_y <= lo_y:
        return empty
    # Compute the response on the region grown by a margin, so the region's edge is not an
    # artificial image border.
    pad = block // 2 + 1
    cx0, cy0 = max(0, lo_x - pad), max(0, lo_y - pad)
    cx1, cy1 = min(width, hi_x + pad), min(height, hi_y + pad)
    response = cv2.cornerMinEigenVal(gray[cy0:cy1, cx0:cx1], block, ksize=3)
    offset = (lo_x - cx0, lo_y - cy0)
    found = _local_maxima(response, offset, (hi_x - lo_x, hi_y - lo_y), config)
    if found is None:
        return empty
    xs, ys, strength = found
    rows = min(config.grid_rows, hi_y - lo_y)
    cols = min(config.grid_cols, hi_x - lo_x)
    cell = (ys * rows // (hi_y - lo_y)) * cols + xs * cols // (hi_x - lo_x)
    chosen = grid_round_robin(strength, cell, config.max_points)
    return _refine_subpixel(gray, response, xs[chosen], ys[chosen], offset, box, block)


def grid_round_robin(strength: np.ndarray, cell: np.ndarray, limit: int) -> np.ndarray:
    """Return the indices of at most ``limit`` features taken round-robin over grid cells.

    Each feature is ranked within its cell by strength; rank 0 of every cell comes first,
    then rank 1, and so on (ties by strength), so every cell gets an equal share.

    Args:
        strength: (N,) float64 feature strengths (corner response, segment length).
        cell: (N,) int64 grid cell of each feature.
        limit: Most features returned.

    Returns:
        (K,) int64 indices into the features, K <= limit, in selection order.

    """
    order = np.lexsort((-strength, cell))
    sorted_cell = cell[order]
    first = np.searchsorted(sorted_cell, sorted_cell, side='left')
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size) - first
    return np.lexsort((-strength, rank))[:limit]


def _local_maxima(response: np.ndarray, offset: tuple[int, int], size: tuple[int, int],
                  config: FeatureConfig
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Return the corners of the inner window: x, y (window pixels) and response, or None.

    A corner is a response above ``quality_level`` times the strongest (and above noise) that
    is also the strongest within ``min_distance_px``.
    """
    (ox, oy), (w, h) = offset, size
    inner = response[oy:oy + h, ox:ox + w]
    strongest = float(inner.max())
    if strongest <= _MIN_RESPONSE:
        return None
    threshold = max(config.quality_level * strongest, _MIN_RESPONSE)
    # Keep the strongest response within min_distance_px (a square neighbourhood).
    radius = max(1, int(round(config.min_distance_px)))
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * radius + 1, 2 * radius + 1))
    peaks = cv2.dilate(response, kernel)[oy:oy + h, ox:ox + w]
    # (cv2.compare takes a 1 x 1 array for a scalar, hence numpy for that size.)
    above = (cv2.compare(inner, threshold, cv2.CMP_GT) if inner.size > 1
             else (inner > threshold).astype(np.uint8) * 255)
    keep = cv2.bitwise_and(cv2.compare(inner, peaks, cv2.CMP_GE), above)
    found = cv2.findNonZero(keep)
    if found is None:
        return None
    found = found.reshape(-1, 2).astype(np.int64)  # (N, 2) or (N, 1, 2) by cv2 version
    xs, ys = found[:, 0], found[:, 1]
    return xs, ys, inner[ys, xs]


def _refine_subpixel(gray: np.ndarray, response: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                     offset: tuple[int, int], box: tuple[int, int, int, int],
                     block: int) -> np.ndarray:
    """Return (N, 2) float64 sub-pixel positions of corners at window pixels ``(xs, ys)``.

    First the vertex of a parabola through the response peak and its neighbours along x and
    y (free), then cv2.cornerSubPix (a few iterations). The parabola alone is biased at
    X-junctions (tiles, checkers), where the response has two peaks beside the junction;
    cornerSubPix moves to the saddle point. Where cornerSubPix leaves its window (blurry,
    edge-like corners) the parabola vertex is kept.
    """
    lo_x, lo_y, hi_x, hi_y = box
    ry, rx = ys + offset[1], xs + offset[0]
    centre = response[ry, rx].astype(np.float64)
    offsets = []
    for before, after in ((response[ry, rx - 1], response[ry, rx + 1]),
                          (response[ry - 1, rx], response[ry + 1, rx])):
        curvature = before - 2.0 * centre + after
        step = 0.5 * (before - after) / np.where(curvature < -1e-20, curvature, -np.inf)
        offsets.append(np.clip(step, -0.5, 0.5))
    low = np.array([lo_x, lo_y], np.float64)
    high = np.array([hi_x - 1, hi_y - 1], np.float64)
    peak = np.clip(np.stack([xs + lo_x + offsets[0], ys + lo_y + offsets[1]], axis=1), low,
                   high)
    refined, good = _corner_subpix(gray, peak, block, low, high)
    return np.where(good[:, None], refined, peak)


def corners_in_region(gray: np.ndarray, points: np.ndarray, config: FeatureConfig,
                      roi: Sequence[float] | None = None) -> np.ndarray:
    """Return the indices of points where :func:`detect_corners` could have found a corner.

    That is inside the region of interest and at least the detector's border from the image
    edge (corners tracked into this image from another one keep the detector's rules).

    Args:
        gray: (H, W) uint8 image.
        points: (N, 2) float64 positions, pixels.
        config: Detector settings (``block_size`` and the default ``roi``).
        roi: Optional region of interest as fractions; overrides ``config.roi``.

    Returns:
        (K,) int64 indices of the points inside, in the given order.

    Raises:
        ValueError: If ``gray`` is not a 2-D uint8 array or ``roi`` is invalid.

    """
    x0, y0, x1, y1 = gray_roi(gray, config.roi if roi is None else roi)
    height, width = gray.shape
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    border = int(config.block_size) // 2 + 2
    low = np.array([max(x0, border), max(y0, border)], np.float64)
    high = np.array([min(x1, width - border) - 1, min(y1, height - border) - 1], np.float64)
    return np.flatnonzero(np.all((points >= low) & (points <= high), axis=1))


def _corner_subpix(gray: np.ndarray, start: np.ndarray, block: int, low: np.ndarray,
                   high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return cv2.cornerSubPix positions of (N, 2) ``start`` and (N,) bool: stayed in place.

    A refinement is good if it is finite, within its window of the start and inside the
    box ``low`` .. ``high``.
    """
    height, width = gray.shape
    # cornerSubPix needs the window plus a margin inside the image.
    half = min(max(2, block), (width - 6) // 2, (height - 6) // 2)
    if half < 1:
        return start, np.zeros(start.shape[0], bool)
    refined = cv2.cornerSubPix(gray, start.astype(np.float32).reshape(-1, 1, 2), (half, half),
                               (-1, -1), _SUBPIX_CRITERIA).reshape(-1, 2).astype(np.float64)
    good = (np.all(np.isfinite(refined), axis=1)
            & np.all(np.abs(refined - start) <= half, axis=1)
            & np.all((refined >= low) & (refined <= high), axis=1))
    return refined, good
