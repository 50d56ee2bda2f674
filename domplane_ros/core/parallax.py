"""Plane + parallax geometry of the ground homography: where a point at infinity lands.

After the right image is warped into the left view by the ground homography ``H``, a point on
the ground has no residual parallax; a point off it is displaced along the epipolar direction,
by an amount that grows with its height above the ground and falls with its distance. With the
camera model of :mod:`domplane_ros.core.prior` (``H = K R_v (I - C n^T / h) K^-1``, baseline
along the left camera's x axis) the left epipole is at infinity along x, so the residual
parallax in the warped view is horizontal, and the homography of the plane at infinity is
``H_inf = K R_v K^-1``. For a left pixel ``x`` the warped view shows the point at infinity
seen through ``x`` shifted by

    ``shift_inf(x) = x-coordinate of H^-1 H_inf x  -  x``,

which is the ground's own disparity relative to infinity: positive below the horizon (growing
toward the image bottom), zero on the horizon, negative above it. A point at height ``eta h``
above the ground, seen through ``x`` below the horizon, lies on the plane parallel to the ground
through it, whose homography is ``H - kappa (H_inf - H)`` with ``kappa = eta / (1 - eta)``; its
residual parallax is ``kappa shift_inf(x)`` (exactly for a rectified head, to first order
otherwise). That is the smallest parallax an obstacle of relative height ``eta`` can produce at
``x``; where it is below the measurable parallax the pixel cannot be decided.

``H`` fixes ``H_inf`` only together with the focal length, which the prior bounds:
:func:`infinity_homography` fits the camera model to ``H`` over the prior's focal range. On a
rectified head (no vergence) every focal length gives the same answer; with vergence the
focal length is picked by how well the model fits.
"""

from __future__ import annotations

import functools
import math
from typing import Sequence

import cv2
from domplane_ros.core.scratch import scratch
import numpy as np

# Focal lengths tried between the prior's bounds (geometric spacing).
_FOCAL_SAMPLES = 16
# Grid step (pixels at the working scale) on which the shift is computed, then interpolated.
_GRID_STEP = 8
# Shifts are clipped to this many pixels (points near the line at infinity of H).
_MAX_SHIFT_PX = 1e4


