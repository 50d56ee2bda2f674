"""The near field of a new ground plane: its own parallax mask must not call it obstacle.

A plane through distant structure (a level plane through far buildings and cars above a
stretch of road, found in a wide low window of a street scene) can explain the texture of
the image as well as the road does, with a score, bands and a slope that pass every other
check of :class:`~domplane_ros.stream.trust.TrustGate` (session 21's crop 191: 7.3 px off
at confidence 1). What it cannot fake is the road in front of the camera: measured against
such a plane the near road shows the parallax of something nearer than the plane, so the
plane's own residual-parallax mask (:func:`~domplane_ros.core.mask.parallax_mask`, the mask
the pipeline would publish beside it) marks the bottom of the view obstacle. Under the true
ground the bottom of the view is mostly ground.

:func:`near_obstacle_share` reads the mask's bottom third (of the ROI's rows, over its
columns): the share of its measured pixels (plane or obstacle, not unknown) marked obstacle.
:func:`near_field_refusal` refuses a plane whose share is above
``verification.max_near_obstacle`` where at least :data:`MIN_NEAR_MEASURED` of the band is
measured and no ground is seen below the obstacle (below). The pipeline applies it to *new*
planes only (a search's finished winner, a challenger about to replace the lock), never to a
held lock's warm plane: an obstacle that comes close and fills the bottom of the view (a
person in front of the robot) must not drop a lock that every warm check still holds.

Measured in session 22 (docs/BENCHMARKS.md round 23): every correct plane about to be
published read a share of 0.24 or less on the tuning crops and 0.34 or less on the rendered
cases, every wrong plane (> 5 px) with a measured band 0.83 or more. Its limit (review of the
same session): an obstacle that truly fills most of the near field reads the same, so the
true ground was refused in front of a robot's obstacle.

**The ground below the obstacle** (session 23, round 24): an obstacle stands *on* the ground,
so under the true plane the ground is seen below it, between the obstacle and the camera:
the lowest measured pixel of a column of the band is plane. Under a plane through distant
structure the nearest ground is the most off that plane, so the bottom of nearly every
column is obstacle. :func:`ground_below_share` reads, over the band's columns with a
measured pixel, the share whose lowest measured pixel is obstacle; a plane is refused only
where that share too is above :data:`MAX_UNGROUNDED_COLUMNS`. Measured on tuning data
(docs/BENCHMARKS.md round 24): correct planes at most 0.13 (crops 48-247, both priors) and
0.07 (the ``ahead`` case: a wide box in front of the head, tuning seeds 0-39), the wrong plane
of crop 191 1.00, planes 3.4-4.6 px off refused by the rule 0.51-1.00. A box that reaches
below the bottom of the view leaves no ground under it: still refused.
"""

from __future__ import annotations

from typing import Sequence

from domplane_ros.config import MaskConfig, PriorConfig
from domplane_ros.core.pixel_decision import OBSTACLE, PLANE
from domplane_ros.stream.detection import level_mask
import numpy as np

# The least share of the bottom band that must be measured (plane or obstacle) for the rule
# to decide: a band that is almost all unknown (no texture, far) says nothing.
MIN_NEAR_MEASURED = 0.02
# A plane is refused for its near field only where, of the band's columns with a measured
# pixel, more than this share have obstacle as their lowest measured pixel (no ground seen
# below the obstacle): between the correct planes' 0.13 and the refused planes' 0.51 (round
# 24; see the module docstring).
MAX_UNGROUNDED_COLUMNS = 0.3


# A plane whose disparity shrinks toward the image bottom is reported as the floor of swapped
# cameras only where its swapped reading (the right image as the left, the inverse
# homography) marks at least this share of the bottom third plane in its own mask
# (:func:`swapped_ground_share`). Measured (docs/BENCHMARKS.md round 24): the floors of
# swapped cameras (evaluate_trust swapped, tuning seeds 0-12) 0.49-0.90; the faces of wide
# boxes in front of a correctly ordered head (the ``ahead`` case) 0.0: read swapped they lie
# beyond infinity, so every pixel of their mask is unknown.
MIN_SWAPPED_GROUND = 0.1


