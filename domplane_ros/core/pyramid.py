"""The working resolution: detect and track on a pyramid level, estimate in full pixels.

The cost of corner detection, line detection and tracking grows with the number of pixels,
the estimator's with the number of features. :func:`working_level` picks the Gaussian pyramid
level (each level halves the image with ``cv2.pyrDown``) whose width is at most
``features.max_width``; :class:`WorkingImage` holds that level of one image. Features found
there (sub-pixel corners, segments) are scaled to full-resolution pixels: level ``L`` pixel
``x`` is full pixel ``2^L x``, as ``cv2.pyrDown`` centres output pixel ``i`` on input pixel
``2 i``. The estimator, the prior, the verification and the mask work in full-resolution
pixels as before, so thresholds in pixels keep their meaning.

Refining the scaled corners on the full image (``cv2.cornerSubPix``, windows of 3 to 7 px,
3 or 10 iterations) did not pay: on rendered 1280 x 720 sequences (max_width 640) the median
transfer error was 0.182 px with it and 0.174 px without (0.133 px at full resolution), so
the corners are used as scaled.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


def working_level(width: int, max_width: int, height: int = 0,
                  max_megapixels: float = 0.0) -> int:
    """Return the pyramid level at most ``max_width`` wide and ``max_megapixels`` large.

    Args:
        width: Image width, pixels.
        max_width: Largest working width, pixels; 0: no width limit.
        height: Image height, pixels (only used with ``max_megapixels``).
        max_megapixels: Largest working image, millions of pixels; 0: no size limit.

    Returns:
        The smallest ``L >= 0`` whose level (``ceil(width / 2^L)`` by ``ceil(height / 2^L)``,
        as ``cv2.pyrDown`` rounds) meets both limits (0 if both are 0).

    """
    level = 0
    max_pixels = 1e6 * max_megapixels
    while width > 1 and ((0 < max_width < width)
                         or (max_pixels > 0 and width * height > max_pixels)):
        width, height = (width + 1) // 2, (height + 1) // 2
        level += 1
    return level


def detector_block(block_size: int, level: int) -> int:
    """Return the corner detector's window at ``level`` for ``block_size`` full pixels.

    The window keeps its extent in full-resolution pixels (odd, at least 3): on rendered
    1280x720 sequences detected on level 1, a 3-pixel window gave 0.140 px median transfer
    error against 0.188 px with the full-resolution 5 (0.145 px at full resolution);
    docs/speed.md, fifth round.
    """
    if level == 0:
        return block_size
    return max(3, (block_size >> level) | 1)


@dataclass(frozen=True)
class WorkingImage:
    """One image at its working resolution.

    Attributes:
        full: (H, W) uint8 the full-resolution image.
        image: (h, w) uint8 the working level (``full`` itself at level 0).
        level: The pyramid level; full pixel = ``scale`` * working pixel.
    """

    full: np.ndarray
    image: np.ndarray
    level: int

    @property
    def scale(self) -> float:
        """Return ``2^level``: full-resolution pixels per working pixel."""
        return float(1 << self.level)

    @classmethod
    def of(cls, gray: np.ndarray, max_width: int, max_megapixels: float = 0.0
           ) -> WorkingImage:
        """Return ``gray`` reduced to the level :func:`working_level` picks for its size."""
        level = working_level(gray.shape[1], max_width, gray.shape[0], max_megapixels)
        image = gray
        for _ in range(level):
            image = cv2.pyrDown(image)
        return cls(gray, image, level)


def scale_matrix(scale: float) -> np.ndarray:
    """Return the (3, 3) float64 map from working to full pixels, ``diag(s, s, 1)``."""
    return np.diag([scale, scale, 1.0])


def motion_to_full(motion: np.ndarray, scale: float) -> np.ndarray:
    """Return a working-level image homography ``M`` in full pixels: ``S M S^-1``.

    Args:
        motion: (3, 3) float64 homography between working-level images.
        scale: Full pixels per working pixel.

    Returns:
        (3, 3) float64 the same map between full-resolution images.

    """
    if scale == 1.0:
        return motion
    s = scale_matrix(scale)
    return s @ motion @ np.diag([1.0 / scale, 1.0 / scale, 1.0])


def level_homography(homography: np.ndarray, scale: float) -> np.ndarray:
    """Return a full-pixel plane homography between working-level images: ``S^-1 H S``.

    Args:
        homography: (3, 3) float64 left-to-right homography in full pixels.
        scale: Full pixels per working pixel.

    Returns:
        (3, 3) float64 the same plane's homography in working pixels.

    """
    if scale == 1.0:
        return homography
    return motion_to_full(homography, 1.0 / scale)
