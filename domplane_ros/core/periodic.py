"""Period vectors of a texture: where a periodic pattern repeats, for its look-alike planes.

On a periodic texture (a checkerboard, tiles, planks) a plane one or more periods off the true
one matches most of the pattern too, and a search that never judged the true plane can publish
the look-alike (measured on OpenCV chessboard pair 13: a plane 72 px off, two squares along
the board's diagonal, matching two thirds of the board). :func:`period_vectors` finds the
pattern's repeat vectors from the autocorrelation of the image over the plane's support, so
that the plane's siblings (the plane moved by those vectors, refined) can be judged beside it:
the true plane explains the board's border and the rest of the pattern, a look-alike does not.

Nothing here imports ROS; numpy arrays in, numpy arrays out.
"""

from __future__ import annotations

import cv2
import numpy as np

# Least normalised autocorrelation of a repeat (1 at zero shift): a checkerboard or tiled
# texture gives 0.5-0.9 at its period, blobby noise under 0.3 beyond its central lobe.
MIN_PEAK = 0.4
# Shifts shorter than this (pixels) are the central lobe, not a period.
MIN_SHIFT_PX = 3.0
# Least drop of the correlation half-way to a repeat below its value at the repeat.
MIN_DIP = 0.3
# Least share of the support overlapping itself at a shift for the shift to be measured.
MIN_OVERLAP = 0.3


def period_vectors(image: np.ndarray, mask: np.ndarray, count: int = 2) -> np.ndarray:
    """Return up to ``count`` repeat vectors of ``image`` over ``mask``, strongest first.

    The zero-mean image over the mask's bounding box (0 off the mask) is autocorrelated by
    FFT and normalised by the mask's own overlap at each shift; the strongest local maxima at
    least :data:`MIN_SHIFT_PX` from zero, above :data:`MIN_PEAK` and with a dip of
    :data:`MIN_DIP` half-way to them are the repeats, the shortest first. A second vector is
    kept only if it is not along the first (a multiple of the same period).

    Args:
        image: (H, W) grey image (any real dtype).
        mask: (H, W) bool pixels of the pattern (a plane's support).
        count: Most vectors returned.

    Returns:
        (K, 2) float64 vectors ``(dx, dy)`` in pixels, ``dx >= 0``, K <= ``count`` (0 when the
        texture does not repeat or the mask is empty).

    Raises:
        ValueError: If the image is not 2-D or the mask's shape differs.

    """
    image = np.asarray(image)
    mask = np.asarray(mask, bool)
    if image.ndim != 2 or mask.shape != image.shape:
        raise ValueError(f'need a 2-D image and a mask of its shape, got {image.shape} and '
                         f'{mask.shape}')
    ys, xs = np.nonzero(mask)
    if ys.size < 16:
        return np.zeros((0, 2))
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    patch = image[y0:y1, x0:x1].astype(np.float64)
    inside = mask[y0:y1, x0:x1].astype(np.float64)
    patch = (patch - patch[inside > 0].mean()) * inside
    shape = (2 * patch.shape[0], 2 * patch.shape[1])
    corr = _autocorrelation(patch, shape)
    overlap = _autocorrelation(inside, shape)
    with np.errstate(divide='ignore', invalid='ignore'):
        norm = (corr / corr[0, 0]) * (overlap[0, 0] / overlap)
    norm[~(overlap >= MIN_OVERLAP * overlap[0, 0])] = -1.0
    norm = np.fft.fftshift(norm)
    centre = np.array([shape[1] // 2, shape[0] // 2])
    dy, dx = np.mgrid[0:shape[0], 0:shape[1]]
    near = np.hypot(dx - centre[0], dy - centre[1]) < MIN_SHIFT_PX
    # The local maxima, compared exactly: cv2.dilate in float64. (Against the dilated float32
    # copy, a peak whose float32 rounded up was not its own maximum: the period of a 32 cm
    # checker, rendered floors_rough 23028, was lost or found by how its peak rounded,
    # 0.478594649 in float64, 0.478594661 in float32; compared in float32 on both sides, every
    # member of a float32 plateau was a peak, and a neighbour of a short period's peak could
    # displace the second period.)
    peaks = norm >= cv2.dilate(norm, np.ones((3, 3)))
    peaks &= (norm >= MIN_PEAK) & ~near
    py, px = np.nonzero(peaks)
    # A repeat, not the slope of the central lobe: the correlation dips half-way to it.
    half_y = centre[1] + (py - centre[1]) // 2
    half_x = centre[0] + (px - centre[0]) // 2
    keep = norm[half_y, half_x] <= norm[py, px] - MIN_DIP
    py, px = py[keep], px[keep]
    # A perfect pattern repeats at every multiple of its period alike: the shortest first.
    order = np.argsort(np.hypot(px - centre[0], py - centre[1]))
    out: list[np.ndarray] = []
    for index in order:
        vector = np.array([px[index] - centre[0], py[index] - centre[1]], np.float64)
        if vector[0] < 0 or (vector[0] == 0 and vector[1] < 0):
            vector = -vector
        if any(abs(vector[0] * v[1] - vector[1] * v[0]) < 0.2 * np.dot(v, v) for v in out):
            continue  # along a vector already kept (its multiple, or itself)
        out.append(vector)
        if len(out) == count:
            break
    return np.array(out).reshape(-1, 2)


def _autocorrelation(values: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Return the (unshifted) circular autocorrelation of ``values`` zero-padded to ``shape``."""
    spectrum = np.fft.rfft2(values, s=shape)
    return np.fft.irfft2(spectrum * np.conj(spectrum), s=shape)
