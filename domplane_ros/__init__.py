"""Dominant ground plane homography from a stereo pair, without correspondences.

The core API: :func:`estimate_plane` (two point sets, an optional initial homography, options)
and :func:`prior_candidates` (candidate homographies from the camera set-up ranges).
"""

from domplane_ros.config import EstimatorConfig, PlaneNodeConfig, PriorConfig
from domplane_ros.core.plane import estimate_plane
from domplane_ros.core.prior import plane_homography, prior_candidates
from domplane_ros.core.result import FailedEstimate, PlaneEstimate

__all__ = [
    'EstimatorConfig', 'FailedEstimate', 'PlaneEstimate', 'PlaneNodeConfig', 'PriorConfig',
    'estimate_plane', 'plane_homography', 'prior_candidates',
]
