"""Dense ground/obstacle mask from the plane homography, and its picture.

:func:`plane_mask` warps the right image into the left view with the plane homography and
compares the two with a local zero-mean normalised cross-correlation (NCC), computed with box
filters. NCC does not change under a gain and offset between the cameras. Where the floor is
seen, the warped right image equals the left one and the NCC is high; on an obstacle the
parallax the plane does not predict breaks the match. Windows with too little texture in
either image, or reaching outside the right image, are unknown. The labels are cleaned by a
small opening and closing, and unknown low-texture regions enclosed by floor (the plain
interior of a tile, say) can be filled as floor.

Labels: :data:`PLANE` (255) on the dominant plane, :data:`OBSTACLE` (127) off it,
:data:`UNKNOWN` (0) undecided.
"""

from __future__ import annotations

import math

import cv2
from domplane_ros.config import MaskConfig
from domplane_ros.core.homography import as_valid_homography, resize_homography
from domplane_ros.core.image import check_gray
import numpy as np

PLANE = 255
OBSTACLE = 127
UNKNOWN = 0

# An unknown region is filled as plane when at least this share of its outline is plane.
_FILL_OUTLINE_SHARE = 0.95
# Translucency of the overlay tint.
_TINT_ALPHA = 0.35
# Colours of :func:`overlay` (RGB); core/legend.py names them.
PLANE_RGB = (0, 255, 0)
OBSTACLE_RGB = (255, 0, 0)
INLIER_RGB = (0, 255, 255)
OUTLIER_RGB = (255, 0, 255)


