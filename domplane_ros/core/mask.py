"""Ground / obstacle / unknown mask from the residual parallax after the plane warp.

:func:`parallax_mask` warps the right image into the left view with the plane homography
``H`` at ``config.scale`` and measures, per pixel, the **residual parallax**: the shift along
the epipolar direction (the image x axis for the prior's head, see
:mod:`domplane_ros.core.parallax`) that aligns the warped right image with the left one.
Points on the plane have none; a point off the plane has parallax that grows with its height
above the plane and falls with its distance. The shift is a dense one-step, one-dimensional
Lucas-Kanade estimate at zero shift (box-filtered gradient products, gain and offset removed
by the local means, regularised so that windows without texture across the epipolar direction
fall back to zero), trusted up to one pixel at the working scale where the zero-shift
normalised correlation (NCC) also holds; beyond that a clearly failed NCC says the pixel is off
the plane without measuring by how much.

Three labels with a physical meaning:

* :data:`PLANE` (255): measured residual parallax below ``config.parallax_threshold_px``
  (full-resolution pixels), where an obstacle of ``config.min_obstacle_height`` (relative to
  the camera height) would have shown at least that much;
* :data:`OBSTACLE` (127): residual parallax at or above the threshold, from a point nearer than
  infinity, below the horizon; or, where such an obstacle would show, a textured window whose
  zero-shift NCC clearly fails;
* :data:`UNKNOWN` (0): everything else: no texture, outside the right image, at or above the
  plane's horizon (sky, far walls: no ground there to compare with), and far or
  small-baseline views where an obstacle of the minimum height would not produce measurable
  parallax.

Obstacles are cleaned by a small opening and closing, plane gaps by a closing; unknown
low-texture regions whose outline inside the right image is (almost) all plane, the plain
interior of a tile, are filled as plane. The residual parallax itself is returned beside the
labels.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import cv2
from domplane_ros.config import MaskConfig
from domplane_ros.core.homography import as_valid_homography, resize_homography
from domplane_ros.core.image import check_gray
from domplane_ros.core.occlusion import occlusion_shadow
from domplane_ros.core.parallax import height_factor, infinity_shift
import numpy as np

PLANE = 255
OBSTACLE = 127
UNKNOWN = 0
# Value of the parallax image where the residual parallax was not measured.
NOT_MEASURED = -1.0
# Default focal range (the default prior's) for the plane-at-infinity fit.
DEFAULT_FOCAL_PX = (400.0, 900.0)

# The one-step estimate is linear in the shift up to about a pixel at the working scale.
_LINEAR_RANGE_PX = 1.0
# Zero-shift NCC below which a textured window is off the plane without a measured parallax.
_REJECT_NCC = 0.5
# Where an obstacle of the minimum height would not show, an obstacle needs this many times
# the parallax threshold (the coarse flow is not trusted near it there).
_FAR_FACTOR = 3.0
# Regulariser of the one-step estimate, grey levels^2 per pixel^2 (windows without texture
# across the epipolar direction fall back to zero shift).
_REGULARISER = 2.0
# An unknown region is filled as plane when at least this share of its outline inside the
# right image is plane, and that outline has at least this many pixels.
_FILL_OUTLINE_SHARE = 0.95
_FILL_MIN_OUTLINE = 4
# A pixel is inside the right image when it maps this many working pixels inside its border,
# so that every full-resolution pixel a working pixel covers maps inside too.
_INSIDE_MARGIN_PX = 1.0
_SQUARE_3 = np.ones((3, 3), np.uint8)
# DIS settings over the ultrafast preset (see _dis_flow).
_DIS_FINEST_SCALE = 1
_DIS_PATCH_STRIDE = 8
# Working images smaller than twice this (pixels) get DIS at their own size, smaller than
# it none.
_DIS_MIN_SIZE = 32
# Translucency of the overlay tint.
_TINT_ALPHA = 0.35
# Colours of :func:`overlay` (RGB); core/legend.py names them.
PLANE_RGB = (0, 255, 0)
OBSTACLE_RGB = (255, 0, 0)
INLIER_RGB = (0, 255, 255)
OUTLIER_RGB = (255, 0, 255)


@dataclass(frozen=True)
class ParallaxMask:
    """The mask of one pair and the residual parallax it was decided on.

    Attributes:
        labels: (H, W) uint8 left-image labels: 255 plane, 127 obstacle, 0 unknown.
        parallax: (h, w) float32 residual parallax magnitude at the mask's working scale,
            in full-resolution pixels; :data:`NOT_MEASURED` (-1) where it was not measured
            (no texture, outside the right image, or too large for the one-step estimate).
    """

    labels: np.ndarray
    parallax: np.ndarray

    def parallax_image(self) -> np.ndarray:
        """Return the (H, W) float32 parallax at the left image's size (nearest neighbour)."""
        height, width = self.labels.shape
        if self.parallax.shape == (height, width):
            return self.parallax
        return cv2.resize(self.parallax, (width, height), interpolation=cv2.INTER_NEAREST)


