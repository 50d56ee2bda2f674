"""The residual parallax after the plane warp, measured densely (:mod:`domplane_ros.core.mask`).

:func:`local_fit` gives, per pixel of the working image, the one-step one-dimensional
Lucas-Kanade shift along the epipolar direction (the image x axis for the prior's head; or,
with ``one_sided``, the shift under linear interpolation, true to scale, and its confidence) with
the window statistics that say whether to trust it (zero-shift normalised correlation, left
window variance), and the coarse shift of DIS optical flow for large parallax;
:func:`shifted_ncc` the correlation of the same windows with the warped image moved by a
per-pixel shift (the coarse flow's, to test it against the zero shift);
:func:`matcher_shift` the signed residual parallax of OpenCV's stereo matchers
(``cv2.StereoBM``, ``cv2.StereoSGBM``) around zero (docs/MASK.md round 12). The float
images are this thread's :func:`~domplane_ros.core.scratch.scratch` arrays: a
:class:`LocalFit` is valid until the next call in the same thread.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
from domplane_ros.core.scratch import constant, scratch
import numpy as np

# Regulariser of the one-step estimate, grey levels^2 per pixel^2 (windows without texture
# across the epipolar direction fall back to zero shift).
_REGULARISER = 2.0
# Confidence a window's one-sided shift needs to be measured: the window variance of the image
# difference along the epipolar direction, grey levels^2 per pixel^2 (docs/MASK.md round 10).
MIN_GRADIENT_ENERGY = 2.0
# A normal's standard deviation over its median absolute value, with the window mean's share
# of a 5 x 5 window's noise put back (sqrt(25 / 24)).
_MAD_TO_SIGMA = 1.4826 * 1.0206
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
        energy: (h, w) float32 confidence of a one-sided ``shift`` (:func:`local_fit` with
            ``one_sided``): the window variance of the image difference along the epipolar
            direction it was read on (grey levels^2 per pixel^2; below
            :data:`MIN_GRADIENT_ENERGY` no shift was measured); None for the one-step shift.
        noise: The pixel noise of the image difference ``warped - gain left`` (grey levels,
            :func:`pixel_noise` over the ``valid`` pixels :func:`local_fit` was given) of a
            one-sided fit, 0 otherwise: a one-sided shift's standard error is
            ``noise / (window sqrt(energy))`` working pixels (docs/MASK.md round 11).
    """

    shift: np.ndarray
    ncc: np.ndarray
    variance: np.ndarray
    flow_shift: np.ndarray
    mean: np.ndarray
    energy: np.ndarray | None = None
    noise: float = 0.0


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
              coarse: np.ndarray | None = None, one_sided: bool = False,
              valid: np.ndarray | None = None) -> LocalFit:
    """Return the one-step 1-D Lucas-Kanade shift and the zero-shift NCC of every window.

    With ``g`` the mean x gradient of both images and ``e`` the difference of the two
    images after removing each window's mean, the shift that aligns them is
    ``sum(g e) / (sum(g^2) + regulariser)`` (Gauss-Newton from zero shift); with
    ``one_sided``, :func:`_one_sided_shift`'s shift and confidence instead (true to scale;
    docs/MASK.md round 10). Float32 OpenCV calls into this thread's scratch arrays (module
    docstring).

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        window: Side of the square window, pixels.
        coarse: (h, w) float32 :func:`flow_shift` of the images if already measured (it is
            global: the mask measures it on the whole images and fits only the rows it
            needs); None to measure it here.
        one_sided: Measure the shift by :func:`_one_sided_shift` (with its confidence).
        valid: (h, w) bool pixels inside the right image, to read the pixel noise of a
            one-sided fit on (:func:`pixel_noise`); None: no noise read (0).

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
    energy = None
    noise = 0.0
    if one_sided:
        shift, energy, zero_residual = _one_sided_shift(left, warped, mean_a, mean_b, size)
        if valid is not None:
            noise = pixel_noise(zero_residual, valid)
    else:
        shift = _one_step_shift(left, warped, mean_a, mean_b, size)
    if coarse is None:
        coarse = flow_shift(left, warped)
    return LocalFit(shift=shift, ncc=ncc, variance=var_a, flow_shift=coarse,
                    mean=mean_a, energy=energy, noise=noise)


def _one_step_shift(left: np.ndarray, warped: np.ndarray, mean_a: np.ndarray,
                    mean_b: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Return the one-step shift of :func:`local_fit` ((h, w) float32 scratch, working px)."""
    shape = left.shape
    f32 = cv2.CV_32F
    tmp = scratch('tmp', shape)
    # The Sobel filter is linear: one pass over a + b gives the sum of both gradients.
    grad = cv2.Sobel(cv2.add(left, warped, dst=tmp, dtype=f32), f32, 1, 0,
                     dst=scratch('var_b', shape), ksize=3, scale=0.0625)
    diff = cv2.subtract(warped, left, dst=scratch('diff', shape), dtype=f32)
    diff -= mean_b
    diff += mean_a
    num = _window_product(grad, diff, size, diff)
    den = _window_product(grad, grad, size, mean_b)
    den += np.float32(_REGULARISER)
    shift = cv2.divide(num, den, dst=num)
    return shift