def _band(labels: np.ndarray, roi: Sequence[float] | None) -> np.ndarray:
    """Return the bottom third of the ROI's rows of ``labels``, over its columns."""
    height, width = labels.shape
    x0, y0, x1, y1 = (0.0, 0.0, 1.0, 1.0) if roi is None else roi
    top, bottom = int(round(y0 * height)), int(round(y1 * height))
    return labels[bottom - max(1, (bottom - top) // 3):bottom,
                  int(round(x0 * width)):int(round(x1 * width))]


def near_obstacle_share(labels: np.ndarray, roi: Sequence[float] | None = None
                        ) -> tuple[float, float]:
    """Return the bottom third's measured share and the obstacle share of what is measured.

    Args:
        labels: (H, W) uint8 mask labels (255 plane, 127 obstacle, 0 unknown).
        roi: ``(x0, y0, x1, y1)`` as fractions of the image, or None for the whole image:
            the band is the lowest third of its rows, over its columns.

    Returns:
        ``(measured, obstacle)``: the band's pixels marked plane or obstacle over all its
        pixels, and those marked obstacle over those measured (0 where none is).

    """
    band = _band(labels, roi)
    if band.size == 0:
        return 0.0, 0.0
    plane = int(np.count_nonzero(band == PLANE))
    obstacle = int(np.count_nonzero(band == OBSTACLE))
    measured = plane + obstacle
    return measured / band.size, (obstacle / measured if measured else 0.0)


def ground_below_share(labels: np.ndarray, roi: Sequence[float] | None = None) -> float:
    """Return the share of the bottom third's columns whose lowest measured pixel is obstacle.

    Args:
        labels: (H, W) uint8 mask labels (255 plane, 127 obstacle, 0 unknown).
        roi: As :func:`near_obstacle_share`.

    Returns:
        Over the band's columns with a pixel marked plane or obstacle, the share whose
        lowest such pixel is obstacle (no ground seen below it); 0 where no column has one.

    """
    band = _band(labels, roi)
    measured = (band == PLANE) | (band == OBSTACLE)
    seen = measured.any(axis=0)
    if not seen.any():
        return 0.0
    # The lowest measured row of each column: the first True from the bottom.
    lowest = band.shape[0] - 1 - np.argmax(measured[::-1], axis=0)
    columns = np.flatnonzero(seen)
    return float(np.mean(band[lowest[columns], columns] == OBSTACLE))


def swapped_ground_share(left: np.ndarray, right: np.ndarray, scale: float,
                         homography: np.ndarray, mask: MaskConfig, prior: PriorConfig,
                         roi: Sequence[float] | None) -> float:
    """Return the share of the bottom third that a plane's swapped reading marks plane.

    The plane read as the floor of swapped cameras: the right image as the left, the
    inverse homography, its own parallax mask (as :func:`near_field_refusal`'s). The floor of
    swapped cameras is the ground of that reading and fills its near field; a surface facing
    a correctly ordered head (a wall, an obstacle's face close ahead: its disparity also
    shrinks toward the image bottom) lies beyond infinity in it and is unknown throughout.

    Args:
        left: (h, w) uint8 left image at the working level (as given).
        right: (h', w') uint8 right image at the working level (as given).
        scale: Full-resolution pixels per working pixel.
        homography: (3, 3) the plane's left-to-right homography in full pixels.
        mask: The mask's settings.
        prior: The camera set-up ranges.
        roi: The features' ROI (fractions), or None.

    Returns:
        The band's pixels marked plane over all its pixels, [0, 1].

    """
    inverse = np.linalg.inv(np.asarray(homography, np.float64))
    inverse /= inverse[2, 2]
    band = _band(level_mask(right, left, scale, inverse, mask, prior).labels, roi)
    return float(np.count_nonzero(band == PLANE)) / band.size if band.size else 0.0


def near_field_refusal(left: np.ndarray, right: np.ndarray, scale: float,
                       homography: np.ndarray, mask: MaskConfig, prior: PriorConfig,
                       roi: Sequence[float] | None, max_share: float) -> str:
    """Return why a new ground plane is refused for its near field ('' if it is not).

    Args:
        left: (h, w) uint8 left image at the working level.
        right: (h', w') uint8 right image at the working level.
        scale: Full-resolution pixels per working pixel.
        homography: (3, 3) the plane's homography in full pixels.
        mask: The mask's settings (the mask the pipeline would publish).
        prior: The camera set-up ranges (the mask's plane at infinity).
        roi: The features' ROI (fractions), or None.
        max_share: ``verification.max_near_obstacle``; 1 or more: off.

    """
    if max_share >= 1.0:
        return ''
    labels = level_mask(left, right, scale, homography, mask, prior).labels
    measured, share = near_obstacle_share(labels, roi)
    if measured < MIN_NEAR_MEASURED or share <= max_share:
        return ''
    ungrounded = ground_below_share(labels, roi)
    if ungrounded <= MAX_UNGROUNDED_COLUMNS:
        return ''
    return (f'not the ground: its own mask marks {100 * share:.0f} % of the measured bottom '
            f'of the view obstacle (> verification.max_near_obstacle {max_share:g}) with no '
            f'ground below it in {100 * ungrounded:.0f} % of its columns; a plane through '
            'distant structure above the ground?')
