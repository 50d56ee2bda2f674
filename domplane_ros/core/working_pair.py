"""A stereo pair shrunk to a working width, with the right image's no-data border.

The verification (:mod:`domplane_ros.core.verification`) judges many planes on one pair at a
width of a few hundred pixels or less: :func:`shrink_pair` shrinks both images once (pyrDown,
then area averaging, or from a pyramid level the pipeline has already made) and keeps the
pixel maps from the full images, and :func:`no_data_valid` marks where the right image has no
data.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
from domplane_ros.core.homography import resize_homography
import numpy as np

__all__ = ['NO_DATA_GROW_PX', 'WorkingPair', 'no_data_valid', 'shrink_pair']

# The right image's no-data border (with the verification's NO_DATA_BORDER): the pixels of
# value exactly 0 (at the working scale, after the shrink) connected to the image's edge,
# grown by NO_DATA_GROW_PX working pixels over the values the shrink mixed with them (each
# pyrDown's 5-tap kernel reaches 1 pixel of its output, the chain 1 + 1/2 + 1/4 + ... < 2;
# grown by 1, the real rough rig 26001 kept its road at 0.20). A warp or a rectification with
# alpha > 0 leaves such a border where the camera's image has no data (the evaluation's rig
# errors warp the right image so: tools/evaluation/real_rigs.py, sim/rigs.py); a left pixel
# mapped onto it cannot be seen by both cameras, and counting it against the plane refused the
# true road of real rough rigs (docs/BENCHMARKS.md rounds 30-31). Dark scene clipped to 0 along
# the edge counts alike: it is flat in the right image, so no plane could be verified on it.
NO_DATA_GROW_PX = 2


@dataclass(frozen=True)
class WorkingPair:
    """A pair shrunk to a working width, to verify several planes on it.

    Attributes:
        left: (h, w) uint8 left image at the working width.
        left_map: (3, 3) pixel map from the full left image to ``left``.
        right: (h', w') uint8 right image at the working width.
        right_map: (3, 3) pixel map from the full right image to ``right``.
        full_shape: (H, W) of the full images.
        width: The working width it was made for.
        right_valid: (h', w') float32 1 where ``right`` has data, 0 on its no-data border
            (:func:`no_data_valid`); None: every pixel.
    """

    left: np.ndarray
    left_map: np.ndarray
    right: np.ndarray
    right_map: np.ndarray
    full_shape: tuple[int, int]
    width: int
    right_valid: np.ndarray | None = None


def shrink_pair(left: np.ndarray, right: np.ndarray, width: int,
                levels: tuple[np.ndarray, np.ndarray, int] | None = None,
                no_data: bool = True) -> WorkingPair:
    """Return the pair shrunk to ``width`` columns (the right image to its share of it).

    Args:
        left: (H, W) uint8 left image (checked by the caller).
        right: (H', W') uint8 right image.
        width: The working width, pixels.
        levels: ``(left level, right level, L)``: the images ``cv2.pyrDown`` L times; the
            shrink starts from them when it halves at least L times, and gives the same
            images as from the full ones.
        no_data: Mark the right image's no-data border (:func:`no_data_valid`); False:
            ``right_valid`` is None.

    Raises:
        ValueError: If a level's shape is not the L-th pyrDown's.

    """
    left_level = right_level = None
    if levels is not None:
        left_level, right_level = (levels[0], levels[2]), (levels[1], levels[2])
    left_small, scale_left = _shrink(left, width, left_level)
    right_small, scale_right = _shrink(right, int(round(
        width * right.shape[1] / left.shape[1])), right_level)
    return WorkingPair(left_small, scale_left, right_small, scale_right,
                       (int(left.shape[0]), int(left.shape[1])), int(width),
                       no_data_valid(right_small) if no_data else None)


def no_data_valid(image: np.ndarray) -> np.ndarray | None:
    """Return (h, w) float32 1 where ``image`` has data, 0 on its no-data border; None if none.

    The pixels of value exactly 0 connected (4-neighbours) to the image's edge, grown by
    :data:`NO_DATA_GROW_PX` (see there).
    """
    zero = (image == 0).astype(np.uint8)
    if not (zero[0].any() or zero[-1].any() or zero[:, 0].any() or zero[:, -1].any()):
        return None
    _, labels = cv2.connectedComponents(zero, connectivity=4)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    edge = edge[edge > 0]
    border = np.isin(labels, edge).astype(np.uint8)
    if NO_DATA_GROW_PX > 0:
        side = 2 * NO_DATA_GROW_PX + 1
        border = cv2.dilate(border, np.ones((side, side), np.uint8))
    return (1 - border).astype(np.float32)


def _shrink(image: np.ndarray, width: int, level: tuple[np.ndarray, int] | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Return the image at ``width`` columns (never enlarged) and its (3, 3) pixel map.

    Halves with ``cv2.pyrDown`` (Gaussian, cheaper than area averaging at 640 x 480) while the
    image is at least twice as wide as asked, then area-averages the rest of the way. A
    ``level`` ``(image L times pyrDown-ed, L)`` that this chain passes through is started
    from instead of halving the full image again (the same pixels: the same calls).
    """
    pixel_map = np.eye(3)
    if level is not None and level[1] > 0 and _halvings(image.shape[1], width) >= level[1]:
        start, times = level
        if start.shape != _halved_shape(image.shape, times):
            raise ValueError(f'a pyramid level {times} of a {image.shape} image has shape '
                             f'{_halved_shape(image.shape, times)}, not {start.shape}')
        image = start
        pixel_map = np.diag([0.5 ** times, 0.5 ** times, 1.0])
    while image.shape[1] >= 2 * width:
        image = cv2.pyrDown(image)
        # pyrDown centres output pixel i on input pixel 2 i.
        pixel_map = np.diag([0.5, 0.5, 1.0]) @ pixel_map
    height, full_w = image.shape
    if full_w > width:
        new_h = max(1, int(round(height * width / full_w)))
        image = cv2.resize(image, (width, new_h), interpolation=cv2.INTER_AREA)
        pixel_map = resize_homography(width / full_w, new_h / height) @ pixel_map
    return image, pixel_map


def _halvings(full_width: int, width: int) -> int:
    """Return how many times :func:`_shrink` halves an image ``full_width`` wide."""
    count = 0
    while full_width >= 2 * width:
        full_width, count = (full_width + 1) // 2, count + 1
    return count


def _halved_shape(shape: tuple[int, ...], times: int) -> tuple[int, ...]:
    """Return the shape of ``cv2.pyrDown`` applied ``times`` times to an image of ``shape``."""
    height, width = shape[:2]
    for _ in range(times):
        height, width = (height + 1) // 2, (width + 1) // 2
    return (height, width) + tuple(shape[2:])
