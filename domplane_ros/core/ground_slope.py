"""The disparity slope of a plane homography: the ground of a correctly ordered head, or not.

:func:`swap_evidence` checks whether a plane that verifies well was found for swapped cameras.
For a ground plane seen by a correctly ordered head the plane's disparity ``x - H(x)`` grows
toward the bottom of the image (nearer floor); for swapped cameras ``H`` is the inverse and the
disparity shrinks toward the bottom; a wall facing the head has none. :func:`ground_roll_deg`
reads the direction of that growth: for the ground under a level head it is straight down the
image once the camera model's vergence and the right camera's roll are taken out. The
photometric side of a plane's verdict is :mod:`domplane_ros.core.verification`.

Nothing here imports ROS; the functions take numpy arrays and return frozen values.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

from domplane_ros.core.homography import as_valid_homography
import numpy as np

# Focal lengths tried between the prior's bounds by ground_roll_deg (geometric spacing).
ROLL_FOCAL_SAMPLES = 33


@dataclass(frozen=True)
class SwapEvidence:
    """Whether a plane homography looks like one found for swapped left and right cameras.

    Attributes:
        swapped: True when the plane's disparity shrinks toward the image bottom.
        disparity_slope: Change of the disparity ``x - H(x, y)_x`` per image row along the
            centre column over the given rows (pixels per pixel); positive for a ground plane
            seen by a correctly ordered head.
        disparity_bottom_px: Disparity at the bottom centre of the image.
    """

    swapped: bool
    disparity_slope: float
    disparity_bottom_px: float


def swap_evidence(homography: np.ndarray, width: int, height: int,
                  rows: tuple[float, float] = (0.6, 1.0),
                  min_slope: float = 0.02) -> SwapEvidence:
    """Tell whether a ground-plane homography was found for swapped cameras.

    The disparity slope is read from the Jacobian ``J`` of ``H`` at five points down the
    centre column over ``rows``: ``-(J[0, 1] + J[1, 0])``. For a plane map of a level head
    ``J[0, 1]`` is minus the growth of the disparity ``x - H(x)_x`` per row; a roll ``r`` of the
    right camera adds ``-r`` to ``J[0, 1]`` and ``+r`` to ``J[1, 0]``, so their sum does not
    see the roll (to first order) while a swap flips its sign. Measured on rendered heads:
    at least +0.052 px per row for true planes, with or without a rough rig (4 deg roll,
    2 deg pitch, 3 % focal mismatch), at most -0.052 for swapped cameras; a plane facing the
    camera (a wall) has none.

    Args:
        homography: (3, 3) float left-to-right plane homography.
        width: Image width in pixels.
        height: Image height in pixels.
        rows: The band of rows, as fractions of the height, over which the disparity slope
            is measured (the lower part, where the ground is).
        min_slope: Slope below ``-min_slope`` is taken for swapped cameras.

    Returns:
        The :class:`SwapEvidence`.

    Raises:
        ValueError: If the homography is not a finite non-singular (3, 3) matrix, the size
            is not positive or the row band is empty.

    """
    hom = as_valid_homography(homography)
    if width < 1 or height < 2:
        raise ValueError(f'image size must be at least 1 x 2, got {width} x {height}')
    lo, hi = (float(r) for r in rows)
    if not 0.0 <= lo < hi <= 1.0:
        raise ValueError(f'rows must satisfy 0 <= lo < hi <= 1, got {rows!r}')
    x = (width - 1) / 2.0
    ys = np.linspace(lo, hi, 5) * (height - 1)
    slopes = [_shear(hom, x, y) for y in ys]
    bottom = hom @ np.array([x, ys[-1], 1.0])
    slope = float(np.mean(slopes))
    return SwapEvidence(swapped=bool(slope < -min_slope), disparity_slope=slope,
                        disparity_bottom_px=float(x - bottom[0] / bottom[2]))


def _shear(hom: np.ndarray, x: float, y: float) -> float:
    """Return ``-(J[0, 1] + J[1, 0])`` of the homography's Jacobian at ``(x, y)``."""
    p = hom @ np.array([x, y, 1.0])
    w = p[2]
    dx_dy = (hom[0, 1] * w - p[0] * hom[2, 1]) / (w * w)
    dy_dx = (hom[1, 0] * w - p[1] * hom[2, 0]) / (w * w)
    return float(-(dx_dy + dy_dx))


