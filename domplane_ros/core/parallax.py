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


def _yaw(angle_rad: np.ndarray) -> np.ndarray:
    """Return (N, 3, 3) rotations about the y axis (the prior's vergence)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    rot = np.zeros(angle_rad.shape + (3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = c, s, 1.0, -s, c
    return rot


@functools.lru_cache(maxsize=16)
def _intrinsics(cx: float, cy: float, low: float, high: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Return the (N, 3, 3) calibration matrices of the sampled focal lengths and inverses."""
    focals = np.geomspace(low, max(high, low), _FOCAL_SAMPLES)
    k = np.zeros((focals.size, 3, 3))
    k[:, 0, 0], k[:, 1, 1], k[:, 0, 2], k[:, 1, 2], k[:, 2, 2] = focals, focals, cx, cy, 1.0
    k_inv = np.linalg.inv(k)
    k.flags.writeable = False
    k_inv.flags.writeable = False
    return k, k_inv


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
    k, k_inv = _intrinsics(cx, cy, float(focal_px[0]), float(focal_px[1]))
    misfit, scale, rot = _model_fit(homography, k, k_inv)
    best = int(np.argmin(np.where(np.isfinite(misfit), misfit, np.inf)))
    if 0 < best < misfit.size - 1 and np.all(np.isfinite(misfit[best - 1:best + 2])):
        # Parabola through the best sample and its neighbours (in log f): the vertex.
        low, mid, high = misfit[best - 1:best + 2]
        curvature = low - 2.0 * mid + high
        if curvature > 0:
            offset = 0.5 * (low - high) / curvature
            ratio = k[best + 1, 0, 0] / k[best, 0, 0]
            focal = k[best, 0, 0] * ratio ** float(np.clip(offset, -1.0, 1.0))
            k1 = k[best:best + 1].copy()
            k1[0, 0, 0] = k1[0, 1, 1] = focal
            k1_inv = np.linalg.inv(k1)
            _, scale1, rot1 = _model_fit(homography, k1, k1_inv)
            return scale1[0] * (k1[0] @ rot1[0] @ k1_inv[0])
    return scale[best] * (k[best] @ rot[best] @ k_inv[best])


def _model_fit(homography: np.ndarray, k: np.ndarray, k_inv: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the model's misfit, scale and vergence rotation for (N, 3, 3) calibrations."""
    g = k_inv @ homography @ k
    rot = _yaw(np.arctan2(-g[:, 2, 0], g[:, 0, 0]))
    m = np.transpose(rot, (0, 2, 1)) @ g
    scale = m[:, 1, 1].copy()
    scale[np.abs(scale) < 1e-12] = 1e-12
    m = m / scale[:, None, None]
    misfit = (m[:, 1, 0] ** 2 + m[:, 1, 2] ** 2 + m[:, 2, 0] ** 2 + m[:, 2, 1] ** 2
              + (m[:, 2, 2] - 1.0) ** 2 + (m[:, 0, 0] - 1.0) ** 2)
    return misfit, scale, rot


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