def _resize(image: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the image resized by ``scale`` (at least 1 x 1) and the (3, 3) pixel map."""
    height, width = image.shape
    new_w, new_h = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    if (new_w, new_h) == (width, height):
        return image, np.eye(3)
    small = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_AREA)
    return small, resize_homography(new_w / width, new_h / height)


def _fill_enclosed(labels: np.ndarray, fillable: np.ndarray, valid: np.ndarray) -> None:
    """Label as plane, in place, fillable regions whose outline is (almost) all plane.

    Only the outline inside the right image counts (the image border and pixels the right
    camera does not see neither support nor oppose the fill), and it must have at least
    :data:`_FILL_MIN_OUTLINE` pixels. The regions are found on every second pixel (plain
    regions worth filling are large), and only fillable pixels change.

    Args:
        labels: (h, w) uint8 labels, changed in place.
        fillable: (h, w) bool, unknown pixels that may become plane.
        valid: (h, w) bool, pixels inside the right image.

    """
    coarse = fillable[::2, ::2].astype(np.uint8)
    count, components = cv2.connectedComponents(coarse, connectivity=4)
    if count <= 1 or count >= 65535:
        return
    # Each outline pixel (next to a component, not in one) votes for the largest and the
    # smallest neighbouring component id (both, when it lies between two components).
    ids = components.astype(np.uint16)
    square = np.ones((3, 3), np.uint8)
    largest = cv2.dilate(ids, square)
    ids[ids == 0] = 65535
    smallest = cv2.erode(ids, square)
    outline = (largest > 0) & (components == 0) & valid[::2, ::2]
    is_plane = labels[::2, ::2][outline] == PLANE
    first = largest[outline].astype(np.int64)
    second = smallest[outline].astype(np.int64)
    second[second == first] = 0  # one vote per component
    second[second == 65535] = 0
    total = np.bincount(first, minlength=count) + np.bincount(second, minlength=count)
    plane = (np.bincount(first, weights=is_plane, minlength=count)
             + np.bincount(second, weights=is_plane, minlength=count))
    fill = (plane >= _FILL_OUTLINE_SHARE * total) & (total >= _FILL_MIN_OUTLINE)
    fill[0] = False
    if not fill.any():
        return
    chosen = fill[components].astype(np.uint8)
    height, width = labels.shape
    chosen = cv2.resize(chosen, (2 * chosen.shape[1], 2 * chosen.shape[0]),
                        interpolation=cv2.INTER_NEAREST)[:height, :width]
    labels[(chosen == 1) & fillable] = PLANE


def _check_focal(focal_px: tuple[float, float]) -> tuple[float, float]:
    """Return the focal range as floats; ValueError unless 0 < min <= max, finite."""
    try:
        low, high = (float(v) for v in focal_px)
    except (TypeError, ValueError) as err:
        raise ValueError(f'focal_px must be two numbers (min, max), got {focal_px!r}') from err
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 < low <= high):
        raise ValueError(f'focal_px must be finite with 0 < min <= max, got {focal_px!r}')
    return low, high


def parallax_mask(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                  config: MaskConfig, focal_px: tuple[float, float] = DEFAULT_FOCAL_PX,
                  principal_point_px: Sequence[float] = ()) -> ParallaxMask:
    """Label every left pixel plane, obstacle or unknown by its residual parallax.

    See the module docstring for the measurement and the labels. Works at ``config.scale``:
    the right image is warped into the left view with ``S_r H S_l^-1``, the labels are
    upsampled to the left image's size by nearest neighbour.

    Args:
        left: (H, W) uint8 left image.
        right: (H', W') uint8 right image; its size may differ from the left image's.
        homography: (3, 3) float plane homography mapping left pixels to right pixels.
        config: Mask settings.
        focal_px: (min, max) focal length range of the prior (``prior.focal_px``), for the
            plane at infinity (:mod:`domplane_ros.core.parallax`).
        principal_point_px: The prior's principal point (``prior.principal_point_px``), or
            empty for the image centre.

    Returns:
        The :class:`ParallaxMask`: labels (H, W) uint8 and the residual parallax at the
        working scale.

    Raises:
        ValueError: If an image is not a non-empty 2-D uint8 array, the homography is not a
            finite, non-singular (3, 3) matrix, or the focal range is not positive.

    """
    left = check_gray(left, 'left')
    right = check_gray(right, 'right')
    hom = as_valid_homography(homography)
    focal = _check_focal(focal_px)
    height, width = left.shape
    left_small, scale_left = _resize(left, config.scale)
    right_small, scale_right = _resize(right, config.scale)
    small_h, small_w = left_small.shape
    hom_small = scale_right @ hom @ np.linalg.inv(scale_left)
    if not np.all(np.isfinite(hom_small)):
        raise ValueError('homography is not invertible at mask scale')
    warped, valid = _warp_to_left(left_small, right_small, hom_small, (small_w, small_h))
    fit = _local_fit(left_small, warped, int(config.window_px))
    # Full-resolution pixels per working pixel along x (the epipolar direction).
    px_per_working = width / small_w
    # The camera model has one calibration for both cameras: a right image of another size
    # is brought to the left image's size first.
    right_h, right_w = right.shape
    same_size = resize_homography(width / right_w, height / right_h) @ hom
    shift_inf = infinity_shift(same_size, width, height, focal, (small_w, small_h),
                               principal_point_px)
    labels, parallax, decidable = _classify(fit, valid, shift_inf, px_per_working, config)
    _clean(labels, valid, decidable, int(config.morph_px))
    hidden = occlusion_shadow(left_small, warped, labels == OBSTACLE)
    labels[hidden] = UNKNOWN
    parallax[hidden] = NOT_MEASURED
    _fill_enclosed(labels, (labels == UNKNOWN) & valid & decidable, valid)
    if (small_h, small_w) != (height, width):
        labels = cv2.resize(labels, (width, height), interpolation=cv2.INTER_NEAREST_EXACT)
    return ParallaxMask(labels=labels, parallax=parallax)


def plane_mask(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
               config: MaskConfig, focal_px: tuple[float, float] = DEFAULT_FOCAL_PX
               ) -> np.ndarray:
    """Return only the (H, W) uint8 labels of :func:`parallax_mask` (same arguments)."""
    return parallax_mask(left, right, homography, config, focal_px).labels


def _warp_to_left(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                  size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Return the right image warped into the left view, and the (h, w) bool valid pixels.

    A pixel is valid when it and its 8 neighbours map inside the right image (the right
    image's outline mapped into the left view: a convex quadrilateral when no corner crosses
    the line at infinity; otherwise the footprint is warped pixel by pixel), the pixel itself
    :data:`_INSIDE_MARGIN_PX` inside. Outside the footprint the warped image is the left image,
    so a window reaching past the footprint's edge is judged on its pixels inside (the rest
    agree exactly) instead of on a black border; the left image's own border needs nothing:
    the window statistics reflect both images there alike.
    """
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    warped = cv2.warpPerspective(right, homography, size, flags=flags,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    footprint = _inside(right.shape, homography, size, 0.0)
    cv2.copyTo(left, cv2.bitwise_not(footprint), warped)
    valid = cv2.erode(footprint, _SQUARE_3, borderType=cv2.BORDER_CONSTANT,
                      borderValue=255) == 255
    valid &= _inside(right.shape, homography, size, _INSIDE_MARGIN_PX) == 255
    return warped, valid


def _inside(right_shape: tuple[int, int], homography: np.ndarray, size: tuple[int, int],
            margin: float) -> np.ndarray:
    """Return the (h, w) uint8 mask (255) of left pixels mapped inside the right image.

    The right image's outline is taken ``margin`` pixels inside its border.
    """
    height, width = right_shape
    low, high_x, high_y = margin, width - 1.0 - margin, height - 1.0 - margin
    if high_x < low or high_y < low:
        return np.zeros((size[1], size[0]), np.uint8)
    corners = np.array([[low, low, 1.0], [high_x, low, 1.0], [high_x, high_y, 1.0],
                        [low, high_y, 1.0]])
    mapped = np.linalg.solve(homography, corners.T).T
    if np.all(mapped[:, 2] > 1e-9):
        quad = mapped[:, :2] / mapped[:, 2:]
        if np.all(np.abs(quad) < 1e6):
            inside = np.zeros((size[1], size[0]), np.uint8)
            cv2.fillConvexPoly(inside, np.round(quad * 16).astype(np.int32), 255,
                               lineType=cv2.LINE_8, shift=4)
            return inside
    footprint = np.zeros(right_shape, np.uint8)
    footprint[int(math.ceil(low)):int(high_y) + 1, int(math.ceil(low)):int(high_x) + 1] = 255
    return cv2.warpPerspective(footprint, homography, size,
                               flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=0)


@dataclass(frozen=True)
class _LocalFit:
    """Per-pixel window statistics of the left and warped right images (working scale).

    Attributes:
        shift: (h, w) float32 signed one-step residual parallax, working pixels (positive:
            nearer than the plane).
        ncc: (h, w) float32 zero-shift normalised correlation.
        variance: (h, w) float32 grey-level variance of the left window.
        flow_shift: (h, w) float32 signed residual parallax from DIS optical flow, working
            pixels: coarse, but not limited to small shifts.
    """

    shift: np.ndarray
    ncc: np.ndarray
    variance: np.ndarray
    flow_shift: np.ndarray


def _dis_flow() -> cv2.DISOpticalFlow:
    """Return a new DIS optical flow object (ultrafast preset, finest scale 1, stride 8).

    The preset's finest scale 2 leaves one flow vector per 16 working pixels at the half
    size it runs on: tall near objects (poles, boxes) then drag the ground's flow by several
    pixels (median 3.3 working pixels on rendered seed 3's floor). Finest scale 1 with
    non-overlapping 8-pixel patches measures the ground within 0.1-0.2 px in the median for
    about 0.1 ms more at 640x480.

    A new one per call (creating it costs microseconds): a reused object keeps state between
    calls on small images, so the same pair would not always give the same mask.
    """
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
    flow.setFinestScale(_DIS_FINEST_SCALE)
    flow.setPatchStride(_DIS_PATCH_STRIDE)
    return flow


def _local_fit(left: np.ndarray, warped: np.ndarray, window: int) -> _LocalFit:
    """Return the one-step 1-D Lucas-Kanade shift and the zero-shift NCC of every window.

    With ``g`` the mean x gradient of both images and ``e`` the difference of the two
    images after removing each window's mean, the shift that aligns them is
    ``sum(g e) / (sum(g^2) + regulariser)`` (Gauss-Newton from zero shift).
    """
    a = left.astype(np.float32)
    b = warped.astype(np.float32)
    size = (window, window)
    mean_a = cv2.blur(a, size)
    mean_b = cv2.blur(b, size)
    var_a = cv2.blur(a * a, size) - mean_a * mean_a
    var_b = cv2.blur(b * b, size) - mean_b * mean_b
    cov = cv2.blur(a * b, size) - mean_a * mean_b
    ncc = cov / np.sqrt(np.maximum(var_a * var_b, 1e-6))
    grad = cv2.Sobel(a, cv2.CV_32F, 1, 0, ksize=3, scale=0.0625)
    grad += cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3, scale=0.0625)
    diff = (b - mean_b) - (a - mean_a)
    num = cv2.blur(grad * diff, size)
    den = cv2.blur(grad * grad, size)
    shift = num / (den + np.float32(_REGULARISER))
    return _LocalFit(shift=shift, ncc=ncc, variance=var_a, flow_shift=_flow_shift(left, warped))


def _flow_shift(left: np.ndarray, warped: np.ndarray) -> np.ndarray:
    """Return the signed x shift (working pixels) of DIS optical flow at half the working size.

    Only large parallax is read from it, so half the resolution serves and costs a quarter.
    """
    height, width = left.shape
    if min(height, width) < _DIS_MIN_SIZE:
        return np.zeros(left.shape, np.float32)  # too small for a pyramid: no coarse flow
    if min(height, width) < 2 * _DIS_MIN_SIZE:
        flow = _dis_flow().calc(left, warped, None)
        return -flow[..., 0]
    half_left, half_warped = cv2.pyrDown(left), cv2.pyrDown(warped)
    flow = _dis_flow().calc(half_left, half_warped, None)[..., 0]
    return cv2.resize(flow, (width, height), interpolation=cv2.INTER_LINEAR) * np.float32(-2.0)


def _classify(fit: _LocalFit, valid: np.ndarray, shift_inf: np.ndarray,
              px_per_working: float, config: MaskConfig
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the working-scale labels, the parallax image and the decidable pixels.

    Decidable pixels are those where an obstacle of ``config.min_obstacle_height`` would show
    at least ``config.parallax_threshold_px`` of residual parallax.
    """
    threshold = float(config.parallax_threshold_px)
    measurable = valid & (fit.variance >= float(config.min_texture) ** 2)
    small = measurable & (np.abs(fit.shift) < _LINEAR_RANGE_PX)
    small &= fit.ncc >= float(config.ncc_threshold)
    residual = np.where(small, fit.shift, fit.flow_shift)
    residual *= np.float32(px_per_working)
    magnitude = np.abs(residual)
    # kappa * shift_inf is the parallax an obstacle of the minimum height would show.
    decidable = shift_inf >= threshold / height_factor(float(config.min_obstacle_height))
    plane = small & (magnitude < threshold)
    labels = (plane & decidable).view(np.uint8) * np.uint8(PLANE)
    # Off the plane: a measured parallax at or above the threshold, or a clear zero-shift
    # mismatch. An obstacle is nearer than infinity by the threshold and below the horizon;
    # where an obstacle of the minimum height would not show, only a clearly larger parallax
    # (the coarse flow is not trusted near the threshold there) counts. A point farther than
    # the plane but nearer than infinity (a hole in the ground) is an obstacle too.
    off = (magnitude >= threshold) | (fit.ncc < _REJECT_NCC)
    off &= measurable & ~plane & (shift_inf > 0)
    off &= decidable | (residual >= _FAR_FACTOR * threshold)
    residual += shift_inf
    off &= residual >= threshold
    labels[off] = OBSTACLE
    magnitude[~measurable] = NOT_MEASURED
    return labels, magnitude, decidable


def _clean(labels: np.ndarray, valid: np.ndarray, decidable: np.ndarray, morph: int) -> None:
    """Clean the labels in place with a ``morph`` square (< 2: no-op).

    Obstacles are opened (specks become unknown) and closed (gaps inside an obstacle, plane or
    unknown, become obstacle); the plane is only closed, and only over unknown decidable
    pixels, so thin plane evidence such as tile joints survives for the fill.
    """
    if morph < 2:
        return
    square = np.ones((morph, morph), np.uint8)
    region = (labels == OBSTACLE).astype(np.uint8)
    cleaned = cv2.morphologyEx(region, cv2.MORPH_OPEN, square)
    cleaned = cv2.morphologyEx(cleaned, cv2.MORPH_CLOSE, square)
    labels[(region == 1) & (cleaned == 0)] = UNKNOWN
    labels[(cleaned == 1) & (region == 0) & valid] = OBSTACLE
    region = (labels == PLANE).astype(np.uint8)
    closed = cv2.morphologyEx(region, cv2.MORPH_CLOSE, square)
    labels[(closed == 1) & (labels == UNKNOWN) & valid & decidable] = PLANE


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
