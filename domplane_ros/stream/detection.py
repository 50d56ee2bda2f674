"""Features of one pair at its working resolution, and the way back to full pixels.

The pipeline detects corners (and line segments) on the working level of each image
(:mod:`domplane_ros.core.pyramid`, ``features.max_width``); the estimator, the prior, the
verification and the acceptance checks work in full pixels. These helpers do the detection as
``features.kind`` asks and scale its results (and the mask) back to the full image.
"""

from __future__ import annotations

from dataclasses import replace
import functools

import cv2
from domplane_ros.config import FeatureConfig, MaskConfig, PlaneNodeConfig, PriorConfig
from domplane_ros.core.features import corners_in_region, detect_corners, Features
from domplane_ros.core.lines import detect_lines
from domplane_ros.core.mask import parallax_mask, ParallaxMask
from domplane_ros.core.pyramid import detector_block, level_homography, WorkingImage
from domplane_ros.stream.motion import enough_carried
import numpy as np


def detect_features(left: WorkingImage, right: WorkingImage, cfg: PlaneNodeConfig
                    ) -> tuple[Features, tuple[np.ndarray, np.ndarray]]:
    """Return corners and segments (full pixels) as ``features.kind`` asks.

    Detected on the working level (:mod:`domplane_ros.core.pyramid`) and scaled to full
    pixels. Also returns the working-level corners, which the tracker uses.
    """
    kind = cfg.features.kind
    none_pts = np.zeros((0, 2))
    if kind == 'lines':
        corners = (none_pts, none_pts)
        left_pts = right_pts = none_pts
    else:
        features = level_features(cfg.features, left.level)
        corners = (detect_corners(left.image, features),
                   detect_corners(right.image, features))
        left_pts, right_pts = (full_corners(image, points)
                               for image, points in zip((left, right), corners))
    left_seg, right_seg = _segments(left, right, cfg)
    return Features(left_pts, right_pts, left_seg, right_seg), corners


def carried_features(left: WorkingImage, right: WorkingImage,
                     tracked: tuple[np.ndarray, np.ndarray], counts: tuple[int, int],
                     cfg: PlaneNodeConfig
                     ) -> tuple[Features, tuple[np.ndarray, np.ndarray],
                                tuple[np.ndarray, np.ndarray]] | None:
    """Return the features of a pair whose corners were tracked from an earlier pair.

    The tracked positions (working pixels) outside the detector's region of interest and
    border are dropped (:func:`~domplane_ros.core.features.corners_in_region`; no sub-pixel
    re-refinement: it did not make them more accurate, docs/speed.md). None if
    too few are left of the earlier pair's ``counts`` (:func:`~domplane_ros.stream.motion.
    enough_carried`): then the pair detects afresh. Else segments are detected as
    :func:`detect_features` does, and the working-level corners (which the tracker uses next)
    and the indices of the tracked positions kept are returned too.
    """
    features = level_features(cfg.features, left.level)
    kept = tuple(corners_in_region(image.image, points, features)
                 for image, points in zip((left, right), tracked))
    corners = (tracked[0][kept[0]], tracked[1][kept[1]])
    if not enough_carried(corners, counts):
        return None
    left_pts, right_pts = (full_corners(image, points)
                           for image, points in zip((left, right), corners))
    left_seg, right_seg = _segments(left, right, cfg)
    return Features(left_pts, right_pts, left_seg, right_seg), corners, (kept[0], kept[1])


@functools.lru_cache(maxsize=16)
def level_features(features: FeatureConfig, level: int) -> FeatureConfig:
    """Return the corner detector's settings on pyramid ``level``.

    ``features.block_size`` keeps its extent in full pixels
    (:func:`~domplane_ros.core.pyramid.detector_block`); the other sizes are at the level.
    """
    block = detector_block(features.block_size, level)
    return features if block == features.block_size else replace(features, block_size=block)


def _segments(left: WorkingImage, right: WorkingImage, cfg: PlaneNodeConfig
              ) -> tuple[np.ndarray, np.ndarray]:
    """Return both images' segments (full pixels) as ``features.kind`` asks."""
    if cfg.features.kind == 'points':
        return np.zeros((0, 4)), np.zeros((0, 4))
    return (left.scale * detect_lines(left.image, cfg.features),
            right.scale * detect_lines(right.image, cfg.features))


def full_corners(image: WorkingImage, corners: np.ndarray) -> np.ndarray:
    """Return working-level corners in full pixels."""
    return corners if image.level == 0 else image.scale * corners


def full_mask(image: WorkingImage, mask: np.ndarray) -> np.ndarray:
    """Return a working-level mask at the full image's size (nearest neighbour)."""
    if image.level == 0:
        return mask
    height, width = image.full.shape
    return cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST)


def level_mask(left: np.ndarray, right: np.ndarray, scale: float, homography: np.ndarray,
               mask: MaskConfig, prior: PriorConfig) -> ParallaxMask:
    """Return the parallax mask of a plane on working-level images (``scale`` full pixels each).

    The homography is in full pixels; it and the prior's focal range and principal point are
    brought to the working level, as the published mask and the near-field rule need.
    """
    return parallax_mask(left, right, level_homography(homography, scale), mask,
                         tuple(f / scale for f in prior.focal_px),
                         tuple(c / scale for c in prior.principal_point_px))
