"""Floor hidden from the right camera by an obstacle: the occlusion shadow along the epipolar line.

After the plane warp (:mod:`domplane_ros.core.mask`), a point off the plane at left pixel
``x'`` with residual parallax ``r'`` (positive: nearer than the plane) shows in the warped
right image at ``x' - r'`` (the epipolar direction is the image x axis for the prior's head,
:mod:`domplane_ros.core.parallax`). A floor pixel ``x`` to its left (``x < x'``) has no
residual parallax if the right camera sees it, so it is hidden when ``x' - r' <= x``: the
obstacle covers it in the right image. Its window then mismatches the warped image at every
shift, and the zero-shift test alone would call it an obstacle.

:func:`occlusion_shadow` predicts that shadow from the obstacles' parallax and returns the
pixels in it that are not part of the occluding obstacle. The obstacles' large parallax comes
from OpenCV's block matcher (``cv2.StereoBM``) on the left and warped images at half the
mask's working size, with its left-right consistency check, so that only obstacle pixels the
right camera sees, with a parallax consistent both ways, cast a shadow. The matcher leaves
holes on the obstacles themselves (slanted faces, weak texture), and an obstacle pixel it
missed is in the shadow of its own neighbours on the right; it stays an obstacle when it
lies just right of a consistent obstacle pixel, when its window matches the warped image at
the parallax of the next occluder on its right (the same face), or when it does not continue
the floor on its left (the constants below say by how much).

Measured on the 30 tuning scenes (``tools/evaluate_mask.py``, docs/MASK.md): hidden floor
marked unknown 9 % -> 31 % (median) at the same obstacle recall (0.914).
"""

from __future__ import annotations

import cv2
import numpy as np

# Everything below runs at half the mask's working size ("half pixels"); the distances are
# given in working pixels and halved there.
# Block matcher: disparities 0 .. _DISPARITIES - 1 half pixels, square block of _BLOCK_PX half
# pixels, left-right check within _LEFT_RIGHT_PX half pixels.
_DISPARITIES = 32
_BLOCK_PX = 7
_LEFT_RIGHT_PX = 1
# An occluder is an obstacle pixel with a consistent parallax of at least this many working
# pixels.
_MIN_OCCLUDER_PX = 2.0
# The predicted shadow reaches this many working pixels further left (the matcher's parallax
# at an occluding edge is low by about that).
_SLACK_PX = 4.0
# A shadow pixel is part of an obstacle, not hidden floor, when it lies within
# _SURFACE_GAP_PX working pixels right of an occluder; when its _WINDOW_PX window (half
# pixels; a 5-pixel window matched independent smooth textures at 0.7 by chance) matches the
# warped image at the parallax of the next occluder on its right with a correlation of at
# least _SAME_SURFACE_NCC; when more than _LEAD_PX obstacle pixels outside the shadow lie
# between it and the last non-obstacle pixel on its left (hidden floor continues the floor);
# or when it is one of the last _EDGE_TRIM_PX pixels before the occluding edge (a window
# reaching over the edge matches nowhere, on the edge as on the floor). The settings were
# chosen on the tuning scenes; _EDGE_TRIM_PX is the smallest trim that keeps their obstacle
# recall at that of the mask without the shadow (docs/MASK.md).
_SURFACE_GAP_PX = 8
_SAME_SURFACE_NCC = 0.7
_LEAD_PX = 8
_WINDOW_PX = 7
_EDGE_TRIM_PX = 4
# Rows (working pixels) the matcher's band reaches beyond the obstacles: the half-size pixels
# it decides depend on 8 half rows around them (pyrDown 1, the pre-filter 4, the block 3).
_BAND_MARGIN_PX = 16


def block_parallax(left: np.ndarray, warped: np.ndarray) -> np.ndarray | None:
    """Return the left-right consistent parallax of the block matcher, in 1/16 pixels.

    Args:
        left: (h, w) uint8 left image (here: at half the mask's working size).
        warped: (h, w) uint8 right image warped into the left view.

    Returns:
        (h, w) int16 parallax times 16 (positive: nearer than the plane), negative where the
        matcher found none; None when the images are too small for it.

    """
    if min(left.shape) < 2 * _BLOCK_PX or left.shape[1] <= _DISPARITIES + _BLOCK_PX:
        return None
    matcher = cv2.StereoBM_create(numDisparities=_DISPARITIES, blockSize=_BLOCK_PX)
    matcher.setDisp12MaxDiff(_LEFT_RIGHT_PX)
    return matcher.compute(left, warped)


