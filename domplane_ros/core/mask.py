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
normalised correlation (NCC) also holds, unless the coarse DIS flow puts the shift beyond that
range and the window matches better at the flow's shift; beyond that a clearly failed NCC says
the pixel is off the plane without measuring by how much.

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
interior of a tile, are filled as plane, and so are those whose outline is mostly plane
(a plain tile beside a box's bottom) when the coarse flow inside them is flat: a plain
obstacle face carries its edges' parallax. The residual parallax itself is returned beside the
labels. Rows wholly above the horizon (less a margin) are unknown without being measured:
no pixel there could be plane or obstacle, and the labels equal those of measuring them.

Each pixel's own decision, the measurement and the classification of its residual parallax
with the switches ``_NOISE_AWARE`` and ``_MEASUREMENT`` (not the default), is
:mod:`domplane_ros.core.pixel_decision`'s; this module, the public entry, warps and cuts the
images, cleans the labels up, hides the floor the right camera cannot see, fills, upsamples,
draws the :func:`overlay` and gives the :func:`mask_scores`. The label values and
:data:`NOT_MEASURED` are defined in :mod:`domplane_ros.core.pixel_decision`; import them
from here, with the rest of the public API.
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
from domplane_ros.core.parallax import infinity_shift
from domplane_ros.core.pixel_decision import (decide_pixels, NOT_MEASURED, OBSTACLE, PLANE,
                                              set_where, UNKNOWN)
from domplane_ros.core.residual import flow_shift
import numpy as np

# The public names, the label values and NOT_MEASURED among them (from pixel_decision).
__all__ = ['DEFAULT_FOCAL_PX', 'INLIER_RGB', 'mask_scores', 'NOT_MEASURED', 'OBSTACLE',
           'OBSTACLE_RGB', 'OUTLIER_RGB', 'overlay', 'parallax_mask', 'ParallaxMask', 'PLANE',
           'PLANE_RGB', 'plane_mask', 'UNKNOWN']

# Default focal range (the default prior's) for the plane-at-infinity fit.
DEFAULT_FOCAL_PX = (400.0, 900.0)

# An obstacle at most this many working rows above a rising plane pixel in its column
# (pixel_decision.PixelDecision.rising) makes it unknown (docs/MASK.md round 4).
_RISE_ROWS = 8
# An unknown region is filled as plane when at least this share of its outline inside the
# right image is plane, and that outline has at least this many pixels.
_FILL_OUTLINE_SHARE = 0.95
_FILL_MIN_OUTLINE = 4
# Or when at least _FILL_FLAT_SHARE of it is plane and the coarse flow inside it is below
# the parallax threshold on all but _FILL_MOVED_SHARE of it (docs/MASK.md round 7: chosen
# with plain box faces in the tuning scenes).
_FILL_FLAT_SHARE = 0.85
_FILL_MOVED_SHARE = 0.1
# The regions are found on every second pixel: a plain fillable pixel whose own sample is not
# fillable (a region's edge between the samples) is filled when a filled pixel lies within
# this many pixels (docs/MASK.md round 13; 0: not at all).
_FILL_EDGE_PX = 1
# A pixel is inside the right image when it maps this many working pixels inside its border,
# so that every full-resolution pixel a working pixel covers maps inside too.
_INSIDE_MARGIN_PX = 1.0
_SQUARE_3 = np.ones((3, 3), np.uint8)
# Rows kept above the first row below the horizon (working pixels; see _first_row): the
# occlusion band's margin, the widest reach of the steps.
_CUT_MARGIN_PX = 16
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
            (no texture, outside the right image, floor hidden from the right camera, rows
            wholly above the plane's horizon).
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


def _fill_enclosed(labels: np.ndarray, fillable: np.ndarray, valid: np.ndarray,
                   flat: tuple[np.ndarray, float] | None = None,
                   plain: np.ndarray | None = None) -> None:
    """Label as plane, in place, fillable regions whose outline is (almost) all plane.

    Only the outline inside the right image counts (the image border and pixels the right
    camera does not see neither support nor oppose the fill), and it must have at least
    :data:`_FILL_MIN_OUTLINE` pixels. The regions are found on every second pixel (plain
    regions worth filling are large), and only fillable pixels change; a plain fillable pixel
    whose own sample (the even row and column at or before it) is not fillable, the edge of
    a region that the samples miss, is filled when a filled pixel lies within
    :data:`_FILL_EDGE_PX` (docs/MASK.md round 13: a line one pixel wide along many filled
    tiles' edges). A region whose outline
    is at least :data:`_FILL_FLAT_SHARE` plane (a plain tile beside a box's bottom) is filled
    too when the coarse flow inside it stays below the threshold on all but
    :data:`_FILL_MOVED_SHARE` of it: the flow fills an untextured region from its edges, so
    a plain obstacle face carries its edges' parallax and a plain floor tile none.

    Args:
        labels: (h, w) uint8 labels, changed in place.
        fillable: (h, w) bool, unknown pixels that may become plane.
        valid: (h, w) bool, pixels inside the right image.
        flat: ``(flow, threshold)``: the (ceil(h/2), ceil(w/2)) float32 coarse flow at every
            second pixel and the threshold in its units, or None for the outline rule only.
        plain: (h, w) bool pixels without texture (:class:`PixelDecision`'s ``plain``): only
            they are filled from a filled neighbour; None: every fillable pixel is.

    """
    coarse = fillable[::2, ::2].astype(np.uint8)
    # 16-bit ids straight away where no more than 65535 components fit (4-connected: at
    # most one per two pixels and the background).
    ltype = cv2.CV_16U if coarse.size <= 2 * 65534 else cv2.CV_32S
    count, components = cv2.connectedComponents(coarse, connectivity=4, ltype=ltype)
    if count <= 1 or count >= 65535:
        return
    components = components.astype(np.uint16, copy=False)
    # Each outline pixel (next to a component, not in one) votes for the largest and the
    # smallest neighbouring component id (both, when it lies between two components).
    square = np.ones((3, 3), np.uint8)
    largest = cv2.dilate(components, square)
    # The smallest id by an erosion of id - 1, where 0 (no component) wraps to 65535.
    smallest = cv2.erode(components - np.uint16(1), square)
    smallest += np.uint16(1)
    outline = np.flatnonzero((largest > 0) & (components == 0) & valid[::2, ::2])
    is_plane = np.ascontiguousarray(labels[::2, ::2]).ravel()[outline] == PLANE
    first = largest.ravel()[outline].astype(np.int64)
    second = smallest.ravel()[outline].astype(np.int64)
    second[second == first] = 0  # one vote per component
    total = np.bincount(first, minlength=count) + np.bincount(second, minlength=count)
    plane = (np.bincount(first, weights=is_plane, minlength=count)
             + np.bincount(second, weights=is_plane, minlength=count))
    fill = (plane >= _FILL_OUTLINE_SHARE * total) & (total >= _FILL_MIN_OUTLINE)
    if flat is not None:
        fill |= _flat_inside(components, count, flat) & (plane >= _FILL_FLAT_SHARE * total) \
            & (total >= _FILL_MIN_OUTLINE)
    fill[0] = False
    if not fill.any():
        return
    if count <= 256:  # a table lookup on bytes, ten times faster than fancy indexing
        table = np.zeros(256, np.uint8)
        table[:count] = fill
        chosen = cv2.LUT(components.astype(np.uint8), table)
    else:
        chosen = fill.view(np.uint8)[components]
    height, width = labels.shape
    size = (2 * chosen.shape[1], 2 * chosen.shape[0])
    filled = _upsample(chosen, size)[:height, :width].view(bool) & fillable
    set_where(labels, PLANE, filled)
    if _FILL_EDGE_PX > 0:  # the edges the samples miss, next to a filled pixel
        missed = fillable & ~_upsample(coarse, size)[:height, :width].view(bool)
        if plain is not None:
            missed &= plain
        reach = np.ones((2 * _FILL_EDGE_PX + 1, 2 * _FILL_EDGE_PX + 1), np.uint8)
        missed &= cv2.dilate(filled.view(np.uint8), reach).view(bool)
        set_where(labels, PLANE, missed)


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
    small_h, small_w = left_small.shape
    # The camera model has one calibration for both cameras: a right image of another size
    # is brought to the left image's size first.
    right_h, right_w = right.shape
    same_size = resize_homography(width / right_w, height / right_h) @ hom
    shift_inf = infinity_shift(same_size, width, height, focal, (small_w, small_h),
                               principal_point_px)
    top = _first_row(shift_inf)
    if top is None or top > 0:
        labels = np.zeros((small_h, small_w), np.uint8)
        parallax = np.full((small_h, small_w), NOT_MEASURED, np.float32)
    if top is not None:
        right_small, scale_right = _resize(right, config.scale)
        hom_small = scale_right @ hom @ np.linalg.inv(scale_left)
        if not np.all(np.isfinite(hom_small)):
            raise ValueError('homography is not invertible at mask scale')
        warped, valid = _warp_to_left(left_small, right_small, hom_small, (small_w, small_h))
        halves = cv2.pyrDown(left_small), cv2.pyrDown(warped)
        # The coarse flow on the whole images (it is global: a cut would change it).
        coarse = flow_shift(left_small, warped, halves)
        rows = slice(top, small_h)
        cut = _label_rows(left_small[rows], warped[rows], valid[rows], coarse[rows],
                          shift_inf[rows], width / small_w, config,
                          (halves[0][top // 2:], halves[1][top // 2:]))
        if top == 0:
            labels, parallax = cut
        else:
            labels[rows], parallax[rows] = cut
    if (small_h, small_w) != (height, width):
        labels = _upsample(labels, (width, height))
    return ParallaxMask(labels=labels, parallax=parallax)


def _first_row(shift_inf: np.ndarray) -> int | None:
    """Return the first working row the mask needs, or None when no pixel is below the horizon.

    At and above the plane's horizon (``shift_inf <= 0``) no pixel can be plane or obstacle
    (:func:`~domplane_ros.core.pixel_decision.decide_pixels`), so rows wholly above it are
    unknown and not measured. The cut keeps :data:`_CUT_MARGIN_PX` rows above the first row
    below the horizon (the windows, the clean-up and the occlusion band reach that far) and
    starts on a multiple of it.
    """
    below = (shift_inf > 0).ravel()
    first = int(np.argmax(below))  # the first pixel below the horizon, 0 if there is none
    if not below[first]:
        return None
    row = first // shift_inf.shape[1]
    return max(0, row - _CUT_MARGIN_PX) // _CUT_MARGIN_PX * _CUT_MARGIN_PX


def _flat_inside(components: np.ndarray, count: int, flat: tuple[np.ndarray, float]
                 ) -> np.ndarray:
    """Return (count,) bool: the flow is below the threshold on nearly all of a component."""
    flow, threshold = flat
    ids = components.ravel()
    inside = np.flatnonzero(ids)
    ids = ids[inside].astype(np.int64)
    size = np.bincount(ids, minlength=count)
    moved = np.bincount(ids, weights=np.abs(flow).ravel()[inside] >= np.float32(threshold),
                        minlength=count)
    return moved <= _FILL_MOVED_SHARE * size


def _label_rows(left: np.ndarray, warped: np.ndarray, valid: np.ndarray, coarse: np.ndarray,
                shift_inf: np.ndarray, px_per_working: float, config: MaskConfig,
                halves: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Return the working-scale labels and parallax of the rows of ``left``.

    Each pixel's decision (:func:`~domplane_ros.core.pixel_decision.decide_pixels`), then
    what pixels decide together: the clean-up, plane rising into an obstacle made unknown,
    the floor hidden from the right camera, the fill of plain regions.

    Args:
        left: (h, w) uint8 left image at the working scale (the rows the mask needs).
        warped: (h, w) uint8 right image warped into the left view, the same rows.
        valid: (h, w) bool pixels inside the right image.
        coarse: (h, w) float32 coarse residual parallax (:func:`flow_shift`), working pixels.
        shift_inf: (h, w) float32 ground disparity relative to infinity, full pixels.
        px_per_working: Full-resolution pixels per working pixel along x.
        config: Mask settings.
        halves: ``cv2.pyrDown`` of ``left`` and ``warped`` (from the whole images).

    Returns:
        (h, w) uint8 labels and (h, w) float32 parallax (:class:`ParallaxMask`).

    """
    flow = coarse[::2, ::2].copy()  # the fill's; ``coarse`` is a scratch array
    decision = decide_pixels(left, warped, valid, coarse, shift_inf, px_per_working, config)
    labels, parallax = decision.labels, decision.parallax
    _clean(labels, valid, decision.decidable, int(config.morph_px))
    _unknown_below_obstacles(labels, decision.rising)
    hidden = occlusion_shadow(left, warped, labels == OBSTACLE, halves)
    set_where(labels, UNKNOWN, hidden)
    set_where(parallax, NOT_MEASURED, hidden)
    _fill_enclosed(labels, (labels == UNKNOWN) & valid & decision.decidable, valid,
                   (flow, float(config.parallax_threshold_px) / px_per_working), decision.plain)
    return labels, parallax


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


def _clean(labels: np.ndarray, valid: np.ndarray, decidable: np.ndarray, morph: int) -> None:
    """Clean the labels in place with a ``morph`` square (< 2: no-op).

    Obstacles are opened (specks become unknown) and closed (gaps inside an obstacle, plane or
    unknown, become obstacle); the plane is only closed, and only over unknown decidable
    pixels, so thin plane evidence such as tile joints survives for the fill.
    """
    if morph < 2:
        return
    square = np.ones((morph, morph), np.uint8)
    region = labels == OBSTACLE
    cleaned = cv2.morphologyEx(region.view(np.uint8), cv2.MORPH_OPEN, square)
    cleaned = cv2.morphologyEx(cleaned, cv2.MORPH_CLOSE, square, dst=cleaned).view(bool)
    set_where(labels, UNKNOWN, region & ~cleaned)
    set_where(labels, OBSTACLE, cleaned & ~region & valid)
    closed = cv2.morphologyEx((labels == PLANE).view(np.uint8), cv2.MORPH_CLOSE,
                              square).view(bool)
    set_where(labels, PLANE, closed & (labels == UNKNOWN) & valid & decidable)


def _unknown_below_obstacles(labels: np.ndarray, rising: np.ndarray) -> None:
    """Label unknown, in place, plane pixels that rise into an obstacle just above them.

    The bottom of a wall or a box below the minimum height shows less parallax than the
    threshold, so it measures as plane; but its parallax is positive (nearer than the plane)
    and grows up to the obstacle above, while the ground's is zero up to noise. A plane pixel
    whose measured parallax is at least a share of the threshold (``rising``, (h, w) bool,
    :class:`~domplane_ros.core.pixel_decision.PixelDecision`) with an obstacle at most
    :data:`_RISE_ROWS` rows above it in its column cannot be told from that bottom: it becomes
    unknown.
    """
    if not rising.any():
        return
    column = np.ones((_RISE_ROWS + 1, 1), np.uint8)
    # Dilated downwards: pixel y sees the obstacles in rows y - _RISE_ROWS .. y.
    below = cv2.dilate((labels == OBSTACLE).view(np.uint8), column, anchor=(0, _RISE_ROWS))
    set_where(labels, UNKNOWN, rising & below.view(bool) & (labels == PLANE))


def _upsample(labels: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Return the (h, w) uint8 labels at ``size`` ``(W, H)`` by nearest neighbour.

    Exactly twice the size (the default ``mask.scale``) repeats every byte as a 16-bit
    word and every row: the same as ``cv2.INTER_NEAREST_EXACT`` in a fifth of the time.
    """
    height, width = labels.shape
    if size != (2 * width, 2 * height):
        return cv2.resize(labels, size, interpolation=cv2.INTER_NEAREST_EXACT)
    words = labels.astype(np.uint16)
    words *= np.uint16(257)
    out = np.empty((height, 2, width), np.uint16)
    out[:, 0] = words
    out[:, 1] = words
    return out.view(np.uint8).reshape(2 * height, 2 * width)


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
