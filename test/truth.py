"""Ground-truth measures shared by tests of several tiers."""

from __future__ import annotations

from domplane_ros.core.homography import apply_homography
import numpy as np


def transfer_error_px(scene, homography: np.ndarray) -> float:
    """Mean distance between the estimate's and the truth's mapping of the plane's pixels."""
    pts = np.argwhere(scene.plane_left & scene.visible_in_right)[:, ::-1].astype(float)
    return float(np.mean(np.linalg.norm(apply_homography(homography, pts)
                                        - apply_homography(scene.homography, pts), axis=1)))
