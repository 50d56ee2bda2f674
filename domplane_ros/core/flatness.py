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

Through an uncorrected lens no homography fits a board exactly: on rendered boards through
radial lenses (``sim/boards.py``, ``lens=True``, tuning seeds 0-29) the true large boards' median
rose to 0.07-0.66 px. :func:`lens_residual_px` fits what a plane seen through two radial
lenses leaves to the flow, and :func:`one_plane_residual_px` takes the lesser median: true
boards through the lens 0.02-0.23 px, fits through the room 0.36-1.04 px.

Nothing here imports ROS.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import cv2
import numpy as np

# Largest image width of the flow, pixels (wider images are reduced; the flow is scaled back).
WIDTH_PX = 640
# Powers of the radial terms of lens_residual_px (r^2 (x - c): k1) and the share of the
# supporting pixels its second fit keeps.
RADIAL_POWERS = (2,)
TRIM_KEEP = 0.8


@dataclass(frozen=True)
class ResidualFlow:
    """The flow left after warping the right image into the left view by a plane.

    Attributes:
        flow: (h, w, 2) float32 DIS flow at the working scale (left pixel ``x`` matches the
            warped right image at ``x + flow``), working pixels.
        support: (h, w) bool the plane's supporting pixels at the working scale.
        homography: (3, 3) float64 the plane at the working scale.
        scale: Working pixels per full pixel.
    """

    flow: np.ndarray
    support: np.ndarray
    homography: np.ndarray
    scale: float


def residual_flow(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                  support: np.ndarray, flow: cv2.DISOpticalFlow | None = None) -> ResidualFlow:
    """Return the :class:`ResidualFlow` of a plane (arguments as :func:`residual_flow_px`).

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
    return ResidualFlow(residual, mask, hom, scale)


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
    return _median_px(residual_flow(left, right, homography, support, flow))


def _median_px(residual: ResidualFlow) -> float:
    """Return the median residual flow length over the support, full pixels (inf if none)."""
    if not residual.support.any():
        return float('inf')
    lengths = np.hypot(residual.flow[..., 0], residual.flow[..., 1])[residual.support]
    return float(np.median(lengths)) / residual.scale


def lens_residual_px(residual: ResidualFlow, radial: Sequence[int] = RADIAL_POWERS,
                     keep: float = TRIM_KEEP) -> float:
    """Return the median residual flow left by a plane seen through two radial lenses.

    The supporting pixels' residual flow is fitted by least squares with what a plane seen
    through two lenses leaves after any homography: a change of the homography (the 8
    first-order terms of ``H (I + E)``) and each camera's radial distortion about the image
    centre (``r^p (x - c)`` for each power ``p`` of ``radial``, the right camera's moved into
    the left view by the Jacobian of ``H^-1``); refitted on the ``keep`` share of the pixels
    it fits best. A plane through surfaces at several depths leaves steps no such smooth field
    follows; one plane through an uncorrected lens leaves almost nothing.

    Returns:
        The median length of what the fit leaves, full pixels; inf with fewer than four
        supporting pixels per term fitted.

    """
    ys, xs = np.nonzero(residual.support)
    if xs.size < 4 * (8 + 2 * len(radial)):
        return float('inf')
    height, width = residual.support.shape
    centre = np.array([0.5 * (width - 1), 0.5 * (height - 1)])
    norm = math.hypot(centre[0], centre[1])
    left_px = np.column_stack([xs, ys]).astype(np.float64)
    u = (left_px - centre) / norm
    hom = residual.homography
    mapped = hom @ np.column_stack([left_px, np.ones(xs.size)]).T
    right_px = (mapped[:2] / mapped[2]).T
    v = (right_px - centre) / norm
    inverse = np.linalg.inv(hom)
    jac = _jacobians(inverse, right_px)
    zero, one = np.zeros(xs.size), np.ones(xs.size)
    ux, uy = u[:, 0], u[:, 1]
    columns = [(one, zero), (zero, one), (ux, zero), (uy, zero), (zero, ux), (zero, uy),
               (-ux * ux, -ux * uy), (-ux * uy, -uy * uy)]
    r_left = np.hypot(ux, uy)
    r_right = np.hypot(v[:, 0], v[:, 1])
    for power in radial:
        columns.append((ux * r_left ** power, uy * r_left ** power))
        right = np.einsum('nij,nj->ni', jac, v * (r_right ** power)[:, None])
        columns.append((right[:, 0], right[:, 1]))
    design = np.vstack([np.concatenate(pair) for pair in columns]).T
    target = np.concatenate([residual.flow[ys, xs, 0], residual.flow[ys, xs, 1]]).astype(
        np.float64)
    raw = np.hypot(target[:xs.size], target[xs.size:])
    rows = raw <= np.quantile(raw, keep)  # the first fit without the flow's worst outliers
    for _ in range(2):
        both = np.concatenate([rows, rows])
        coef, *_ = np.linalg.lstsq(design[both], target[both], rcond=None)
        left_over = target - design @ coef
        lengths = np.hypot(left_over[:xs.size], left_over[xs.size:])
        rows = lengths <= np.quantile(lengths, keep)
    return float(np.median(lengths)) / residual.scale


def one_plane_residual_px(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                          support: np.ndarray, flow: cv2.DISOpticalFlow | None = None) -> float:
    """Return how far a plane's supporting pixels are from one plane seen through a lens.

    The lesser of the median residual flow (:func:`residual_flow_px`) and the median of what
    the fit of two radial lenses leaves (:func:`lens_residual_px`), full pixels (arguments as
    :func:`residual_flow_px`; inf without supporting pixels). Measured on rendered boards seen
    through lenses (``sim/boards.py``, ``lens=True``, tuning seeds; docs/METHOD.md).
    """
    residual = residual_flow(left, right, homography, support, flow)
    plain = _median_px(residual)
    return plain if math.isinf(plain) else min(plain, lens_residual_px(residual))


def _jacobians(hom: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Return the (N, 2, 2) Jacobians of the homography at (N, 2) points."""
    p = hom @ np.column_stack([points, np.ones(len(points))]).T
    w = p[2]
    jac = np.empty((len(points), 2, 2))
    for row in range(2):
        for col in range(2):
            jac[:, row, col] = (hom[row, col] * w - p[row] * hom[2, col]) / (w * w)
    return jac
