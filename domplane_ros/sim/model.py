"""The scene model of the renderer: the stereo head, boxes on the floor, the head's pose.

It uses exactly the camera model of :mod:`domplane_ros.core.prior`:

* Left camera frame: x right, y down, z forward; ``K`` has the principal point at
  ``((w - 1) / 2, (h - 1) / 2)``.
* The floor is ``n . X = h`` with ``h = 1`` and ``n = (0, cos(tilt), sin(tilt))``.
* The right camera centre is ``C = (b, 0, 0)`` (``b = baseline_over_height``) and
  ``X_right = R_v (X_left - C)``.

Geometry lives in the *level frame* of the head: the origin is the left camera centre, x is the
camera's x axis, y points straight down (the floor is ``y = 1``) and z is the horizontal forward
direction. Boxes are placed in this frame. Floor texture is a function of *world* floor
coordinates; a :class:`HeadPose` says where the head stands on the floor and where it faces, so
moving the head moves the floor texture under a fixed camera set-up.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

from domplane_ros.core import prior
import numpy as np

BACKGROUNDS = ('horizon', 'wall')
# Smallest gap between the footprints (circumscribed circles) of two placed boxes.
_BOX_GAP = 0.1


@dataclass(frozen=True)
class CameraSetup:
    """A stereo head: intrinsics, baseline, tilt and vergence, as in :mod:`~.core.prior`.

    Attributes:
        focal_px: Focal length in pixels (both cameras).
        baseline_over_height: Stereo baseline divided by the camera height above the floor.
        tilt_deg: Tilt toward the floor in degrees (positive looks down).
        vergence_deg: Yaw of the right camera toward the left one, degrees.
        width: Image width in pixels.
        height: Image height in pixels.
    """

    focal_px: float
    baseline_over_height: float
    tilt_deg: float
    vergence_deg: float
    width: int = 640
    height: int = 480

    def __post_init__(self) -> None:
        """Check that the set-up is finite and renderable.

        Raises:
            ValueError: If a value is non-finite, the focal length is not positive, the image
                is smaller than 8 x 8 or the tilt is not in (-89, 89) degrees.

        """
        values = (self.focal_px, self.baseline_over_height, self.tilt_deg, self.vergence_deg)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'camera set-up values must be finite, got {values!r}')
        if self.focal_px <= 0:
            raise ValueError(f'focal_px must be positive, got {self.focal_px}')
        if int(self.width) != self.width or int(self.height) != self.height:
            raise ValueError(f'image size must be integer, got {self.width} x {self.height}')
        if self.width < 8 or self.height < 8:
            raise ValueError(f'image must be at least 8 x 8, got {self.width} x {self.height}')
        if not -89.0 < self.tilt_deg < 89.0:
            raise ValueError(f'tilt_deg must be in (-89, 89), got {self.tilt_deg}')

    def homography(self) -> np.ndarray:
        """Return the true left-to-right floor homography, (3, 3) float64, ``H[2, 2] == 1``."""
        return prior.plane_homography(self.focal_px, self.baseline_over_height, self.tilt_deg,
                                      self.vergence_deg, self.width, self.height)

    def intrinsics(self) -> np.ndarray:
        """Return the (3, 3) float64 calibration matrix shared by both cameras."""
        return prior.intrinsics(self.focal_px, self.width, self.height)


@dataclass(frozen=True)
class Box:
    """A box standing on the floor, in the level frame of the head (camera height = 1).

    Attributes:
        x: Centre of the footprint, metres to the right of the left camera.
        z: Centre of the footprint, horizontal distance ahead of the left camera.
        width: Side along the box's own x axis.
        depth: Side along the box's own z axis.
        height: Height above the floor.
        yaw_deg: Rotation of the box about the vertical axis, degrees.
    """

    x: float
    z: float
    width: float
    depth: float
    height: float
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        """Check that the box is finite with positive sides.

        Raises:
            ValueError: If a value is non-finite or a side is not positive.

        """
        values = (self.x, self.z, self.width, self.depth, self.height, self.yaw_deg)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'box values must be finite, got {values!r}')
        if min(self.width, self.depth, self.height) <= 0:
            raise ValueError(
                f'box sides must be positive, got {self.width}, {self.depth}, {self.height}')


@dataclass(frozen=True)
class HeadPose:
    """Where the head stands on the textured floor (the floor texture origin).

    A level-frame floor point ``(x_l, z_l)`` has world floor coordinates
    ``(x, z) + x_l * (cos yaw, -sin yaw) + z_l * (sin yaw, cos yaw)``.

    Attributes:
        x: World x of the point under the left camera.
        z: World z of the point under the left camera.
        yaw_deg: Heading of the head in the world, degrees.
    """

    x: float = 0.0
    z: float = 0.0
    yaw_deg: float = 0.0


@dataclass(frozen=True, eq=False)
class StereoFrame:
    """A rendered stereo pair with its ground truth.

    Attributes:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        homography: (3, 3) float64 true left-to-right floor homography.
        plane_left: (H, W) bool, the left pixel sees the floor (not a box, wall or sky).
        visible_in_right: (H, W) bool, the floor point seen at the left pixel's centre is inside
            the right image and not occluded by a box from the right camera.
        obstacle_left: (H, W) bool, the left pixel sees (at least partly) a box.
        setup: The camera set-up.
        boxes: The boxes, in the level frame.
        floor: The floor texture kind.
        head_pose: The head's pose on the floor.
        occluded_in_right: (H, W) bool, the floor point seen at the left pixel's centre is
            inside the right image but hidden from the right camera by a box (the occlusion
            shadow; disjoint from ``visible_in_right``), or None if not rendered.
        obstacle_hidden: (H, W) bool, box pixels whose point (where the left pixel centre's
            ray meets a box) the right camera does not see: outside the right image, or
            behind a box (a face turned away from it); or None if not rendered.
    """

    left: np.ndarray
    right: np.ndarray
    homography: np.ndarray
    plane_left: np.ndarray
    visible_in_right: np.ndarray
    obstacle_left: np.ndarray
    setup: CameraSetup
    boxes: tuple[Box, ...] = ()
    floor: str = 'random'
    head_pose: HeadPose = HeadPose()
    occluded_in_right: np.ndarray | None = None
    obstacle_hidden: np.ndarray | None = None


def footprint_radius(box: Box) -> float:
    """Return the radius of the circle around a box's footprint."""
    return 0.5 * math.hypot(box.width, box.depth)


