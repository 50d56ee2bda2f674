"""One plane or several: how far a plane's own pixels are from it, by dense flow.

The verification (:mod:`~domplane_ros.core.verification`) works at a quarter of the image width
with probes a few working pixels wide, so a plane fitted through surfaces at several depths
whose disparities differ by a few pixels (the far field of a room behind a board) passes it
as one plane. :func:`residual_flow_px` looks closer: the right image is warped into the left
view by the plane and aligned to the left image by DIS optical flow at up to
:data:`WIDTH_PX` columns; the median flow left over the plane's supporting pixels is near 0 on
one plane and about a pixel on a fit through several. Measured on rendered boards in front of
a room (``sim/boards.py``, tuning seeds 0-8, 10, 15, 29): the true board 0.02-0.08 px, the
planes through the room that a search published instead 0.42-1.13 px.

Nothing here imports ROS.
"""

from __future__ import annotations

import cv2
import numpy as np

# Largest image width of the flow, pixels (wider images are reduced; the flow is scaled back).
WIDTH_PX = 640


def residual_flow_px(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                     support: np.ndarray, flow: cv2.DISOpticalFlow | None = None) -> float:
    """Return the median residual flow over a plane's supporting pixels, full pixels.

    Args:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        homography: (3, 3) float64 left-to-right plane homography.
        support: (h, w) bool supporting pixels of the plane at any scale of the left image
            (the verification's ``AgreementMaps.support``).
        flow: A DIS flow object to reuse (medium preset if None).

    Returns:
        The median length of the flow left after warping, in full-resolution pixels; inf
        when no supporting pixel is left.

    Raises:
        ValueError: If the images differ in size or are not 2-D.

    """
    if left.ndim != 2 or left.shape != right.shape:
        raise ValueError(f'need two 2-D images of one size, got {left.shape} and {right.shape}')
    height, width = left.shape
    scale = min(1.0, WIDTH_PX / width)
    to_small = np.diag([scale, scale, 1.0])
    small = (max(1, int(round(width * scale))), max(1, int(round(height * scale))))
    small_l = cv2.resize(left, small, interpolation=cv2.INTER_AREA) if scale < 1 else left
    small_r = cv2.resize(right, small, interpolation=cv2.INTER_AREA) if scale < 1 else right
    hom = to_small @ np.asarray(homography, np.float64) @ np.linalg.inv(to_small)
    warped = cv2.warpPerspective(small_r, hom, small,
                                 flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    if flow is None:
        flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    residual = flow.calc(small_l, warped, None)
    mask = cv2.resize(np.asarray(support, np.uint8), small,
                      interpolation=cv2.INTER_NEAREST) > 0
    if not mask.any():
        return float('inf')
    lengths = np.hypot(residual[..., 0], residual[..., 1])[mask]
    return float(np.median(lengths)) / scale
