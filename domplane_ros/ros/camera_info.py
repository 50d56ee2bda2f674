"""The camera model of an optional ``sensor_msgs/CameraInfo``, as prior parameters.

Duck-typed like :mod:`domplane_ros.core.image` (reads ``k``, ``width``, ``height``,
``binning_x``, ``binning_y``), so it takes rclpy and rosbags messages and needs no ROS import.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np

_MAX_ASPECT_MISMATCH = 0.05  # relative fx/fy difference above which K is not square pixels


@dataclass(frozen=True)
class CameraModel:
    """The focal length and principal point of a calibrated camera, in image pixels.

    Attributes:
        focal_px: Focal length in pixels (mean of fx and fy).
        principal_px: Principal point ``(cx, cy)`` in pixels.
        aspect_mismatch: ``|fx - fy| / max(fx, fy)``; the prior assumes square pixels.

    """

    focal_px: float
    principal_px: tuple[float, float]
    aspect_mismatch: float

    def prior_values(self, focal_tolerance: float) -> dict[str, list[float]]:
        """Return the prior parameters this model gives: focal range and principal point.

        Args:
            focal_tolerance: Relative tolerance ``t``: ``prior.focal_px`` is
                ``f * [1 - t, 1 + t]``.

        Returns:
            ``{'prior.focal_px': [low, high], 'prior.principal_point_px': [cx, cy]}``.

        """
        return {'prior.focal_px': [self.focal_px * (1.0 - focal_tolerance),
                                   self.focal_px * (1.0 + focal_tolerance)],
                'prior.principal_point_px': [self.principal_px[0], self.principal_px[1]]}


def camera_model(msg: Any) -> CameraModel:
    """Read the focal length and principal point from a CameraInfo's ``K``.

    ``binning_x`` / ``binning_y`` above 1 divide K's row as image_pipeline does; the image
    size, when given (non-zero), must hold the principal point.

    Args:
        msg: A ``sensor_msgs/CameraInfo`` like object.

    Returns:
        The camera model.

    Raises:
        ValueError: With a one-line reason: K missing or not 9 values, non-finite, zero (an
            uncalibrated camera publishes K = 0), a non-positive focal length, a principal
            point outside the image, or fx and fy more than 5 % apart.

    """
    k = [float(v) for v in getattr(msg, 'k', ())]
    if len(k) != 9:
        raise ValueError(f'camera_info K has {len(k)} values, expected 9')
    if not all(math.isfinite(v) for v in k):
        raise ValueError('camera_info K holds non-finite values')
    if not any(k):
        raise ValueError('camera_info K is all zero (the camera is not calibrated)')
    bin_x = max(int(getattr(msg, 'binning_x', 0) or 0), 1)
    bin_y = max(int(getattr(msg, 'binning_y', 0) or 0), 1)
    fx, cx, fy, cy = k[0] / bin_x, k[2] / bin_x, k[4] / bin_y, k[5] / bin_y
    if fx <= 0 or fy <= 0:
        raise ValueError(f'camera_info K has a non-positive focal length (fx {fx:g}, fy {fy:g})')
    mismatch = abs(fx - fy) / max(fx, fy)
    if mismatch > _MAX_ASPECT_MISMATCH:
        raise ValueError(f'camera_info K has fx {fx:g} and fy {fy:g} more than 5 % apart; '
                         'the prior assumes square pixels')
    width = int(getattr(msg, 'width', 0) or 0) / bin_x
    height = int(getattr(msg, 'height', 0) or 0) / bin_y
    if cx < 0 or cy < 0 or (width > 0 and cx > width) or (height > 0 and cy > height):
        raise ValueError(f'camera_info principal point ({cx:g}, {cy:g}) is outside the '
                         f'{width:g}x{height:g} image')
    return CameraModel(0.5 * (fx + fy), (cx, cy), mismatch)


class CameraInfoTracker:
    """The K last applied to the prior: each distinct K is applied once (node and replay)."""

    def __init__(self) -> None:
        """Start with no K applied."""
        self._applied: tuple[float, ...] | None = None

    def new_values(self, model: CameraModel, focal_tolerance: float
                   ) -> dict[str, list[float]] | None:
        """Return ``model``'s prior values if its K differs from the last applied, else None.

        ``focal_tolerance``: ``camera_info.focal_tolerance`` (:meth:`CameraModel.prior_values`).
        The K counts as applied once returned (the caller applies it or reports why not).
        """
        key = (model.focal_px, *model.principal_px)
        if self._applied is not None and np.allclose(key, self._applied, rtol=1e-6):
            return None
        self._applied = key
        return model.prior_values(focal_tolerance)

    @staticmethod
    def describe(model: CameraModel, values: dict[str, list[float]],
                 focal_tolerance: float) -> str:
        """Return the one line saying what the prior became."""
        low, high = values['prior.focal_px']
        return (f'prior from camera_info: focal_px [{low:.1f}, {high:.1f}] (f '
                f'{model.focal_px:.1f} +-{100 * focal_tolerance:g} %), principal point '
                f'({model.principal_px[0]:.1f}, {model.principal_px[1]:.1f})')