def overlaps_any(box: Box, others: Sequence[Box]) -> bool:
    """Return whether ``box``'s footprint comes within 0.1 of any of ``others``' footprints."""
    radius = footprint_radius(box)
    return any(math.hypot(box.x - o.x, box.z - o.z) < radius + footprint_radius(o) + _BOX_GAP
               for o in others)


def level_boxes(world_boxes: Sequence[Box], x: float, z: float, yaw_deg: float) -> list[Box]:
    """Return boxes given relative to a start pose in the level frame of a moved head.

    Args:
        world_boxes: Boxes in the start's level frame.
        x: The head's x in the start's level frame.
        z: The head's z in the start's level frame.
        yaw_deg: The head's heading relative to the start, degrees.

    Returns:
        The boxes in the moved head's level frame.

    """
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    out = []
    for b in world_boxes:
        dx, dz = b.x - x, b.z - z
        out.append(Box(c * dx - s * dz, s * dx + c * dz, b.width, b.depth, b.height,
                       b.yaw_deg - yaw_deg))
    return out


def rot_y(angle_rad: float) -> np.ndarray:
    """Return the (3, 3) rotation about the y axis by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def level_from_left(tilt_deg: float) -> np.ndarray:
    """Return the (3, 3) rotation taking left-camera coordinates to level-frame coordinates."""
    t = math.radians(tilt_deg)
    return np.array([[1.0, 0.0, 0.0],
                     [0.0, math.cos(t), math.sin(t)],
                     [0.0, -math.sin(t), math.cos(t)]])


def camera_poses(setup: CameraSetup) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return (origin (3,), camera-to-level rotation (3, 3)) of the left and right cameras."""
    r_lc = level_from_left(setup.tilt_deg)
    r_v = rot_y(math.radians(setup.vergence_deg))
    centre = np.array([setup.baseline_over_height, 0.0, 0.0])
    return [(np.zeros(3), r_lc), (r_lc @ centre, r_lc @ r_v.T)]