def _one_sided_shift(left: np.ndarray, warped: np.ndarray, mean_a: np.ndarray,
                     mean_b: np.ndarray, size: tuple[int, int]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the window's residual parallax under linear interpolation, and its confidence.

    A shift ``u`` of the warped image between whole pixels is what linear interpolation
    makes of it (``cv2.remap``, ``cv2.resize`` by area at the working scale for whole
    full-resolution pixels): ``warped(x + u) = warped(x) + u d(x)`` with ``d`` the forward
    difference for ``u >= 0`` and the backward one for ``u <= 0``. Per side, the least-squares
    ``u`` with an offset (``cov(d, gain left - warped) / var(d)`` over the window, ``gain`` the
    ratio of the images' standard deviations: a one-sided difference correlates with the
    image, so a gain left in the difference would read as a shift) is clamped to its
    side (the minimum of a convex quadratic on a half-line), and the side that explains more
    of the difference wins: the shift reads sub-pixel shifts true to scale (docs/MASK.md
    round 10), where the centred gradient of both images with a regulariser read half of
    them on the rendered floors. The residual parallax is ``-u`` (a point nearer than the
    plane shows at ``x - r`` in the warped image).

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        mean_a: (h, w) float32 window mean of ``left``.
        mean_b: (h, w) float32 window mean of ``warped``.
        size: The window ``(side, side)``.

    Returns:
        (h, w) float32 residual parallax, working pixels (positive: nearer than the plane;
        0 where the confidence is below :data:`MIN_GRADIENT_ENERGY`: the zero-shift
        correlation alone judges such a window), and (h, w) float32 its confidence: the
        window variance of the chosen side's ``d`` (grey levels^2 per pixel^2; the shift's
        noise is the difference's pixel noise over the square root of it and of the
        window's pixel count). Scratch arrays. And the zero-shift residual, the difference
        ``warped - gain left`` less its window mean at every fourth pixel ((ceil(h/4),
        ceil(w/4)) float32, a fresh array; :func:`pixel_noise`).

    """
    shape = left.shape
    if shape[1] < 2:  # no difference along x: nothing measured
        nothing = np.zeros(shape, np.float32)
        return nothing, nothing.copy(), np.zeros(((shape[0] + 3) // 4, 1), np.float32)
    f32 = cv2.CV_32F
    tmp = scratch('tmp', shape)
    gain = _gain(left, warped)
    diff = cv2.addWeighted(warped, 1.0, left, -gain, 0.0, dst=scratch('diff', shape), dtype=f32)
    mean_diff = cv2.addWeighted(mean_b, 1.0, mean_a, -gain, 0.0,
                                dst=scratch('mean_diff', shape))
    zero_residual = diff[::4, ::4] - mean_diff[::4, ::4]
    step = scratch('step', shape)  # d(x) = warped(x + 1) - warped(x); 0 in the last column
    cv2.subtract(warped[:, 1:], warped[:, :-1], dst=step[:, :-1], dtype=f32)
    step[:, -1] = 0.0
    # The window mean of d is the difference of the window means one pixel apart.
    step_mean = scratch('step_mean', shape)
    cv2.subtract(mean_b[:, 1:], mean_b[:, :-1], dst=step_mean[:, :-1])
    step_mean[:, -1] = 0.0
    energy = _window_product(step, step, size, scratch('energy', shape))
    energy -= cv2.multiply(step_mean, step_mean, dst=tmp)
    ahead = _window_product(step, diff, size, scratch('ahead', shape))
    ahead -= cv2.multiply(step_mean, mean_diff, dst=tmp)
    # The backward difference at x is d(x - 1): its products with the difference at x.
    behind = scratch('behind', shape)
    cv2.multiply(step[:, :-1], diff[:, 1:], dst=behind[:, 1:])
    behind[:, 0] = 0.0
    cv2.blur(behind, size, dst=behind)
    cv2.multiply(step_mean[:, :-1], mean_diff[:, 1:], dst=tmp[:, 1:])
    tmp[:, 0] = 0.0
    behind -= tmp
    # r = -u: the forward side holds r <= 0, the backward side r >= 0 (clamped to 0), each
    # over its own variance (the backward one's is the forward one's a pixel to the left).
    floor = constant(1e-6, shape, np.float32)
    zero = constant(0.0, shape, np.float32)
    cv2.min(ahead, zero, dst=ahead)
    cv2.max(behind, zero, dst=behind)
    back_energy = scratch('back_energy', shape)
    back_energy[:, 1:] = energy[:, :-1]
    back_energy[:, 0] = energy[:, 0]
    cv2.divide(ahead, cv2.max(energy, floor, dst=tmp), dst=tmp)
    cv2.divide(behind, cv2.max(back_energy, floor, dst=diff), dst=diff)
    # The side that explains more of the difference: the larger covariance times shift.
    chosen = cv2.compare(cv2.multiply(ahead, tmp, dst=ahead),
                         cv2.multiply(behind, diff, dst=behind), cv2.CMP_GT)
    shift = cv2.copyTo(tmp, chosen, diff)
    cv2.copyTo(energy, chosen, back_energy)
    # Too little texture along the epipolar direction: no shift measured (zero; the
    # zero-shift correlation alone judges the window).
    cv2.copyTo(zero, (back_energy < np.float32(MIN_GRADIENT_ENERGY)).view(np.uint8), shift)
    return shift, back_energy, zero_residual


def pixel_noise(zero_residual: np.ndarray, valid: np.ndarray) -> float:
    """Return the pixel noise of the image difference (grey levels) at zero shift.

    The robust spread (1.4826 times the median absolute value) of the zero-shift residual
    (:func:`_one_sided_shift`, every fourth pixel) over the pixels in ``valid`` ((h, w) bool),
    corrected for the window mean it has lost: on the plane (most of a view below the
    horizon) the difference at zero shift is noise, and the median ignores the obstacles.
    0 without such pixels.
    """
    values = np.abs(zero_residual[valid[::4, ::4]])
    if values.size == 0:
        return 0.0
    middle = values.size // 2  # the upper median: np.median's sort is six times slower
    return _MAD_TO_SIGMA * float(np.partition(values, middle)[middle])


def _gain(left: np.ndarray, warped: np.ndarray) -> float:
    """Return the ratio of the warped image's standard deviation to the left one's (0.5-2)."""
    _, std_left = cv2.meanStdDev(left)
    _, std_warped = cv2.meanStdDev(warped)
    if std_left[0, 0] < 1.0:
        return 1.0
    return float(np.clip(std_warped[0, 0] / std_left[0, 0], 0.5, 2.0))


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
                        small: np.ndarray, linear_range_px: float) -> np.ndarray:
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
        small: (h, w) bool pixels with a small shift that looks trusted: measurable, within
            ``linear_range_px``, the zero-shift NCC at least the mask's ``ncc_threshold``.
        linear_range_px: The one-step estimate's range, working pixels.

    Returns:
        (h, w) bool, pixels with a small, trusted-looking shift that the flow's shift beats.

    """
    candidates = small & (np.abs(fit.flow_shift) >= linear_range_px)
    rows = np.flatnonzero(candidates.any(axis=1))
    if rows.size == 0:
        return candidates
    band = slice(int(rows[0]), int(rows[-1]) + 1)
    # The zero shift's best window within a pixel (a 3 x 3 maximum of its NCC): next to an
    # obstacle's edge a ground pixel's own window reaches over the edge, a neighbour's need not.
    zero = cv2.dilate(fit.ncc, _SQUARE_3)[band]
    candidates[band] &= shifted_ncc(left, warped, fit, band, window) > zero
    return candidates


# Stereo matchers on (left, warped) (docs/MASK.md round 12): disparities
# MATCHER_MIN_PX .. MATCHER_MIN_PX + MATCHER_COUNT - 1 working pixels (OpenCV's disparity
# is the residual parallax: a point nearer than the plane shows at x - r in the warped image),
# square block of _MATCHER_BLOCK_PX, uniqueness ratio _MATCHER_UNIQUENESS (per cent), the
# block matcher's texture threshold _MATCHER_TEXTURE.
MATCHER_MIN_PX = -16
MATCHER_COUNT = 32
_MATCHER_BLOCK_PX = 7
_MATCHER_UNIQUENESS = 10
_MATCHER_TEXTURE = 10
_SGBM_BLOCK_PX = 3
# StereoSGBM's smoothness penalties per block pixel (OpenCV's sample: 8 and 32) and its mode.
_SGBM_P1 = 8
_SGBM_P2 = 32
_SGBM_MODE = cv2.STEREO_SGBM_MODE_SGBM_3WAY


def _stereo_matcher(kind: str, minimum: int, count: int) -> cv2.StereoMatcher:
    """Return a new OpenCV matcher: ``'block'`` StereoBM, ``'semi_global'`` StereoSGBM 3-way."""
    if kind == 'block':
        matcher = cv2.StereoBM_create(numDisparities=count, blockSize=_MATCHER_BLOCK_PX)
        matcher.setMinDisparity(minimum)
        matcher.setUniquenessRatio(_MATCHER_UNIQUENESS)
        matcher.setTextureThreshold(_MATCHER_TEXTURE)
        matcher.setSpeckleWindowSize(0)
        matcher.setDisp12MaxDiff(-1)
        return matcher
    if kind == 'semi_global':
        block = _SGBM_BLOCK_PX
        return cv2.StereoSGBM_create(minDisparity=minimum, numDisparities=count,
                                     blockSize=block, P1=_SGBM_P1 * block * block,
                                     P2=_SGBM_P2 * block * block, disp12MaxDiff=-1,
                                     uniquenessRatio=_MATCHER_UNIQUENESS, speckleWindowSize=0,
                                     mode=_SGBM_MODE)
    raise ValueError(f'unknown matcher {kind!r}')


def matcher_shift(left: np.ndarray, warped: np.ndarray, kind: str = 'block',
                  minimum: int | None = None, count: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Return the residual parallax of an OpenCV stereo matcher and where it was measured.

    The matcher searches the signed shifts ``minimum .. minimum + count - 1`` (working pixels;
    ``count`` a multiple of 16) around zero on the left and the warped image, both padded by
    replicating their side columns so that the image's own columns are searched over the whole
    range (OpenCV leaves the columns whose search runs past a side unmatched). Its disparity
    ``d`` says ``left(x) ~ warped(x - d)``: the residual parallax, positive nearer than the
    plane (1/16 pixel steps). Where the matcher finds no match (too little texture, a second
    best match too close, OpenCV's invalid value ``(minimum - 1) * 16``) or the match lies on
    the range's ends, nothing is measured.

    Args:
        left: (h, w) uint8 left image at the working scale.
        warped: (h, w) uint8 right image warped into the left view.
        kind: ``'block'`` (``cv2.StereoBM``) or ``'semi_global'`` (``cv2.StereoSGBM``).
        minimum: Smallest shift searched, working pixels (negative: farther than the plane);
            None: :data:`MATCHER_MIN_PX`.
        count: Number of shifts searched, a positive multiple of 16; None:
            :data:`MATCHER_COUNT`.

    Returns:
        (h, w) float32 residual parallax, working pixels (0 where not measured), and (h, w)
        bool where it was measured.

    Raises:
        ValueError: If ``kind`` is not a matcher's name or ``count`` not a positive multiple
            of 16.

    """
    minimum = MATCHER_MIN_PX if minimum is None else int(minimum)
    count = MATCHER_COUNT if count is None else int(count)
    if count <= 0 or count % 16:
        raise ValueError(f'count must be a positive multiple of 16, got {count}')
    height, width = left.shape
    pad = max(-minimum, minimum + count, 0) + _MATCHER_BLOCK_PX
    if height < _MATCHER_BLOCK_PX:
        return np.zeros((height, width), np.float32), np.zeros((height, width), bool)
    padded_left = cv2.copyMakeBorder(left, 0, 0, pad, pad, cv2.BORDER_REPLICATE)
    padded_warped = cv2.copyMakeBorder(warped, 0, 0, pad, pad, cv2.BORDER_REPLICATE)
    disparity = _stereo_matcher(kind, minimum, count).compute(padded_left, padded_warped)
    disparity = disparity[:, pad:pad + width]
    measured = (disparity > 16 * minimum) & (disparity < 16 * (minimum + count - 1))
    shift = disparity.astype(np.float32)
    shift *= np.float32(1.0 / 16.0)
    shift[~measured] = 0.0
    return shift, measured