def _resize(image: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the image resized by ``scale`` (at least 1 x 1) and the (3, 3) pixel map."""
    height, width = image.shape
    new_w, new_h = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    if (new_w, new_h) == (width, height):
        return image, np.eye(3)
    small = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_AREA)
    return small, resize_homography(new_w / width, new_h / height)


def _fill_enclosed(labels: np.ndarray, fillable: np.ndarray) -> None:
    """Label as plane, in place, fillable regions whose outline is (almost) all plane.

    Args:
        labels: (h, w) uint8 labels, changed in place.
        fillable: (h, w) bool, unknown pixels that may become plane (low texture, but inside
            the right image).

    """
    count, components = cv2.connectedComponents(fillable.astype(np.uint8), connectivity=4)
    if count <= 1:
        return
    # Each outline pixel (next to a component, not in one) takes the largest neighbouring
    # component id; pixels between two components are rare and only blur the vote.
    grown = cv2.dilate(components.astype(np.float32), np.ones((3, 3), np.uint8)).astype(
        np.int32)
    outline = (grown > 0) & (components == 0)
    ids = grown[outline]
    is_plane = labels[outline] == PLANE
    total = np.bincount(ids, minlength=count)
    plane = np.bincount(ids, weights=is_plane, minlength=count)
    # Regions touching the image border have part of their outline outside the image.
    border = np.zeros(count, bool)
    for edge in (components[0], components[-1], components[:, 0], components[:, -1]):
        border[edge] = True
    fill = (plane >= _FILL_OUTLINE_SHARE * np.maximum(total, 1)) & (total > 0) & ~border
    fill[0] = False
    labels[fill[components]] = PLANE


def plane_mask(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
               config: MaskConfig, fill_enclosed: bool = True) -> np.ndarray:
    """Label every left pixel as on the plane, off the plane or unknown.

    Works at ``config.scale`` resolution: the right image is warped into the left view with the
    plane homography (scaled as ``S_r H S_l^-1``), and a zero-mean normalised
    cross-correlation over ``config.window_px`` windows decides plane (NCC at least
    ``config.ncc_threshold``) or obstacle. Windows where either image's grey-level standard
    deviation is below ``config.min_texture``, or that reach outside the right image, are
    unknown. The plane and obstacle labels are then opened and closed with a
    ``config.morph_px`` square, and the result is upsampled to the left image's size by
    nearest neighbour.

    Args:
        left: (H, W) uint8 left image.
        right: (H', W') uint8 right image; its size may differ from the left image's.
        homography: (3, 3) float plane homography mapping left pixels to right pixels.
        config: Mask settings.
        fill_enclosed: Label as plane the low-texture unknown regions whose outline is (at
            least 95 %) plane, such as the plain interior of a floor tile. Obstacles are never
            relabelled, and pixels that map outside the right image stay unknown.

    Returns:
        (H, W) uint8 labels: 255 plane, 127 obstacle, 0 unknown.

    Raises:
        ValueError: If an image is not a non-empty 2-D uint8 array, or the homography is not a
            finite, non-singular (3, 3) matrix.

    """
    left = check_gray(left, 'left')
    right = check_gray(right, 'right')
    hom = as_valid_homography(homography)
    height, width = left.shape
    left_small, scale_left = _resize(left, config.scale)
    right_small, scale_right = _resize(right, config.scale)
    small_h, small_w = left_small.shape
    hom_small = scale_right @ hom @ np.linalg.inv(scale_left)
    if not np.all(np.isfinite(hom_small)):
        raise ValueError('homography is not invertible at mask scale')
    window = int(config.window_px)
    warped, valid = _warp_to_left(right_small, hom_small, (small_w, small_h), window)
    labels = _ncc_labels(left_small, warped, valid, window, config)
    _open_and_close(labels, valid, int(config.morph_px))
    if fill_enclosed:
        _fill_enclosed(labels, (labels == UNKNOWN) & valid)
    if (small_h, small_w) != (height, width):
        labels = cv2.resize(labels, (width, height), interpolation=cv2.INTER_NEAREST_EXACT)
    return labels


def _warp_to_left(right: np.ndarray, homography: np.ndarray, size: tuple[int, int],
                  window: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the right image warped into the left view, and the (h, w) bool valid windows.

    A window is valid when all its pixels map inside the right image (with all four bilinear
    neighbours inside).
    """
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    warped = cv2.warpPerspective(right, homography, size, flags=flags,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    inside = cv2.warpPerspective(np.full(right.shape, 255, np.uint8), homography, size,
                                 flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    kernel = np.ones((window, window), np.uint8)
    valid = cv2.erode(inside, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) == 255
    return warped, valid


def _ncc_labels(left: np.ndarray, warped: np.ndarray, valid: np.ndarray, window: int,
                config: MaskConfig) -> np.ndarray:
    """Return (h, w) uint8 labels by the local zero-mean NCC of two aligned images."""
    a = left.astype(np.float32)
    b = warped.astype(np.float32)
    size = (window, window)
    mean_a = cv2.blur(a, size)
    mean_b = cv2.blur(b, size)
    var_a = cv2.blur(a * a, size) - mean_a * mean_a
    var_b = cv2.blur(b * b, size) - mean_b * mean_b
    cov = cv2.blur(a * b, size) - mean_a * mean_b
    min_var = float(config.min_texture) ** 2
    textured = (var_a >= min_var) & (var_b >= min_var) & (var_a > 0) & (var_b > 0)
    decided = valid & textured
    # ncc >= t  <=>  cov >= t sqrt(var_a var_b), without dividing by small numbers.
    bound = config.ncc_threshold * np.sqrt(np.maximum(var_a * var_b, 0.0))
    on_plane = decided & (cov >= bound)
    labels = np.full(left.shape, UNKNOWN, np.uint8)
    labels[decided] = OBSTACLE
    labels[on_plane] = PLANE
    return labels


def _open_and_close(labels: np.ndarray, valid: np.ndarray, morph: int) -> None:
    """Clean the plane and obstacle labels in place by a ``morph`` square (< 2: no-op)."""
    if morph < 2:
        return
    square = np.ones((morph, morph), np.uint8)
    for value in (OBSTACLE, PLANE):
        region = (labels == value).astype(np.uint8)
        cleaned = cv2.morphologyEx(region, cv2.MORPH_OPEN, square)
        cleaned = cv2.morphologyEx(cleaned, cv2.MORPH_CLOSE, square)
        # Opening drops specks (to unknown). Closing fills gaps inside a region: the
        # obstacle's may claim plane and unknown pixels, the plane's only unknown ones,
        # so obstacles stay intact; pixels outside the right image stay unknown.
        labels[(region == 1) & (cleaned == 0)] = UNKNOWN
        claim = (cleaned == 1) & (region == 0) & valid
        if value == PLANE:
            claim &= labels == UNKNOWN
        labels[claim] = value


def overlay(gray: np.ndarray, mask: np.ndarray, inliers: np.ndarray | None = None,
            outliers: np.ndarray | None = None, inlier_lines: np.ndarray | None = None,
            outlier_lines: np.ndarray | None = None) -> np.ndarray:
    """Draw the mask and the points over a grey image.

    Args:
        gray: (H, W) uint8 image.
        mask: (H, W) uint8 labels from :func:`plane_mask`: plane pixels get a translucent
            green tint, obstacle pixels red, unknown pixels none.
        inliers: Optional (N, 2) float (x, y) points, drawn as small cyan circles (corners
            the plane maps onto a right corner).
        outliers: Optional (M, 2) float (x, y) points, drawn as small magenta crosses
            (corners the plane maps onto none: unmatched, not necessarily off the plane).
        inlier_lines: Optional (K, 4) float segments (x1, y1, x2, y2), drawn in cyan.
        outlier_lines: Optional (L, 4) float segments, drawn in magenta.

    Returns:
        (H, W, 3) uint8 RGB image.

    Raises:
        ValueError: If the image or mask is not (H, W) uint8 of the same shape, a point
            array is not (N, 2) or a segment array not (N, 4).

    """
    gray = check_gray(gray, 'gray')
    mask = check_gray(mask, 'mask')
    if mask.shape != gray.shape:
        raise ValueError(f'mask shape {mask.shape} differs from image shape {gray.shape}')
    rgb = cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB)
    for value, colour in ((PLANE, PLANE_RGB), (OBSTACLE, OBSTACLE_RGB)):
        region = (mask == value).astype(np.uint8) if mask.size == 1 else cv2.compare(
            mask, value, cv2.CMP_EQ)  # cv2.compare takes a 1 x 1 array for a scalar
        if cv2.countNonZero(region):
            tinted = cv2.addWeighted(rgb, 1.0 - _TINT_ALPHA, np.full_like(rgb, colour),
                                     _TINT_ALPHA, 0.0)
            cv2.copyTo(tinted, region, rgb)
    for name, segments, colour in (('inlier_lines', inlier_lines, INLIER_RGB),
                                   ('outlier_lines', outlier_lines, OUTLIER_RGB)):
        for x1, y1, x2, y2 in _fixed_point_rows(name, segments, 4):
            cv2.line(rgb, (int(x1), int(y1)), (int(x2), int(y2)), colour, 1, cv2.LINE_AA,
                     shift=4)
    radius = max(2, int(round(min(gray.shape) / 160)))
    for name, points, colour in (('inliers', inliers, INLIER_RGB),
                                 ('outliers', outliers, OUTLIER_RGB)):
        for x, y in _fixed_point_rows(name, points, 2):
            centre = (int(x), int(y))
            if name == 'inliers':
                cv2.circle(rgb, centre, radius * 16, colour, 1, cv2.LINE_AA, shift=4)
            else:
                for dx, dy in ((1, 1), (1, -1)):
                    cv2.line(rgb, (int(x - dx * radius * 16), int(y - dy * radius * 16)),
                             (int(x + dx * radius * 16), int(y + dy * radius * 16)), colour,
                             1, cv2.LINE_AA, shift=4)
    return rgb


def _fixed_point_rows(name: str, rows: np.ndarray | None, columns: int) -> np.ndarray:
    """Return finite (N, columns) drawing coordinates with 4 fractional bits (cv2 ``shift=4``).

    Raises:
        ValueError: If ``rows`` is not empty and not of shape (N, columns).

    """
    if rows is None:
        return np.zeros((0, columns), np.int64)
    arr = np.asarray(rows, dtype=np.float64)
    if arr.size == 0:
        return np.zeros((0, columns), np.int64)
    if arr.ndim != 2 or arr.shape[1] != columns:
        raise ValueError(f'{name} must have shape (N, {columns}), got {arr.shape}')
    arr = arr[np.all(np.isfinite(arr), axis=1)]
    return np.clip(np.rint(arr * 16).astype(np.int64), -(2 ** 24), 2 ** 24)


def mask_scores(mask: np.ndarray, plane_truth: np.ndarray, obstacle_truth: np.ndarray,
                valid: np.ndarray | None = None) -> dict[str, float]:
    """Score a mask against the truth.

    Args:
        mask: (H, W) uint8 labels from :func:`plane_mask`.
        plane_truth: (H, W) bool, pixels truly on the plane (and decidable, for example
            ``plane_left & visible_in_right`` of a rendered frame).
        obstacle_truth: (H, W) bool, pixels truly on an obstacle.
        valid: Optional (H, W) bool, the pixels to score (default: all).

    Returns:
        A dict of floats (NaN where the denominator is empty):
        ``plane_iou`` (pixels labelled plane vs true plane pixels), ``plane_precision``,
        ``plane_recall``, ``obstacle_recall`` (true obstacle pixels labelled obstacle),
        ``obstacle_precision``, ``obstacle_as_plane`` (true obstacle pixels labelled plane),
        ``unknown_fraction`` (pixels labelled unknown), ``plane_fraction`` (pixels labelled
        plane), all over the valid pixels.

    Raises:
        ValueError: If the arrays are not 2-D with the same shape.

    """
    mask = np.asarray(mask)
    arrays = {'mask': mask, 'plane_truth': np.asarray(plane_truth, bool),
              'obstacle_truth': np.asarray(obstacle_truth, bool)}
    if valid is not None:
        arrays['valid'] = np.asarray(valid, bool)
    for name, array in arrays.items():
        if array.ndim != 2 or array.shape != mask.shape:
            raise ValueError(f'{name} must be 2-D with the mask shape {mask.shape}, got '
                             f'{array.shape}')
    keep = arrays.get('valid', np.ones(mask.shape, bool))
    plane_pred = (mask == PLANE) & keep
    obstacle_pred = (mask == OBSTACLE) & keep
    plane_true = arrays['plane_truth'] & keep
    obstacle_true = arrays['obstacle_truth'] & keep

    def ratio(num: np.ndarray, den: np.ndarray) -> float:
        total = int(np.count_nonzero(den))
        return float(np.count_nonzero(num)) / total if total else math.nan

    return {
        'plane_iou': ratio(plane_pred & plane_true, plane_pred | plane_true),
        'plane_precision': ratio(plane_pred & plane_true, plane_pred),
        'plane_recall': ratio(plane_pred & plane_true, plane_true),
        'obstacle_recall': ratio(obstacle_pred & obstacle_true, obstacle_true),
        'obstacle_precision': ratio(obstacle_pred & obstacle_true, obstacle_pred),
        'obstacle_as_plane': ratio(plane_pred & obstacle_true, obstacle_true),
        'unknown_fraction': ratio((mask == UNKNOWN) & keep, keep),
        'plane_fraction': ratio(plane_pred, keep),
    }