def occlusion_shadow(left: np.ndarray, warped: np.ndarray, obstacle: np.ndarray,
                     halves: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Return the obstacle pixels that are floor hidden from the right camera.

    Works at half the given size, on the rows holding obstacle pixels (and the matcher's
    block around them).

    Args:
        left: (h, w) uint8 left image at the mask's working scale.
        warped: (h, w) uint8 right image warped into the left view by the plane.
        obstacle: (h, w) bool pixels labelled obstacle.
        halves: ``cv2.pyrDown`` of ``left`` and ``warped`` if the caller has them (the band's
            rows are cut from them: they differ from a band reduced alone only in its first
            and last half row, which the margin keeps away from every obstacle pixel's
            match).

    Returns:
        (h, w) bool, a subset of ``obstacle``: in the shadow of an occluder to the right and
        not part of an obstacle by the tests of the module docstring.

    """
    height, width = obstacle.shape
    shadow = np.zeros((height, width), bool)
    rows = np.flatnonzero(obstacle.any(axis=1))
    if rows.size == 0:
        return shadow
    # Even bounds, so that the half-size band lies on the same grid as the whole image.
    top = max(0, (int(rows[0]) - _BAND_MARGIN_PX) & ~1)
    bottom = min(height, (int(rows[-1]) + _BAND_MARGIN_PX + 2) & ~1)
    if bottom - top < 4 * _BLOCK_PX or width < 2 * (_DISPARITIES + _BLOCK_PX + 1):
        return shadow  # too small for the matcher
    band = slice(top, bottom)
    if halves is None:
        half_left, half_warped = cv2.pyrDown(left[band]), cv2.pyrDown(warped[band])
    else:
        half_band = slice(top // 2, (bottom + 1) // 2)
        half_left, half_warped = halves[0][half_band], halves[1][half_band]
    parallax = block_parallax(half_left, half_warped)
    if parallax is None:
        return shadow
    half_obstacle = cv2.resize(obstacle[band].view(np.uint8), half_left.shape[::-1],
                               interpolation=cv2.INTER_NEAREST).view(bool)
    half = _shadow_in_band(half_left, half_warped, half_obstacle, parallax)
    if half.any():
        full = cv2.resize(half.view(np.uint8), (width, bottom - top),
                          interpolation=cv2.INTER_NEAREST).view(bool)
        shadow[band] = full & obstacle[band]
    return shadow


def _gather(values: np.ndarray, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Return ``values[rows, columns]`` of a C-contiguous 2-D array (flat indexing)."""
    return values.ravel()[rows * values.shape[1] + columns]


def _nonzero(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``np.nonzero`` of a C-contiguous (h, w) bool array (four times faster)."""
    return np.divmod(np.flatnonzero(mask), mask.shape[1])


def _row_cumsum(mask: np.ndarray) -> np.ndarray:
    """Return ``np.cumsum(mask, axis=1)`` of an (h, w) bool array as int32.

    From ``cv2.integral`` (the difference of consecutive rows of the integral image): ten
    times faster than numpy's cumulative sum along rows.
    """
    integral = cv2.integral(mask.view(np.uint8), sdepth=cv2.CV_32S)
    return np.subtract(integral[1:, 1:], integral[:-1, 1:])


def _min_ahead(values: np.ndarray, reach: int) -> np.ndarray:
    """Return per pixel the minimum of (h, w) int32 ``values`` over it and ``reach`` to its right.

    A float32 erosion with a one-row kernel anchored at its left end; exact for values of
    magnitude below 2^24 (and the sentinel ``1 << 30``, a power of two). Only where the
    wanted minimum is known to lie within ``reach`` does it equal the running minimum
    ``np.minimum.accumulate(values[:, ::-1], axis=1)[:, ::-1]``, at a fraction of its cost.
    """
    kernel = np.ones((1, reach + 1), np.uint8)
    return cv2.erode(values.astype(np.float32), kernel, anchor=(0, 0),
                     borderType=cv2.BORDER_CONSTANT, borderValue=float(1 << 30))


def _where(condition: np.ndarray, values: np.ndarray, fill: int) -> np.ndarray:
    """Return ``np.where(condition, values, fill)`` as (h, w) int32.

    ``cv2.copyTo`` with the mask viewed as bytes: several times faster than ``np.where`` on
    irregular masks.
    """
    out = np.full(condition.shape, fill, np.int32)
    cv2.copyTo(np.ascontiguousarray(values, np.int32), condition.view(np.uint8), out)
    return out


def _occluders(obstacle: np.ndarray, parallax16: np.ndarray) -> np.ndarray:
    """Return the (h, w) bool occluders: obstacle pixels with a consistent large parallax.

    An occluder cannot hide floor that the matcher sees (parallax below one pixel) between its
    right-image position and itself: more than one such pixel and it is a false match (they
    occur in the hidden floor itself).
    """
    occluder = obstacle & (parallax16 >= np.int16(8 * _MIN_OCCLUDER_PX))
    rows, cols = _nonzero(occluder)
    if rows.size:
        seen = _row_cumsum((parallax16 >= 0) & (parallax16 < 16))
        reach_px = (_gather(parallax16, rows, cols).astype(np.int32) + 15) // 16
        start = np.maximum(cols - reach_px, 0)
        false = _gather(seen, rows, cols) - _gather(seen, rows, start) > 1
        occluder[rows[false], cols[false]] = False
    return occluder


def _shadow_in_band(left: np.ndarray, warped: np.ndarray, obstacle: np.ndarray,
                    parallax16: np.ndarray) -> np.ndarray:
    """Return the shadow at the matcher's size (see :func:`occlusion_shadow`).

    ``parallax16`` is the matcher's int16 output (1/16 pixels, negative where none).
    """
    height, width = obstacle.shape
    occluder = _occluders(obstacle, parallax16)
    shadow = np.zeros((height, width), bool)
    if not occluder.any():
        return shadow
    # Leftmost right-image position of an occluder to the right of each pixel (an occluder's
    # own does not matter: occluders are taken out below). An occluder with parallax p
    # reaches (p / 16 + slack) pixels to its left, so only that many to the right matter.
    columns = np.arange(width, dtype=np.int32)[None, :]
    parallax = parallax16.astype(np.int32)
    reach_px = int(parallax16.max() + 8 * _SLACK_PX) // 16 + 1
    exact = 1024 * width < (1 << 24)  # the float32 running minimum is exact
    position = _where(occluder, 16 * columns - parallax, 1 << 30)
    if exact:
        reach = _min_ahead(position, reach_px)
    else:
        reach = np.minimum.accumulate(position[:, ::-1], axis=1)[:, ::-1]
    shadow[:, :-1] = reach[:, :-1] <= 16 * columns[:, :-1] + 8 * _SLACK_PX
    shadow &= obstacle & ~occluder
    # The matcher's first consistent pixel lies a pixel or so inside an occluding edge: the
    # pixel just left of an occluder is its edge, not hidden floor.
    shadow[:, :-1] &= ~occluder[:, 1:]
    # Not inside an obstacle: no occluder within the gap on the left.
    gap = _SURFACE_GAP_PX // 2
    near_left = cv2.dilate(occluder.view(np.uint8), np.ones((1, gap + 1), np.uint8),
                           anchor=(gap, 0))
    shadow &= near_left == 0
    if not shadow.any():
        return shadow
    # The nearest occluder on the right with its parallax: index * 1024 + parallax16 (a
    # shadow pixel's lies within the reach of the occluder that casts the shadow).
    key = _where(occluder, columns * 1024 + parallax, 1 << 30)
    if exact:
        next_right = _min_ahead(key, reach_px).astype(np.int32)
    else:
        next_right = np.minimum.accumulate(key[:, ::-1], axis=1)[:, ::-1]
    rows, cols = _nonzero(shadow)
    differs = _differs_from_occluder(left, warped, rows, cols, next_right)
    shadow[rows[~differs], cols[~differs]] = False
    rows, cols = rows[differs], cols[differs]
    far = _lead_px(obstacle, shadow, rows, cols) > _LEAD_PX // 2
    shadow[rows[far], cols[far]] = False
    # The last pixels before the occluding edge stay obstacles.
    trim = _EDGE_TRIM_PX // 2
    shadow &= cv2.erode(shadow.view(np.uint8), np.ones((1, trim + 1), np.uint8),
                        anchor=(0, 0), borderType=cv2.BORDER_REPLICATE).view(bool)
    return shadow


def _differs_from_occluder(left: np.ndarray, warped: np.ndarray, rows: np.ndarray,
                           cols: np.ndarray, next_right: np.ndarray) -> np.ndarray:
    """Return, per shadow pixel, whether it mismatches the warped image at its occluder's shift.

    ``next_right`` holds, per pixel, ``index * 1024 + parallax16`` of the nearest occluder on
    its right, ``1 << 30`` where there is none (such pixels do not differ: they are dropped).
    Pixels that match at that parallax are part of the occluder's surface, not hidden floor.
    """
    width = left.shape[1]
    nearest = _gather(next_right, rows, cols)
    found = nearest < (1 << 30)  # an occluder on the right in its own row
    shift = (nearest % 1024).astype(np.float32) * np.float32(1.0 / 16.0)
    # The correlation only over the candidates' bounding box and a window around it.
    top, bottom = max(0, int(rows.min()) - _WINDOW_PX), int(rows.max()) + _WINDOW_PX + 1
    first, last = max(0, int(cols.min()) - _WINDOW_PX), int(cols.max()) + _WINDOW_PX + 1
    box = (slice(top, bottom), slice(first, last))
    map_x = np.tile(np.arange(first, min(last, width), dtype=np.float32),
                    (left[box].shape[0], 1))
    map_x[rows - top, cols - first] -= np.where(found, shift, np.float32(0.0))
    map_y = np.repeat(np.arange(top, top + map_x.shape[0], dtype=np.float32)[:, None],
                      map_x.shape[1], axis=1)
    shifted = cv2.remap(warped, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    ncc = _ncc(left[box], shifted)
    return found & (_gather(ncc, rows - top, cols - first) < _SAME_SURFACE_NCC)


def _lead_px(obstacle: np.ndarray, shadow: np.ndarray, rows: np.ndarray, cols: np.ndarray
             ) -> np.ndarray:
    """Return, per shadow pixel, the other obstacle pixels between it and the floor on its left.

    Hidden floor has at most :data:`_LEAD_PX` (working pixels) of them: a window's reach into
    it; more and the pixel does not continue the floor.
    """
    width = shadow.shape[1]
    columns = np.broadcast_to(np.arange(width, dtype=np.int32), shadow.shape)
    other = _row_cumsum(obstacle & ~shadow)
    floor_left = np.maximum.accumulate(_where(~obstacle, columns, 0), axis=1)
    return _gather(other, rows, cols) - _gather(other, rows, _gather(floor_left, rows, cols))


def _ncc(a_image: np.ndarray, b_image: np.ndarray) -> np.ndarray:
    """Return the (h, w) float32 zero-shift normalised correlation of two uint8 images' windows."""
    size = (_WINDOW_PX, _WINDOW_PX)
    f32 = cv2.CV_32F
    mean_a = cv2.boxFilter(a_image, f32, size)
    mean_b = cv2.boxFilter(b_image, f32, size)
    # Products of the uint8 images straight into float32 (exact: below 2^16).
    var_a = cv2.blur(cv2.multiply(a_image, a_image, dtype=f32), size)
    var_a -= cv2.multiply(mean_a, mean_a)
    var_b = cv2.blur(cv2.multiply(b_image, b_image, dtype=f32), size)
    var_b -= cv2.multiply(mean_b, mean_b)
    cov = cv2.blur(cv2.multiply(a_image, b_image, dtype=f32), size)
    cov -= cv2.multiply(mean_a, mean_b, dst=mean_a)
    norm = cv2.multiply(var_a, var_b, dst=var_a)
    np.maximum(norm, np.float32(1e-6), out=norm)
    return cv2.divide(cov, cv2.sqrt(norm, dst=norm), dst=cov)
