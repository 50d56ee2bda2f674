"""The mask before issue 12 (local NCC after the plane warp), kept as the evaluation's baseline.

A frozen copy of ``core/mask.py``'s ``plane_mask`` as it was (defaults: scale 0.5, 7 x 7
windows, NCC 0.8, texture 3 grey levels, 5 px clean-up, enclosed low-texture regions filled),
so that :mod:`domplane_ros.tools.evaluate_mask` measures today's figures and the residual
parallax mask's in one run. Not used by the library.
"""

from __future__ import annotations

import cv2
from domplane_ros.core.homography import as_valid_homography, resize_homography
from domplane_ros.core.image import check_gray
from domplane_ros.core.mask import OBSTACLE, PLANE, UNKNOWN
import numpy as np

SCALE = 0.5
WINDOW_PX = 7
NCC_THRESHOLD = 0.8
MIN_TEXTURE = 3.0
MORPH_PX = 5
_FILL_OUTLINE_SHARE = 0.95


def _resize(image: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    height, width = image.shape
    new_w, new_h = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    if (new_w, new_h) == (width, height):
        return image, np.eye(3)
    small = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_AREA)
    return small, resize_homography(new_w / width, new_h / height)


def _fill_enclosed(labels: np.ndarray, fillable: np.ndarray) -> None:
    count, components = cv2.connectedComponents(fillable.astype(np.uint8), connectivity=4)
    if count <= 1:
        return
    grown = cv2.dilate(components.astype(np.float32), np.ones((3, 3), np.uint8)).astype(
        np.int32)
    outline = (grown > 0) & (components == 0)
    ids = grown[outline]
    is_plane = labels[outline] == PLANE
    total = np.bincount(ids, minlength=count)
    plane = np.bincount(ids, weights=is_plane, minlength=count)
    border = np.zeros(count, bool)
    for edge in (components[0], components[-1], components[:, 0], components[:, -1]):
        border[edge] = True
    fill = (plane >= _FILL_OUTLINE_SHARE * np.maximum(total, 1)) & (total > 0) & ~border
    fill[0] = False
    labels[fill[components]] = PLANE


def ncc_mask(left: np.ndarray, right: np.ndarray, homography: np.ndarray) -> np.ndarray:
    """Return the (H, W) uint8 labels of the NCC mask (255 plane, 127 obstacle, 0 unknown)."""
    left = check_gray(left, 'left')
    right = check_gray(right, 'right')
    hom = as_valid_homography(homography)
    height, width = left.shape
    left_small, scale_left = _resize(left, SCALE)
    right_small, scale_right = _resize(right, SCALE)
    small_h, small_w = left_small.shape
    hom_small = scale_right @ hom @ np.linalg.inv(scale_left)
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    warped = cv2.warpPerspective(right_small, hom_small, (small_w, small_h), flags=flags)
    inside = cv2.warpPerspective(np.full(right_small.shape, 255, np.uint8), hom_small,
                                 (small_w, small_h), flags=flags)
    valid = cv2.erode(inside, np.ones((WINDOW_PX, WINDOW_PX), np.uint8),
                      borderType=cv2.BORDER_CONSTANT, borderValue=0) == 255
    labels = _ncc_labels(left_small, warped, valid)
    _open_and_close(labels, valid)
    _fill_enclosed(labels, (labels == UNKNOWN) & valid)
    if (small_h, small_w) != (height, width):
        labels = cv2.resize(labels, (width, height), interpolation=cv2.INTER_NEAREST_EXACT)
    return labels


def _ncc_labels(left: np.ndarray, warped: np.ndarray, valid: np.ndarray) -> np.ndarray:
    a = left.astype(np.float32)
    b = warped.astype(np.float32)
    size = (WINDOW_PX, WINDOW_PX)
    mean_a = cv2.blur(a, size)
    mean_b = cv2.blur(b, size)
    var_a = cv2.blur(a * a, size) - mean_a * mean_a
    var_b = cv2.blur(b * b, size) - mean_b * mean_b
    cov = cv2.blur(a * b, size) - mean_a * mean_b
    min_var = MIN_TEXTURE ** 2
    textured = (var_a >= min_var) & (var_b >= min_var) & (var_a > 0) & (var_b > 0)
    decided = valid & textured
    bound = NCC_THRESHOLD * np.sqrt(np.maximum(var_a * var_b, 0.0))
    on_plane = decided & (cov >= bound)
    labels = np.full(left.shape, UNKNOWN, np.uint8)
    labels[decided] = OBSTACLE
    labels[on_plane] = PLANE
    return labels


def _open_and_close(labels: np.ndarray, valid: np.ndarray) -> None:
    square = np.ones((MORPH_PX, MORPH_PX), np.uint8)
    for value in (OBSTACLE, PLANE):
        region = (labels == value).astype(np.uint8)
        cleaned = cv2.morphologyEx(region, cv2.MORPH_OPEN, square)
        cleaned = cv2.morphologyEx(cleaned, cv2.MORPH_CLOSE, square)
        labels[(region == 1) & (cleaned == 0)] = UNKNOWN
        claim = (cleaned == 1) & (region == 0) & valid
        if value == PLANE:
            claim &= labels == UNKNOWN
        labels[claim] = value
