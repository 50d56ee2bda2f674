"""The disparity slope of a plane homography: the ground of a correctly ordered head, or not.

:func:`swap_evidence` checks whether a plane that verifies well was found for swapped cameras.
For a ground plane seen by a correctly ordered head the plane's disparity ``x - H(x)`` grows
toward the bottom of the image (nearer floor); for swapped cameras ``H`` is the inverse and the
disparity shrinks toward the bottom; a wall facing the head has none. The photometric side of
a plane's verdict is :mod:`domplane_ros.core.verification`.

Nothing here imports ROS; the functions take numpy arrays and return frozen values.
"""

from __future__ import annotations

from dataclasses import dataclass

from domplane_ros.core.homography import as_valid_homography
import numpy as np


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
