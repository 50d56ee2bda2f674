"""Temporal prediction of the plane homography from each camera's frame-to-frame motion.

An active head pans, tilts and verges, so the left-to-right plane homography changes from frame
to frame. Each camera's own motion is measured from its images alone: the previous frame's
corners are tracked into the current frame with pyramidal Lucas-Kanade (kept only if tracking
back lands where it started), and a homography ``M`` (previous to current pixels) is fitted to
the tracks robustly (MAGSAC++). For a camera that only rotates, ``M = K R K^-1`` is exact for
every scene point; when a camera also translates (the right camera of a head panning about the
left one), ``M`` of the dominant plane is still exact for plane points, which dominate the
tracks. The plane homography then moves with the cameras as

    ``H_t ~ M_right H_{t-1} M_left^-1``

because a left pixel ``x_t`` came from ``M_left^-1 x_t`` in the previous frame, which the plane
mapped to ``H_{t-1} M_left^-1 x_t`` in the previous right image, which moved to
``M_right H_{t-1} M_left^-1 x_t``. The pipeline uses this as the warm start.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
from domplane_ros.core.homography import check_homography, normalise_scale
import numpy as np

if TYPE_CHECKING:
    from domplane_ros.config import TrackingConfig

_LK_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)


@dataclass(frozen=True)
class CameraMotion:
    """One camera's motion between two frames, or why it could not be measured.

    Attributes:
        homography: (3, 3) float64 previous-to-current pixel homography ``M`` with
            ``M[2, 2] == 1``, or None if the fit failed.
        n_tracks: Points tracked forward and back within the tolerance.
        n_inliers: Tracks consistent with ``M`` (0 on failure).
        median_shift_px: Median displacement of the tracks, pixels (NaN without tracks).
        reason: Why the motion could not be measured ('' on success).
    """

    homography: np.ndarray | None
    n_tracks: int
    n_inliers: int
    median_shift_px: float
    reason: str = ''

    @property
    def ok(self) -> bool:
        """Return True if ``homography`` holds a motion."""
        return self.homography is not None


def track_points(previous: np.ndarray, current: np.ndarray, points: np.ndarray,
                 window_px: int = 21, pyramid_levels: int = 3,
                 forward_backward_px: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Track points from one grey image to the next (pyramidal Lucas-Kanade).

    A point is kept only if LK converged both ways and tracking it back from its new position
    lands within ``forward_backward_px`` of where it started; with ``forward_backward_px`` 0
    there is no tracking back (:func:`track_forward`, half the cost): every point LK tracked
    into the image is kept, and the robust motion fit rejects the bad tracks.

    Args:
        previous: (H, W) uint8 previous image.
        current: (H, W) uint8 current image (same shape).
        points: (N, 2) float64 points in ``previous``.
        window_px: Side of the LK window, pixels (odd, >= 5).
        pyramid_levels: Pyramid levels above full resolution.
        forward_backward_px: Largest forward-backward round-trip error, pixels; 0: forward
            only.

    Returns:
        ``(source, target)``: (K, 2) float64 kept points in ``previous`` and their (K, 2)
        positions in ``current``.

    Raises:
        ValueError: If the images differ in shape or are not 2-D uint8, or the points are not
            (N, 2).

    """
    points = _checked(previous, current, points)
    if points.shape[0] == 0:
        return np.empty((0, 2)), np.empty((0, 2))
    if forward_backward_px <= 0:
        kept, target = track_forward(previous, current, points, window_px, pyramid_levels)
        return points[kept], target
    window = (int(window_px), int(window_px))
    p0 = points.astype(np.float32).reshape(-1, 1, 2)
    p1, st1, _ = cv2.calcOpticalFlowPyrLK(previous, current, p0, None, winSize=window,
                                          maxLevel=int(pyramid_levels), criteria=_LK_CRITERIA)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(current, previous, p1, None, winSize=window,
                                            maxLevel=int(pyramid_levels), criteria=_LK_CRITERIA)
    round_trip = np.linalg.norm((back - p0).reshape(-1, 2), axis=1)
    target = p1.reshape(-1, 2).astype(np.float64)
    keep = ((st1.ravel() == 1) & (st2.ravel() == 1) & (round_trip < forward_backward_px)
            & _inside(target, current.shape))
    return points[keep], target[keep]