def ground_roll_deg(homography: np.ndarray, width: int, height: int,
                    focal_px: tuple[float, float], principal_point_px: Sequence[float] = (),
                    samples: int = ROLL_FOCAL_SAMPLES) -> float:
    """Return the least roll of a ground plane about the optical axis, over the focal range.

    In the prior's camera model (:mod:`domplane_ros.core.prior`) ``G = K^-1 H K`` is
    ``R_v (I - c n^T)`` with ``c = (b / h, 0, 0)`` and the ground's normal
    ``n = (0, cos(tilt), sin(tilt))``: the ground's disparity grows straight down the image
    (``c n_x`` across it, ``c n_y`` down it). For each focal length ``f`` sampled in
    ``focal_px`` the vergence ``v`` is read from ``G``'s first column and ``M = R_v^T G``
    scaled to ``M[1, 1] = 1`` (a focal mismatch of the right camera scales both image axes
    alike); ``c n_x = 1 - M[0, 0]``, ``c n_y = -(M[0, 1] + M[1, 0])``. A roll ``r`` of the
    right camera adds ``r`` to ``M[1, 0]`` and ``-r c n_y`` to ``c n_x`` (to first order), so
    the roll of the plane is ``atan2(c n_x + M[1, 0] c n_y, c n_y)``; the least in magnitude
    over the focal lengths is returned (the focal length is known only to the prior's range).

    The ground of a level head inside the prior has none: 0.08 deg at most over the default
    prior's rendered set-ups, 1.4 deg on the same heads as rough rigs (roll 4 deg, pitch
    2 deg, focal 3 %, principal points 10 px apart); ``stream/trust.py``
    (``verification.max_ground_roll_deg``) for what published planes measure. A rotation of
    both images by ``a`` (both cameras rolled alike against their baseline) reads about
    ``2 a``: its vertical disparity is taken for the right camera's roll and its vertical
    compression for a focal mismatch.

    Args:
        homography: (3, 3) float left-to-right plane homography.
        width: Image width in pixels.
        height: Image height in pixels.
        focal_px: (min, max) focal length range of the prior, pixels.
        principal_point_px: The prior's ``(cx, cy)``, or empty for the image centre.
        samples: Focal lengths sampled (geometric spacing).

    Returns:
        Signed roll in degrees, in (-180, 180]; 90 or more where the disparity does not grow
        down the image.

    Raises:
        ValueError: If the homography is not a finite non-singular (3, 3) matrix, the size
            is not positive or the focal range is not positive.

    """
    across, down, m10 = _model_terms(homography, width, height, focal_px,
                                     principal_point_px, samples)
    rolls = np.degrees(np.arctan2(across + m10 * down, down))
    return float(rolls[int(np.argmin(np.abs(rolls)))])


