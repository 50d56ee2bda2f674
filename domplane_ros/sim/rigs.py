"""Rendered pairs from rigs the prior does not model: rough heads, swapped cameras, cuts.

Also two cameras that see the light differently (:func:`camera_response`): each its own
response curve and vignetting, on top of the renderer's gain and offset.

A hand-assembled stereo head differs from the prior's camera model
(:mod:`domplane_ros.core.prior`) by a small rotation of the right camera about its own centre
(roll about the optical axis, relative pitch) and by its intrinsics (focal length, principal
point). Both act on the right image as a homography ``G``, exactly, whatever the scene depth:
a rotation ``R`` about the centre maps pixels by ``K R K^-1`` and a change of intrinsics by
``K' K^-1``. So a rendered pair becomes a rough-rig pair by warping its right image with
``G = K' R K^-1`` and its true floor homography becomes ``G H``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from typing import Sequence

import cv2
from domplane_ros.core.homography import apply_homography
from domplane_ros.sim.generators import scene_sequence
from domplane_ros.sim.model import StereoFrame
from domplane_ros.sim.truth import every_floor_pixel, transfer_error_px
import numpy as np


@dataclass(frozen=True)
class RigError:
    """How a rough head differs from the prior's model (the right camera's deviations).

    Attributes:
        roll_deg: Rotation of the right camera about its optical axis, degrees.
        pitch_deg: Relative pitch of the right camera, degrees (a vertical offset of about
            ``f * tan(pitch)`` pixels).
        focal_ratio: Right focal length over left focal length (1.03: a 3 % mismatch).
        principal_offset_px: ``(dx, dy)`` shift of the right principal point, pixels.
    """

    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    focal_ratio: float = 1.0
    principal_offset_px: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        """Check the values are finite and the focal ratio positive.

        Raises:
            ValueError: If a value is non-finite or ``focal_ratio`` is not positive.

        """
        values = (self.roll_deg, self.pitch_deg, self.focal_ratio, *self.principal_offset_px)
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f'rig error values must be finite, got {values!r}')
        if self.focal_ratio <= 0:
            raise ValueError(f'focal_ratio must be positive, got {self.focal_ratio}')


def random_rig_error(rng: np.random.Generator, max_roll_deg: float = 4.0,
                     max_pitch_deg: float = 2.0, max_focal_mismatch: float = 0.03,
                     max_principal_offset_px: float = 10.0) -> RigError:
    """Draw a rough rig uniformly within the given magnitudes (each sign equally likely)."""
    angle = rng.uniform(0.0, 2.0 * math.pi)
    offset = max_principal_offset_px * rng.uniform(0.0, 1.0)
    return RigError(roll_deg=float(rng.uniform(-max_roll_deg, max_roll_deg)),
                    pitch_deg=float(rng.uniform(-max_pitch_deg, max_pitch_deg)),
                    focal_ratio=float(1.0 + rng.uniform(-max_focal_mismatch,
                                                        max_focal_mismatch)),
                    principal_offset_px=(float(offset * math.cos(angle)),
                                         float(offset * math.sin(angle))))


def rig_warp(error: RigError, focal_px: float, width: int, height: int) -> np.ndarray:
    """Return the (3, 3) float64 right-image homography ``G = K' R K^-1`` of a rig error.

    Args:
        error: The right camera's deviations.
        focal_px: The nominal focal length in pixels.
        width: Image width in pixels (principal point at the centre).
        height: Image height in pixels.

    Returns:
        ``G`` with ``G[2, 2] == 1``: a nominal right pixel maps to the rough rig's right pixel.

    """
    cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
    k = np.array([[focal_px, 0.0, cx], [0.0, focal_px, cy], [0.0, 0.0, 1.0]])
    roll, pitch = math.radians(error.roll_deg), math.radians(error.pitch_deg)
    r_roll = np.array([[math.cos(roll), -math.sin(roll), 0.0],
                       [math.sin(roll), math.cos(roll), 0.0], [0.0, 0.0, 1.0]])
    r_pitch = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(pitch), -math.sin(pitch)],
                        [0.0, math.sin(pitch), math.cos(pitch)]])
    dx, dy = error.principal_offset_px
    f2 = focal_px * error.focal_ratio
    k2 = np.array([[f2, 0.0, cx + dx], [0.0, f2, cy + dy], [0.0, 0.0, 1.0]])
    g = k2 @ r_roll @ r_pitch @ np.linalg.inv(k)
    return g / g[2, 2]


def rough_rig(frame: StereoFrame, error: RigError) -> StereoFrame:
    """Return the pair the same scene gives on a rough head, with its ground truth.

    The right image is warped by :func:`rig_warp` (linear interpolation, border black); the
    true homography becomes ``G H``; a left floor pixel stays visible in the right image only
    if ``G H`` maps it inside the image.

    Args:
        frame: A rendered pair from the nominal head.
        error: The rough rig's deviations.

    Returns:
        The rough rig's :class:`StereoFrame` (same left image and masks).

    """
    height, width = frame.left.shape
    g = rig_warp(error, frame.setup.focal_px, width, height)
    right = cv2.warpPerspective(frame.right, g, (width, height), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    h = g @ frame.homography
    h = h / h[2, 2]
    return replace(frame, right=right, homography=h,
                   visible_in_right=frame.visible_in_right & _maps_inside(h, width, height))


def rough_left_rig(frame: StereoFrame, error: RigError) -> StereoFrame:
    """Return the pair the same scene gives with the rough rig's error on the left camera.

    As :func:`rough_rig` with the cameras' roles exchanged: the left image is warped by
    ``G`` (:func:`rig_warp`, linear interpolation, border black), the true homography becomes
    ``H G^-1`` and the left-view masks move with the left image (nearest neighbour; the
    occlusion masks are dropped). The level-head rule reads a left camera's roll against the
    baseline about twice (docs/METHOD.md), a right camera's not at all; this case measures
    that.

    Args:
        frame: A rendered pair from the nominal head.
        error: The rough rig's deviations, applied to the left camera.

    Returns:
        The :class:`StereoFrame` (same right image).

    """
    height, width = frame.left.shape
    g = rig_warp(error, frame.setup.focal_px, width, height)

    def warped(image: np.ndarray, flags: int) -> np.ndarray:
        return cv2.warpPerspective(image, g, (width, height), flags=flags,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def mask(values: np.ndarray) -> np.ndarray:
        return warped(values.astype(np.uint8), cv2.INTER_NEAREST) > 0

    h = frame.homography @ np.linalg.inv(g)
    h = h / h[2, 2]
    return replace(frame, left=warped(frame.left, cv2.INTER_LINEAR), homography=h,
                   plane_left=mask(frame.plane_left), obstacle_left=mask(frame.obstacle_left),
                   visible_in_right=mask(frame.visible_in_right) & _maps_inside(h, width, height),
                   occluded_in_right=None, obstacle_hidden=None)


def swapped(frame: StereoFrame) -> StereoFrame:
    """Return the pair with left and right exchanged; the truth is ``H^-1``.

    The floor masks are moved into the new left view (the old right image) through ``H``;
    pixels of the old right image that no left floor pixel reaches are left out.

    Args:
        frame: A rendered pair.

    Returns:
        The swapped :class:`StereoFrame` (its ``setup`` still names the original head).

    """
    height, width = frame.left.shape
    h = frame.homography
    inverse = np.linalg.inv(h)
    inverse = inverse / inverse[2, 2]
    floor = (frame.plane_left & frame.visible_in_right).astype(np.uint8)
    moved = cv2.warpPerspective(floor, h, (width, height), flags=cv2.INTER_NEAREST) > 0
    obstacle = cv2.warpPerspective(frame.obstacle_left.astype(np.uint8), h, (width, height),
                                   flags=cv2.INTER_NEAREST) > 0
    return replace(frame, left=frame.right, right=frame.left, homography=inverse,
                   plane_left=moved, visible_in_right=moved.copy(), obstacle_left=obstacle)


def camera_response(frame: StereoFrame, rng: np.random.Generator,
                    gamma: tuple[float, float] = (0.75, 1.33),
                    vignetting: tuple[float, float] = (0.15, 0.35)) -> StereoFrame:
    """Return the pair seen through two cameras with their own response and vignetting.

    Each image ``I`` becomes ``255 (I / 255)^g (1 - v r^2)``, rounded and clipped to 8 bits,
    with its own ``g`` (log-uniform in ``gamma``) and ``v`` (uniform in ``vignetting``), ``r``
    the distance to the image centre over the half diagonal: the corners are ``v`` darker. The
    geometry and the truth are unchanged. Combine it with :func:`random_scene`'s ``gain`` and
    ``offset`` for a right camera that is also exposed differently.

    Args:
        frame: A rendered pair.
        rng: Source of the two cameras' draws (left first).
        gamma: Range of the response exponents.
        vignetting: Range of the darkening at the image corners.

    Returns:
        The :class:`StereoFrame` with both images changed.

    """
    images = []
    for image in (frame.left, frame.right):
        exponent = float(np.exp(rng.uniform(math.log(gamma[0]), math.log(gamma[1]))))
        darkening = float(rng.uniform(*vignetting))
        height, width = image.shape
        ys, xs = np.mgrid[0:height, 0:width]
        r2 = (((xs - 0.5 * (width - 1)) ** 2 + (ys - 0.5 * (height - 1)) ** 2)
              / (0.25 * (width ** 2 + height ** 2)))
        value = 255.0 * (image / 255.0) ** exponent * (1.0 - darkening * r2)
        images.append(np.clip(np.rint(value), 0, 255).astype(np.uint8))
    return replace(frame, left=images[0], right=images[1])


def cut_sequence(n_before: int, n_after: int, seed: int, width: int = 640, height: int = 480,
                 floors: Sequence[str | None] = (None, None)) -> list[StereoFrame]:
    """Return two unrelated rendered sequences joined: a cut at index ``n_before``.

    The two halves differ in scene, floor and camera set-up (seeds ``2 * seed`` and
    ``2 * seed + 1``): a saccade, a re-plugged camera or two recordings joined.
    """
    first = scene_sequence(n_before, seed=2 * seed, width=width, height=height, floor=floors[0])
    second = scene_sequence(n_after, seed=2 * seed + 1, width=width, height=height,
                            floor=floors[1])
    return list(first) + list(second)


def plane_error_px(frame: StereoFrame, homography: np.ndarray | None) -> float:
    """Return the mean transfer distance to the truth over the visible floor, pixels."""
    pixels = every_floor_pixel(frame)
    return transfer_error_px(homography, frame, pixels[::max(1, pixels.shape[0] // 4000)])


def _maps_inside(h: np.ndarray, width: int, height: int) -> np.ndarray:
    ys, xs = np.mgrid[0:height, 0:width]
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    mapped = apply_homography(h, pts)
    inside = ((mapped[:, 0] >= 0) & (mapped[:, 0] <= width - 1)
              & (mapped[:, 1] >= 0) & (mapped[:, 1] <= height - 1))
    return inside.reshape(height, width)
