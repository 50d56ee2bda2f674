"""Frame to frame: each camera's motion, and the corners carried into the next pair.

The pipeline keeps the previous pair's working-level images and corners here. For each new
pair :class:`FrameTracker` tracks those corners into the new images with pyramidal
Lucas-Kanade and fits each camera's motion ``M`` (previous to current pixels) to the tracks
(:mod:`domplane_ros.core.tracking`), from which the pipeline predicts the plane homography.

With ``tracking.reuse_pairs`` above 0 (off by default) the tracked corners of a locked pair
*are* the next pair's corners for that many pairs in a row: detecting afresh costs more than
tracking (4.4 ms for a 640 x 480 image against 2.2 ms to track 400 corners into it, one
core). They are tracked from the pair they were detected in, the previous positions as the
guess, so they do not drift; a pair detects afresh after ``reuse_pairs`` pairs, when fewer than
:data:`MIN_CARRIED_SHARE` of the corners survive, or when the motion cannot be fitted. The
motion is then fitted to the forward tracks of every corner. It saves about a quarter of a
warm pair but costs accuracy where Lucas-Kanade slides along edges (tiled and planked floors:
0.03-0.13 px; random texture: none), hence off. With ``reuse_pairs`` 0 the motion is fitted to
tracks of the first ``tracking.max_points`` corners (forward only by default,
``tracking.forward_backward_px``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from domplane_ros.config import PlaneNodeConfig, TrackingConfig
from domplane_ros.core.pyramid import motion_to_full, WorkingImage
from domplane_ros.core.tracking import camera_motion, CameraMotion, fit_camera_motion, \
    track_forward
import numpy as np

# A pair re-uses the tracked corners only if at least this share of the previous pair's
# corners survive in each image (tracked inside the image and the region of interest, and
# still a corner); else it detects afresh, so the corners stay spread over the image.
MIN_CARRIED_SHARE = 0.7


@dataclass
class _Camera:
    """One camera's previous pair: its image and corners, and where they were detected.

    Carried corners are tracked from the image they were detected in (``key_image``), the
    previous positions serving as the guess, so they do not drift from pair to pair.
    """

    image: np.ndarray
    points: np.ndarray
    key_image: np.ndarray
    key_points: np.ndarray
    alive: np.ndarray


@dataclass(frozen=True)
class Tracked:
    """One pair's view of the previous one.

    Attributes:
        motions: ``(M_left, M_right)`` (3, 3) float64 in full pixels, or None.
        corners: ``(left, right)`` (N, 2) float64 tracked positions (working pixels) of the
            previous corners that may serve as this pair's corners, or None: detect.
        counts: The previous pair's corner counts ``(left, right)``.
        alive: ``(left, right)`` (N,) int64: which detected corner each tracked one is.
        lost: The previous pair had corners enough to track (``tracking.min_tracks`` in each
            camera) and yet a camera's motion could not be fitted: this pair does not
            continue the previous one (a cut, a saccade). False with a motion, and where
            nothing was tried or there was too little to track.
    """

    motions: tuple[np.ndarray, np.ndarray] | None = None
    corners: tuple[np.ndarray, np.ndarray] | None = None
    counts: tuple[int, int] = (0, 0)
    alive: tuple[np.ndarray, np.ndarray] | None = None
    lost: bool = False


class FrameTracker:
    """The previous pair, and how many pairs in a row have carried its corners."""

    def __init__(self) -> None:
        """Start with no previous pair."""
        self._cameras: tuple[_Camera, _Camera] | None = None
        self._carried = 0

    def clear(self) -> None:
        """Forget the previous pair (after a reset)."""
        self._cameras = None
        self._carried = 0

    def track(self, left: WorkingImage, right: WorkingImage, config: PlaneNodeConfig,
              motion: bool, carry: bool) -> Tracked:
        """Track the previous pair into this one.

        Args:
            left: This pair's left working image.
            right: This pair's right working image.
            config: The configuration (``tracking.*``, ``features.kind``).
            motion: Whether the cameras' motion is wanted (there is a plane to predict).
            carry: Whether the tracked corners may serve as this pair's corners.

        Returns:
            The :class:`Tracked` view; no motion and no corners without a previous pair of
            the same size, with tracking off or ``motion`` False.

        """
        cfg = config.tracking
        cams = self._cameras
        if (not cfg.enabled or not motion or cams is None
                or cams[0].image.shape != left.image.shape):
            return Tracked()
        if cfg.reuse_pairs == 0 or config.features.kind == 'lines':
            motions = _checked_motions(cams, left, right, config)
            return Tracked(motions=motions, lost=motions is None and _trackable(cams, cfg))
        fits: list[CameraMotion] = []
        corners, alive = [], []
        for image, cam in zip((left, right), cams):
            kept, target = track_forward(cam.key_image, image.image, cam.key_points[cam.alive],
                                         cfg.window_px, cfg.pyramid_levels, initial=cam.points)
            fits.append(fit_camera_motion(cam.points[kept], target, cfg.min_tracks,
                                          cfg.min_inlier_ratio, cfg.threshold_px))
            corners.append(target)
            alive.append(cam.alive[kept])
        if not (fits[0].ok and fits[1].ok):
            return Tracked(lost=_trackable(cams, cfg))
        motions = (motion_to_full(fits[0].homography, left.scale),
                   motion_to_full(fits[1].homography, right.scale))
        counts = (cams[0].points.shape[0], cams[1].points.shape[0])
        if not (carry and self._carried < cfg.reuse_pairs):
            return Tracked(motions)
        return Tracked(motions, (corners[0], corners[1]), counts, (alive[0], alive[1]))

    def keep(self, left: WorkingImage, right: WorkingImage,
             corners: tuple[np.ndarray, np.ndarray],
             alive: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Keep this pair's working images and corners (working pixels) for the next one.

        Args:
            left: This pair's left working image.
            right: This pair's right working image.
            corners: ``(left, right)`` (N, 2) float64 this pair's corners, working pixels.
            alive: For carried corners, which corner of the image they were detected in each
                one is (see :class:`Tracked`); None for corners detected in this pair.

        """
        images = tuple(image.image.copy() if image.level == 0 else image.image
                       for image in (left, right))
        if alive is None or self._cameras is None:
            self._cameras = tuple(_Camera(image, points, image, points,
                                          np.arange(points.shape[0]))
                                  for image, points in zip(images, corners))
            self._carried = 0
            return
        self._cameras = tuple(_Camera(image, points, cam.key_image, cam.key_points, index)
                              for image, points, cam, index in zip(images, corners,
                                                                   self._cameras, alive))
        self._carried += 1


def enough_carried(carried: Sequence[np.ndarray], counts: tuple[int, int]) -> bool:
    """Return True if the carried corners are enough to stand for a detection."""
    return all(c.shape[0] >= MIN_CARRIED_SHARE * n for c, n in zip(carried, counts))


def _trackable(cams: tuple[_Camera, _Camera], cfg: TrackingConfig) -> bool:
    """Return whether both cameras' previous pair had ``tracking.min_tracks`` corners to track."""
    return all(min(cam.points.shape[0], cfg.max_points) >= cfg.min_tracks for cam in cams)


def _checked_motions(cams: tuple[_Camera, _Camera], left: WorkingImage, right: WorkingImage,
                     config: PlaneNodeConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """Return both cameras' motions from tracks of the first ``tracking.max_points``, or None."""
    cfg = config.tracking
    motion_left = camera_motion(cams[0].image, left.image, cams[0].points, cfg)
    if not motion_left.ok:
        return None
    motion_right = camera_motion(cams[1].image, right.image, cams[1].points, cfg)
    if not motion_right.ok:
        return None
    return (motion_to_full(motion_left.homography, left.scale),
            motion_to_full(motion_right.homography, right.scale))