def track_forward(previous: np.ndarray, current: np.ndarray, points: np.ndarray,
                  window_px: int = 21, pyramid_levels: int = 3,
                  initial: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Track points from one grey image to the next, forward only (pyramidal Lucas-Kanade).

    Half the cost of :func:`track_points` with its round trip: no tracking back. Bad tracks
    are left to the robust motion fit (and, for carried corners, to the estimator).

    Args:
        previous: (H, W) uint8 previous image.
        current: (H, W) uint8 current image (same shape).
        points: (N, 2) float64 points in ``previous``.
        window_px: Side of the LK window, pixels (odd, >= 5).
        pyramid_levels: Pyramid levels above full resolution.
        initial: Optional (N, 2) float64 guesses of the positions in ``current`` (the
            points tracked from an older image than ``previous``'s predecessor).

    Returns:
        ``(kept, target)``: (K,) int64 indices of the points LK tracked into the image and
        their (K, 2) float64 positions in ``current``.

    Raises:
        ValueError: As :func:`track_points`.

    """
    points = _checked(previous, current, points)
    if points.shape[0] == 0:
        return np.empty(0, np.int64), np.empty((0, 2))
    window = (int(window_px), int(window_px))
    p0 = points.astype(np.float32).reshape(-1, 1, 2)
    flags = 0
    guess = None
    if initial is not None:
        guess = np.asarray(initial, np.float32).reshape(-1, 1, 2).copy()
        flags = cv2.OPTFLOW_USE_INITIAL_FLOW
    p1, status, _ = cv2.calcOpticalFlowPyrLK(previous, current, p0, guess, winSize=window,
                                             maxLevel=int(pyramid_levels),
                                             criteria=_LK_CRITERIA, flags=flags)
    target = p1.reshape(-1, 2).astype(np.float64)
    kept = np.flatnonzero((status.ravel() == 1) & _inside(target, current.shape))
    return kept, target[kept]


def _checked(previous: np.ndarray, current: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Validate two frames and a point set; return the points as (N, 2) float64."""
    for image, name in ((previous, 'previous'), (current, 'current')):
        if not (isinstance(image, np.ndarray) and image.ndim == 2
                and image.dtype == np.uint8):
            raise ValueError(f'{name} must be a 2-D uint8 image')
    if previous.shape != current.shape:
        raise ValueError(f'image shapes differ: {previous.shape} and {current.shape}')
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f'points must have shape (N, 2), got {points.shape}')
    return points


def _inside(points: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Return (N,) bool: finite points inside an image of ``shape`` (H, W)."""
    height, width = shape
    return (np.all(np.isfinite(points), axis=1) & (points[:, 0] >= 0)
            & (points[:, 0] <= width - 1) & (points[:, 1] >= 0) & (points[:, 1] <= height - 1))


def fit_camera_motion(source: np.ndarray, target: np.ndarray, min_tracks: int = 20,
                      min_inlier_ratio: float = 0.5, threshold_px: float = 2.0
                      ) -> CameraMotion:
    """Fit a camera's frame-to-frame homography to point tracks robustly (MAGSAC++).

    Args:
        source: (K, 2) float64 points in the previous image.
        target: (K, 2) float64 the same points in the current image.
        min_tracks: Fewer tracks than this is a failure.
        min_inlier_ratio: A fit with fewer than this share of the tracks as inliers is a
            failure.
        threshold_px: Inlier threshold of the robust fit, pixels.

    Returns:
        The :class:`CameraMotion`; on failure ``homography`` is None and ``reason`` says why.

    Raises:
        ValueError: If the arrays are not (K, 2) of equal length.

    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.ndim != 2 or source.shape[1] != 2 or source.shape != target.shape:
        raise ValueError(f'source and target must both be (K, 2), got {source.shape} and '
                         f'{target.shape}')
    n = source.shape[0]
    shift = float(np.median(np.linalg.norm(target - source, axis=1))) if n else float('nan')
    if n < max(int(min_tracks), 4):
        return CameraMotion(None, n, 0, shift, f'too few tracks: {n} < {min_tracks}')
    m, inliers = cv2.findHomography(source, target, cv2.USAC_MAGSAC, float(threshold_px),
                                    maxIters=2000, confidence=0.999)
    if m is None or inliers is None:
        return CameraMotion(None, n, 0, shift, 'robust motion fit failed')
    n_in = int(np.count_nonzero(inliers))
    if n_in < min_inlier_ratio * n:
        return CameraMotion(None, n, n_in, shift,
                            f'poor motion fit: {n_in} of {n} tracks are inliers')
    m = np.asarray(m, dtype=np.float64)
    reason = check_homography(m)
    if reason:
        return CameraMotion(None, n, n_in, shift, f'motion fit {reason}')
    return CameraMotion(normalise_scale(m), n, n_in, shift)


def camera_motion(previous: np.ndarray, current: np.ndarray, points: np.ndarray,
                  options: TrackingConfig) -> CameraMotion:
    """Track ``points`` from ``previous`` into ``current`` and fit the camera's motion.

    Args:
        previous: (H, W) uint8 previous image.
        current: (H, W) uint8 current image.
        points: (N, 2) float64 points in ``previous`` (its corners, best first); the first
            ``options.max_points`` of them are tracked.
        options: Tracking settings.

    Returns:
        The :class:`CameraMotion`.

    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim == 2 and points.shape[0] > options.max_points:
        # detect_corners lists the strongest corner of every grid cell first, then the
        # second strongest, ...: the first ones are strong and spread over the image.
        points = points[:options.max_points]
    source, target = track_points(previous, current, points, options.window_px,
                                  options.pyramid_levels, options.forward_backward_px)
    return fit_camera_motion(source, target, options.min_tracks, options.min_inlier_ratio,
                             options.threshold_px)


def predict_plane_homography(last: np.ndarray, motion_left: np.ndarray,
                             motion_right: np.ndarray) -> np.ndarray | None:
    """Propagate a plane homography through both cameras' motions.

    Args:
        last: (3, 3) float64 left-to-right plane homography of the previous frame.
        motion_left: (3, 3) float64 left camera motion ``M_left`` (previous to current).
        motion_right: (3, 3) float64 right camera motion ``M_right``.

    Returns:
        (3, 3) float64 ``M_right H M_left^-1`` with ``[2, 2] == 1``, or None if it is singular
        or non-finite.

    """
    try:
        inv_left = np.linalg.inv(motion_left)
    except np.linalg.LinAlgError:
        return None
    h = motion_right @ last @ inv_left
    if check_homography(h):
        return None
    return normalise_scale(h)