def ground_slope_range(homography: np.ndarray, width: int, height: int,
                       focal_px: tuple[float, float], principal_point_px: Sequence[float] = (),
                       samples: int = ROLL_FOCAL_SAMPLES) -> tuple[float, float]:
    """Return the least and greatest disparity slope of a ground plane over the focal range.

    The slope is ``c n_y`` of :func:`ground_roll_deg`'s model, i.e. ``(b / h) cos(tilt)`` for
    the ground of a level head: the growth of the disparity per image row, without the right
    camera's roll, its focal mismatch and the vergence (taken out per focal length of the
    prior, as for the roll). It does not depend on the image's scale (a pyramid level reads
    the same); a principal point ``dy`` pixels off the prior's (a crop that moves the image
    centre, when ``principal_point_px`` is not set) shifts it by about ``dy sin(v) / f`` for a
    vergence ``v`` (0.021 for the lower half of 640 x 480 at f 400 and 4 deg; nothing for a
    rectified head); the prior's ranges of ``b / h`` and tilt bound it
    (:func:`prior_slope_bounds`). A plane far beyond the ground (a plane through distant
    structure, almost at infinity) has a slope near 0.

    Args:
        homography: (3, 3) float left-to-right plane homography.
        width: Image width in pixels.
        height: Image height in pixels.
        focal_px: (min, max) focal length range of the prior, pixels.
        principal_point_px: The prior's ``(cx, cy)``, or empty for the image centre.
        samples: Focal lengths sampled (geometric spacing).

    Returns:
        ``(least, greatest)`` slope over the sampled focal lengths (pixels per pixel).

    Raises:
        ValueError: As :func:`ground_roll_deg`.

    """
    down = _model_terms(homography, width, height, focal_px, principal_point_px, samples)[1]
    return float(down.min()), float(down.max())


def prior_slope_bounds(baseline_over_height: tuple[float, float],
                       tilt_deg: tuple[float, float]) -> tuple[float, float]:
    """Return the least and greatest ground disparity slope ``(b / h) cos(tilt)`` of a prior.

    Args:
        baseline_over_height: The prior's (min, max) baseline over camera height.
        tilt_deg: The prior's (min, max) tilt of the head below the horizon, degrees.

    Returns:
        ``(least, greatest)`` slope (pixels per pixel) over the prior's ranges.

    """
    low_bh, high_bh = (float(v) for v in baseline_over_height)
    low_t, high_t = (math.radians(float(v)) for v in tilt_deg)
    cos_least = min(math.cos(low_t), math.cos(high_t))
    cos_greatest = 1.0 if low_t <= 0.0 <= high_t else max(math.cos(low_t), math.cos(high_t))
    return low_bh * max(cos_least, 0.0), high_bh * cos_greatest


def _model_terms(homography: np.ndarray, width: int, height: int,
                 focal_px: tuple[float, float], principal_point_px: Sequence[float],
                 samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``c n_x`` (with the roll), ``c n_y`` and ``M[1, 0]`` per sampled focal length.

    See :func:`ground_roll_deg` for the model; arrays of ``samples`` values.
    """
    hom = as_valid_homography(homography)
    if width < 1 or height < 1:
        raise ValueError(f'image size must be positive, got {width} x {height}')
    low, high = (float(f) for f in focal_px)
    if not 0.0 < low <= high or samples < 1:
        raise ValueError(f'focal range must satisfy 0 < min <= max, got {focal_px!r}')
    if len(principal_point_px) == 2:
        cx, cy = (float(v) for v in principal_point_px)
    else:
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    if hom[1, 1] - cy * hom[2, 1] < 0.0:
        # H and -H are the same plane; the model's G[1, 1] is positive (the vergence is read
        # from G's first column, whose sign follows H's scale).
        hom = -hom
    focals = np.geomspace(low, high, samples)
    # G = K^-1 H K per focal length: of its entries used here only G[2, 0] and G[2, 1] depend
    # on f (the upper-left 2 x 2 block does not).
    g00, g01 = hom[0, 0] - cx * hom[2, 0], hom[0, 1] - cx * hom[2, 1]
    g10, g11 = hom[1, 0] - cy * hom[2, 0], hom[1, 1] - cy * hom[2, 1]
    g20, g21 = focals * hom[2, 0], focals * hom[2, 1]
    angle = np.arctan2(-g20, g00)
    cos, sin = np.cos(angle), np.sin(angle)
    scale = g11 if abs(g11) >= 1e-12 else 1e-12
    m00 = (cos * g00 - sin * g20) / scale
    m01 = (cos * g01 - sin * g21) / scale
    m10 = g10 / scale
    return 1.0 - m00, -(m01 + m10), np.broadcast_to(m10, focals.shape)
