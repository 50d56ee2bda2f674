"""The residual parallax after the plane warp, measured densely (:mod:`domplane_ros.core.mask`).

:func:`local_fit` gives, per pixel of the working image, the one-step one-dimensional
Lucas-Kanade shift along the epipolar direction (the image x axis for the prior's head) with
the window statistics that say whether to trust it (zero-shift normalised correlation, left
window variance), and the coarse shift of DIS optical flow for large parallax;
:func:`shifted_ncc` the correlation of the same windows with the warped image moved by a
per-pixel shift (the coarse flow's, to test it against the zero shift). The float
images are this thread's :func:`~domplane_ros.core.scratch.scratch` arrays: a
:class:`LocalFit` is valid until the next call in the same thread.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
from domplane_ros.core.scratch import scratch
import numpy as np

# Regulariser of the one-step estimate, grey levels^2 per pixel^2 (windows without texture
# across the epipolar direction fall back to zero shift).
_REGULARISER = 2.0
# DIS settings over the ultrafast preset (see _dis_flow).
_DIS_FINEST_SCALE = 1
_DIS_PATCH_STRIDE = 8
_SQUARE_3 = np.ones((3, 3), np.uint8)
# Working images smaller than twice this (pixels) get DIS at their own size, smaller than
# it none.
_DIS_MIN_SIZE = 32


@dataclass(frozen=True)
class LocalFit:
    """Per-pixel window statistics of the left and warped right images (working scale).

    Attributes:
        shift: (h, w) float32 signed one-step residual parallax, working pixels (positive:
            nearer than the plane).
        ncc: (h, w) float32 zero-shift normalised correlation.
        variance: (h, w) float32 grey-level variance of the left window.
        flow_shift: (h, w) float32 signed residual parallax from DIS optical flow, working
            pixels: coarse, but not limited to small shifts.
        mean: (h, w) float32 grey-level mean of the left window.
    """

    shift: np.ndarray
    ncc: np.ndarray
    variance: np.ndarray
    flow_shift: np.ndarray
    mean: np.ndarray


def _dis_flow() -> cv2.DISOpticalFlow:
    """Return a new DIS optical flow object (ultrafast preset, finest scale 1, stride 8).

    The preset's finest scale 2 leaves one flow vector per 16 working pixels at the half
    size it runs on: tall near objects (poles, boxes) then drag the ground's flow by several
    pixels (median 3.3 working pixels on rendered seed 3's floor). Finest scale 1 with
    non-overlapping 8-pixel patches measures the ground within 0.1-0.2 px in the median for
    about 0.1 ms more at 640x480.

    A new one per call (creating it costs microseconds): a reused object keeps state between
    calls on small images, so the same pair would not always give the same mask.
    """
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST)
    flow.setFinestScale(_DIS_FINEST_SCALE)
    flow.setPatchStride(_DIS_PATCH_STRIDE)
    return flow


def local_fit(left: np.ndarray, warped: np.ndarray, window: int,
              coarse: np.ndarray | None = None) -> LocalFit:
    """Return the one-step 1-D Lucas-Kanade shift and the zero-shift NCC of every window.

    With ``g`` the mean x gradient of both images and ``e`` the difference of the two
    images after removing each window's mean, the shift that aligns them is
    ``sum(g e) / (sum(g^2) + regulariser)`` (Gauss-Newton from zero shift). Float32 OpenCV
    calls into this thread's scratch arrays (module docstring).

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        window: Side of the square window, pixels.
        coarse: (h, w) float32 :func:`flow_shift` of the images if already measured (it is
            global: the mask measures it on the whole images and fits only the rows it
            needs); None to measure it here.

    Returns:
        The :class:`LocalFit`; its arrays are scratch arrays, valid until the next call.

    """
    shape = left.shape
    size = (window, window)
    f32 = cv2.CV_32F
    tmp = scratch('tmp', shape)
    mean_a = cv2.boxFilter(left, f32, size, dst=scratch('mean_a', shape))
    mean_b = cv2.boxFilter(warped, f32, size, dst=scratch('mean_b', shape))
    # Products of the uint8 images straight into float32 (no float copies of the images).
    var_a = _window_product(left, left, size, scratch('var_a', shape))
    var_a -= cv2.multiply(mean_a, mean_a, dst=tmp)
    var_b = _window_product(warped, warped, size, scratch('var_b', shape))
    var_b -= cv2.multiply(mean_b, mean_b, dst=tmp)
    cov = _window_product(left, warped, size, scratch('ncc', shape))
    cov -= cv2.multiply(mean_a, mean_b, dst=tmp)
    norm = cv2.multiply(var_a, var_b, dst=tmp)
    np.maximum(norm, np.float32(1e-6), out=norm)
    ncc = cv2.divide(cov, cv2.sqrt(norm, dst=norm), dst=cov)
    # The Sobel filter is linear: one pass over a + b gives the sum of both gradients.
    grad = cv2.Sobel(cv2.add(left, warped, dst=tmp, dtype=f32), f32, 1, 0, dst=var_b, ksize=3,
                     scale=0.0625)
    diff = cv2.subtract(warped, left, dst=scratch('diff', shape), dtype=f32)
    diff -= mean_b
    diff += mean_a
    num = _window_product(grad, diff, size, diff)
    den = _window_product(grad, grad, size, mean_b)
    den += np.float32(_REGULARISER)
    shift = cv2.divide(num, den, dst=num)
    if coarse is None:
        coarse = flow_shift(left, warped)
    return LocalFit(shift=shift, ncc=ncc, variance=var_a, flow_shift=coarse,
                    mean=mean_a)


def _window_product(first: np.ndarray, second: np.ndarray, size: tuple[int, int],
                    out: np.ndarray) -> np.ndarray:
    """Return the window mean of ``first * second`` in ``out`` ((h, w) float32)."""
    cv2.multiply(first, second, dst=out, dtype=cv2.CV_32F)
    return cv2.blur(out, size, dst=out)


def flow_shift(left: np.ndarray, warped: np.ndarray,
               halves: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Return the signed x shift (working pixels) of DIS optical flow at half the working size.

    Only large parallax is read from it, so half the resolution serves and costs a quarter.
    ``halves`` are ``cv2.pyrDown`` of both images if the caller has them. The result is a
    scratch array above the smallest sizes (module docstring).
    """
    height, width = left.shape
    if min(height, width) < _DIS_MIN_SIZE:
        return np.zeros(left.shape, np.float32)  # too small for a pyramid: no coarse flow
    if min(height, width) < 2 * _DIS_MIN_SIZE:
        flow = _dis_flow().calc(left, warped, None)
        return -flow[..., 0]
    half_left, half_warped = halves or (cv2.pyrDown(left), cv2.pyrDown(warped))
    # A fresh flow array: DIS starts from the content of one passed in.
    flow = _dis_flow().calc(half_left, half_warped, None)
    out = cv2.resize(cv2.extractChannel(flow, 0), (width, height),
                     dst=scratch('flow_x', left.shape), interpolation=cv2.INTER_LINEAR)
    out *= np.float32(-2.0)
    return out


def shifted_ncc(left: np.ndarray, warped: np.ndarray, fit: LocalFit, rows: slice,
                window: int) -> np.ndarray:
    """Return the NCC of the left windows with the warped image moved by the coarse flow.

    The warped image is sampled at ``x - round(fit.flow_shift)`` (a point nearer than the
    plane with residual parallax ``r`` shows at ``x - r``; the nearest pixel, as the flow is
    coarse), so where the flow is the true residual parallax the windows agree. Computed on
    ``rows`` only, with the window's reach around them; the left windows' mean and variance
    are the fit's. Its own scratch arrays: the fit's stay untouched; the result is one of
    them, valid until the next call in the same thread.

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        fit: The :func:`local_fit` of these images (``mean``, ``variance``, ``flow_shift``).
        rows: The rows wanted, ``slice(start, stop)`` within ``0 .. h``.
        window: Side of the fit's square window, pixels.

    Returns:
        (stop - start, w) float32 normalised correlation of those rows.

    """
    height, width = left.shape
    half = window // 2
    top, bottom = max(0, rows.start - half), min(height, rows.stop + half)
    shape = (bottom - top, width)
    map_x = cv2.subtract(np.arange(width, dtype=np.float32)[None, :].repeat(shape[0], axis=0),
                         fit.flow_shift[top:bottom], dst=scratch('shifted_x', shape))
    map_y = scratch('shifted_y', shape)
    map_y[:] = np.arange(top, bottom, dtype=np.float32)[:, None]
    moved = cv2.remap(warped, map_x, map_y, cv2.INTER_NEAREST,
                      dst=scratch('shifted', shape, np.uint8), borderMode=cv2.BORDER_REPLICATE)
    band = left[top:bottom]
    size = (window, window)
    tmp = scratch('shifted_tmp', shape)
    mean_b = cv2.boxFilter(moved, cv2.CV_32F, size, dst=scratch('shifted_mean', shape))
    var_b = _window_product(moved, moved, size, scratch('shifted_var', shape))
    var_b -= cv2.multiply(mean_b, mean_b, dst=tmp)
    cov = _window_product(band, moved, size, scratch('shifted_ncc', shape))
    cov -= cv2.multiply(fit.mean[top:bottom], mean_b, dst=tmp)
    norm = cv2.multiply(fit.variance[top:bottom], var_b, dst=var_b)
    np.maximum(norm, np.float32(1e-6), out=norm)
    ncc = cv2.divide(cov, cv2.sqrt(norm, dst=norm), dst=cov)
    return ncc[rows.start - top:rows.stop - top]


def beyond_linear_range(left: np.ndarray, warped: np.ndarray, fit: LocalFit, window: int,
                        measurable: np.ndarray, ncc_threshold: float,
                        linear_range_px: float) -> np.ndarray:
    """Return (h, w) bool: small one-step shifts that the coarse flow's shift explains better.

    The one-step estimate holds within ``linear_range_px`` of zero. A window moved by
    several pixels can still correlate at zero shift (a smooth box face: 0.7-0.94 on the
    tuning scenes, where the ground gives 0.94-1) and then measures a small shift. Where the
    coarse flow puts the shift beyond the linear range, the window is correlated again at
    the flow's shift (:func:`shifted_ncc`): where it agrees better there than the best of the
    pixel's and its eight neighbours' windows at zero shift, the small shift is not to be
    trusted (docs/MASK.md, round 8). The neighbours' windows keep the ground beside an
    obstacle: its own window reaches over the obstacle's edge and can match better at the
    obstacle's shift.

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        fit: Their :func:`local_fit`.
        window: Side of the fit's square window, pixels.
        measurable: (h, w) bool pixels whose shift could be measured at all.
        ncc_threshold: Zero-shift NCC a small shift needs to be trusted.
        linear_range_px: The one-step estimate's range, working pixels.

    Returns:
        (h, w) bool, pixels with a small, trusted-looking shift that the flow's shift beats.

    """
    candidates = measurable & (np.abs(fit.shift) < linear_range_px)
    candidates &= fit.ncc >= np.float32(ncc_threshold)
    candidates &= np.abs(fit.flow_shift) >= linear_range_px
    rows = np.flatnonzero(candidates.any(axis=1))
    if rows.size == 0:
        return candidates
    band = slice(int(rows[0]), int(rows[-1]) + 1)
    # The zero shift's best window within a pixel (a 3 x 3 maximum of its NCC): next to an
    # obstacle's edge a ground pixel's own window reaches over the edge, a neighbour's need not.
    zero = cv2.dilate(fit.ncc, _SQUARE_3)[band]
    candidates[band] &= shifted_ncc(left, warped, fit, band, window) > zero
    return candidates