def _rotation_homography(focal: float, cx: float, cy: float, angle_rad: float) -> np.ndarray:
    """Return the (3, 3) ``K R_v K^-1`` of a rotation about the y axis (the prior's vergence)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    k = np.array([[focal, 0.0, cx], [0.0, focal, cy], [0.0, 0.0, 1.0]])
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    k_inv = np.array([[1.0 / focal, 0.0, -cx / focal], [0.0, 1.0 / focal, -cy / focal],
                      [0.0, 0.0, 1.0]])
    return k @ rot @ k_inv


@functools.lru_cache(maxsize=16)
def _focals(low: float, high: float) -> np.ndarray:
    """Return the (N,) sampled focal lengths of a range (geometric spacing, read-only)."""
    focals = np.geomspace(low, max(high, low), _FOCAL_SAMPLES)
    focals.flags.writeable = False
    return focals


def _principal_point(width: int, height: int, principal_point_px: Sequence[float]
                     ) -> tuple[float, float]:
    """Return the principal point: the given one, else the image centre."""
    if len(principal_point_px) == 2:
        return float(principal_point_px[0]), float(principal_point_px[1])
    return (width - 1) / 2.0, (height - 1) / 2.0


def infinity_homography(homography: np.ndarray, width: int, height: int,
                        focal_px: tuple[float, float],
                        principal_point_px: Sequence[float] = ()) -> np.ndarray:
    """Return the homography of the plane at infinity that goes with a ground homography.

    For each focal length ``f`` sampled in ``focal_px``, ``G = K^-1 H K`` (principal point at
    ``principal_point_px``, default the image centre, as in the prior) is split as
    ``R_v (I - c n^T)``: the vergence ``v`` from ``G``'s first column (``n`` has no x
    component), and the model's misfit from the rows of ``R_v^T G`` that ``c n^T`` cannot
    change. The best fitting ``f`` (refined between the samples by a
    parabola through the misfits) gives ``H_inf = K R_v K^-1``, scaled
    so that ``H - H_inf`` is the model's rank-one plane term.

    Args:
        homography: (3, 3) float64 ground homography, left to right pixels.
        width: Left image width in pixels.
        height: Left image height in pixels.
        focal_px: (min, max) focal length range of the prior, pixels.
        principal_point_px: The prior's ``(cx, cy)``, or empty for the image centre.

    Returns:
        (3, 3) float64 ``H_inf``, on the same scale as ``homography``.

    """
    cx, cy = _principal_point(width, height, principal_point_px)
    focals = _focals(float(focal_px[0]), float(focal_px[1]))
    misfit, scale, angle = _model_fit(homography, focals, cx, cy)
    best = int(np.argmin(np.where(np.isfinite(misfit), misfit, np.inf)))
    focal, vergence = float(focals[best]), float(angle[best])
    if 0 < best < misfit.size - 1 and np.all(np.isfinite(misfit[best - 1:best + 2])):
        # Parabola through the best sample and its neighbours (in log f): the vertex.
        low, mid, high = misfit[best - 1:best + 2]
        curvature = low - 2.0 * mid + high
        if curvature > 0:
            offset = 0.5 * (low - high) / curvature
            ratio = focals[best + 1] / focals[best]
            focal = float(focals[best] * ratio ** float(np.clip(offset, -1.0, 1.0)))
            vergence = float(_model_fit(homography, np.array([focal]), cx, cy)[2][0])
    return scale * _rotation_homography(focal, cx, cy, vergence)


def _model_fit(homography: np.ndarray, focals: np.ndarray, cx: float, cy: float
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """Return the model's misfit, scale and vergence angle for (N,) focal lengths.

    ``G = K^-1 H K`` written out per entry (of ``G`` only the last row's first two entries
    and the last column's first two depend on the focal length ``f``), so that the fit over
    the samples is a few operations on (N,) arrays rather than (N, 3, 3) matrix products.
    """
    h = homography
    column = h @ np.array([cx, cy, 1.0])  # H K's last column
    g00, g01 = h[0, 0] - cx * h[2, 0], h[0, 1] - cx * h[2, 1]
    g10, g11 = h[1, 0] - cy * h[2, 0], h[1, 1] - cy * h[2, 1]
    g20, g21 = focals * h[2, 0], focals * h[2, 1]
    g12 = (column[1] - cy * column[2]) / focals
    g02 = (column[0] - cx * column[2]) / focals
    g22 = column[2]
    angle = np.arctan2(-g20, g00)
    c, s = np.cos(angle), np.sin(angle)
    # M = R_v^T G, divided by its scale M[1, 1] = G[1, 1].
    scale = float(g11) if abs(g11) >= 1e-12 else 1e-12
    m00 = (c * g00 - s * g20) / scale
    m20 = (s * g00 + c * g20) / scale
    m21 = (s * g01 + c * g21) / scale
    m22 = (s * g02 + c * g22) / scale
    misfit = ((g10 / scale) ** 2 + (g12 / scale) ** 2 + m20 ** 2 + m21 ** 2
              + (m22 - 1.0) ** 2 + (m00 - 1.0) ** 2)
    return misfit, scale, angle


def infinity_shift(homography: np.ndarray, width: int, height: int,
                   focal_px: tuple[float, float], size: tuple[int, int],
                   principal_point_px: Sequence[float] = ()) -> np.ndarray:
    """Return the ground's disparity relative to infinity, per pixel of a working grid.

    Args:
        homography: (3, 3) float64 ground homography of the full-size images.
        width: Left image width in pixels.
        height: Left image height in pixels.
        focal_px: (min, max) focal length range of the prior, pixels.
        size: ``(w, h)`` of the working grid; pixel ``(i, j)`` of it covers the left image
            like :func:`cv2.resize` does.
        principal_point_px: The prior's ``(cx, cy)``, or empty for the image centre.

    Returns:
        (h, w) float32 ``shift_inf`` in full-resolution pixels (module docstring): positive
        below the horizon, zero on it, negative above it; large negative where the pixel's ray
        misses the plane at infinity in front of the camera. A view of this thread's scratch
        array (:mod:`domplane_ros.core.scratch`): valid until the next call.

    """
    h_inf = infinity_homography(homography, width, height, focal_px, principal_point_px)
    to_inf = np.linalg.solve(homography, h_inf)
    work_w, work_h = size
    step = _GRID_STEP
    # Grid nodes at working pixels (i + 0.5) step - 0.5, i = -1 .. n: cv2.resize by ``step``
    # puts node i exactly there, and the extra node on each side covers the borders.
    grid_w, grid_h = (work_w + step - 1) // step + 2, (work_h + step - 1) // step + 2
    sx, sy = width / work_w, height / work_h
    xs = (((np.arange(grid_w) - 0.5) * step - 0.5 + 0.5) * sx - 0.5)[None, :]
    ys = (((np.arange(grid_h) - 0.5) * step - 0.5 + 0.5) * sy - 0.5)[:, None]
    num = to_inf[0, 0] * xs + (to_inf[0, 1] * ys + to_inf[0, 2])
    den = to_inf[2, 0] * xs + (to_inf[2, 1] * ys + to_inf[2, 2])
    if np.all(den > 1e-12):
        shift = num / den - xs
    else:
        with np.errstate(divide='ignore', invalid='ignore'):
            shift = num / den - xs
        shift[(den <= 1e-12) | ~np.isfinite(shift)] = -_MAX_SHIFT_PX
    shift = np.clip(shift, -_MAX_SHIFT_PX, _MAX_SHIFT_PX, out=shift).astype(np.float32)
    dense = cv2.resize(shift, (grid_w * step, grid_h * step), interpolation=cv2.INTER_LINEAR,
                       dst=scratch('infinity shift', (grid_h * step, grid_w * step)))
    return dense[step:step + work_h, step:step + work_w]


def height_factor(min_height: float) -> float:
    """Return the height factor ``kappa = eta / (1 - eta)`` of a relative height ``eta``.

    An obstacle of relative height ``eta`` shows ``kappa`` times the ground's disparity
    relative to infinity as residual parallax (module docstring).

    Raises:
        ValueError: Unless ``0 < min_height < 1``.

    """
    if not 0.0 < min_height < 1.0:
        raise ValueError(f'min_height must be in (0, 1), got {min_height}')
    return min_height / (1.0 - min_height)
