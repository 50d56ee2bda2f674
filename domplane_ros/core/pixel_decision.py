"""The mask's per-pixel decision: each pixel's residual parallax measured and classified.

:func:`decide_pixels` is the first half of the work of
:func:`~domplane_ros.core.mask.parallax_mask` on the rows it measures: on the left image and
the right image warped into its view, at the mask's working scale, it measures every pixel's
residual parallax (:mod:`domplane_ros.core.residual`) and labels each pixel by itself
:data:`PLANE`, :data:`OBSTACLE` or :data:`UNKNOWN` (what each means: the module docstring of
:mod:`domplane_ros.core.mask`). What pixels decide together, the clean-up, the floor hidden
from the right camera, the fill of plain regions and the upsampling, follows in
:mod:`domplane_ros.core.mask`, the public entry, which also re-exports the label values and
:data:`NOT_MEASURED` defined here.

The default measurement is the one-step shift, trusted up to :data:`_LINEAR_RANGE_PX`
working pixels where the zero-shift correlation holds and the coarse flow does not match the
window better (:func:`~domplane_ros.core.residual.beyond_linear_range`), and judged against
the threshold alone.

Behind the switch ``_NOISE_AWARE`` (off: it costs 1.2-1.25 times the mask's time, docs/MASK.md
round 11) the small shift is the one-sided one, true to scale, and it is judged knowing its
standard error (the pixel noise over ``window sqrt(confidence)``): plane where the residual
it most probably comes from is below the threshold and the error is small enough to tell,
obstacle only where it clears the threshold by two standard errors, unknown between.

Behind the switch ``_MEASUREMENT`` (``'one_step'``, the default; ``'block'`` or
``'semi_global'``: 1.4 and 1.9 times the mask's time, docs/MASK.md round 12) the residual
parallax is an OpenCV stereo matcher's disparity on the left and warped images (signed shifts
around zero, :func:`~domplane_ros.core.residual.matcher_shift`), averaged with the one-step
shift where both measure; where the matcher finds no match the coarse flow and the zero-shift
correlation decide, as for a large shift.

The switches and the constants of the decision are read here, at call time: a test or a tool
that switches one sets it on this module, not on :mod:`domplane_ros.core.mask`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
from domplane_ros.config import MaskConfig
from domplane_ros.core.parallax import height_factor
from domplane_ros.core.residual import (beyond_linear_range, local_fit, LocalFit, matcher_shift,
                                        MIN_GRADIENT_ENERGY)
from domplane_ros.core.scratch import constant
import numpy as np

PLANE = 255
OBSTACLE = 127
UNKNOWN = 0
# Value of the parallax image where the residual parallax was not measured.
NOT_MEASURED = -1.0

# The one-step estimate is linear in the shift up to about a pixel at the working scale.
_LINEAR_RANGE_PX = 1.0
# The shift and the decision (docs/MASK.md round 11): the one-sided shift, true to scale
# (residual.local_fit's one_sided), judged knowing its noise. Its standard error ``se`` is the
# pixel noise over window * sqrt(confidence). With both off, round 10's mask: the one-step
# shift against the threshold alone.
_NOISE_AWARE = False
# The measurement of the residual parallax (docs/MASK.md round 12): 'one_step' (the local
# fit's one-step shift, trusted within _LINEAR_RANGE_PX and tested against the coarse flow),
# 'block' (cv2.StereoBM on the left and warped images) or 'semi_global' (cv2.StereoSGBM):
# the matcher's disparity is the residual parallax wherever it matched (no linear range, no
# test against the coarse flow); where it did not, the coarse flow and the zero-shift
# correlation decide, as for a large shift. Not the default: docs/MASK.md round 12.
_MEASUREMENT = 'one_step'
# With a matcher, the residual parallax is the mean of the matcher's and the one-step shift
# where both measured (the one-step shift within _LINEAR_RANGE_PX): the matcher's sub-pixel
# reading locks onto whole working pixels, the one-step one is noisy (round 12).
_MATCHER_AVERAGE = True
# A measured shift is an obstacle only where it clears the threshold by this many standard
# errors; one at or above the threshold that does not is unknown (the clean-up and the fill
# may still close it into the plane around it).
_OBSTACLE_SE = 2.0
# A measured shift is plane where the residual parallax it most probably comes from is below
# the threshold, under a normal prior of this spread (full-resolution pixels) on the ground:
# |r| < threshold * (1 + (se / spread)^2), the posterior mean below the threshold.
_PRIOR_SPREAD_PX = 1.0
# ... and only where its standard error is below this share of the threshold: a noisier
# window cannot tell the ground from an obstacle at the threshold (unknown).
_PLANE_MAX_SE = 1.3
# Zero-shift NCC below which a textured window is off the plane without a measured parallax.
_REJECT_NCC = 0.5
# Where an obstacle of the minimum height would not show, an obstacle needs this many times
# the parallax threshold (the coarse flow is not trusted near it there).
_FAR_FACTOR = 3.0
# The bottom of an obstacle: a pixel measured within the threshold but nearer than the plane
# by at least this share of it, with an obstacle at most core/mask.py's _RISE_ROWS working
# pixels above it in its column, is unknown, not plane (chosen on the tuning scenes,
# docs/MASK.md round 4; with the noise-aware decision on the shift true to scale, 0.7 of it:
# round 11).
_RISE_SHARE = 0.4
_TRUE_SCALE_RISE_SHARE = 0.7


@dataclass(frozen=True)
class PixelDecision:
    """Each pixel's label before the clean-up, and what the clean-up needs of the decision.

    Attributes:
        labels: (h, w) uint8 working-scale labels, :data:`PLANE`, :data:`OBSTACLE` or
            :data:`UNKNOWN` (the clean-up changes them in place).
        parallax: (h, w) float32 residual parallax magnitude, full-resolution pixels;
            :data:`NOT_MEASURED` where it was not measured (no texture, outside the right
            image).
        decidable: (h, w) bool pixels where an obstacle of ``config.min_obstacle_height``
            would show at least ``config.parallax_threshold_px`` of residual parallax.
        rising: (h, w) bool plane pixels whose measured parallax is at least
            :data:`_RISE_SHARE` of the threshold (:data:`_TRUE_SCALE_RISE_SHARE` with
            ``_NOISE_AWARE``): nearer than the plane, like the bottom of an obstacle.
        plain: (h, w) bool pixels inside the right image whose left window has less texture
            than ``config.min_texture`` (not measured: what the fill of plain regions fills).
    """

    labels: np.ndarray
    parallax: np.ndarray
    decidable: np.ndarray
    rising: np.ndarray
    plain: np.ndarray


def decide_pixels(left: np.ndarray, warped: np.ndarray, valid: np.ndarray, coarse: np.ndarray,
                  shift_inf: np.ndarray, px_per_working: float, config: MaskConfig
                  ) -> PixelDecision:
    """Return each pixel's decision on the rows of ``left`` (see the module docstring).

    Args:
        left: (h, w) uint8 left image at the working scale (the rows the mask needs).
        warped: (h, w) uint8 right image warped into the left view, the same rows.
        valid: (h, w) bool pixels inside the right image.
        coarse: (h, w) float32 coarse residual parallax
            (:func:`~domplane_ros.core.residual.flow_shift`), working pixels; a scratch array
            that the decision overwrites.
        shift_inf: (h, w) float32 ground disparity relative to infinity, full pixels.
        px_per_working: Full-resolution pixels per working pixel along x.
        config: Mask settings.

    Returns:
        The :class:`PixelDecision`.

    """
    fit = local_fit(left, warped, int(config.window_px), coarse, _NOISE_AWARE, valid)
    measurable = valid & (fit.variance >= float(config.min_texture) ** 2)
    plain = valid & ~measurable
    matched = None
    if _MEASUREMENT == 'one_step':
        # The small shifts, trusted where the coarse flow does not explain the window better.
        small = measurable & (np.abs(fit.shift) < _LINEAR_RANGE_PX)
        small &= fit.ncc >= float(config.ncc_threshold)
        small &= ~beyond_linear_range(left, warped, fit, int(config.window_px), small,
                                      _LINEAR_RANGE_PX)
    else:
        fit, matched = _matcher_fit(left, warped, fit)
        small = measurable & matched  # a matcher: its shift wherever it matched
    noise = fit.noise if _NOISE_AWARE else None
    labels, parallax, decidable = _classify(fit, measurable, small, shift_inf, px_per_working,
                                            config, noise, matched)
    share = _TRUE_SCALE_RISE_SHARE if _NOISE_AWARE else _RISE_SHARE
    rise_px = share * float(config.parallax_threshold_px) / px_per_working
    rising = (labels == PLANE) & (fit.shift >= np.float32(rise_px))
    return PixelDecision(labels=labels, parallax=parallax, decidable=decidable, rising=rising,
                         plain=plain)


def _matcher_fit(left: np.ndarray, warped: np.ndarray, fit: LocalFit
                 ) -> tuple[LocalFit, np.ndarray]:
    """Return the fit with the matcher's shift (:data:`_MEASUREMENT`) and where it matched.

    The shift is :func:`~domplane_ros.core.residual.matcher_shift`'s (working pixels, 0 where
    it found no match), or with :data:`_MATCHER_AVERAGE` its mean with the fit's one-step
    shift where that is within :data:`_LINEAR_RANGE_PX` too. Returns the new
    :class:`LocalFit` and the (h, w) bool pixels the matcher matched.
    """
    shift, matched = matcher_shift(left, warped, _MEASUREMENT)
    if _MATCHER_AVERAGE:
        both = matched & (np.abs(fit.shift) < np.float32(_LINEAR_RANGE_PX))
        mean = cv2.addWeighted(shift, 0.5, fit.shift, 0.5, 0.0)
        _copy_where(mean, both, shift)
    return replace(fit, shift=shift), matched


def _classify(fit: LocalFit, measurable: np.ndarray, small: np.ndarray, shift_inf: np.ndarray,
              px_per_working: float, config: MaskConfig, noise: float | None = None,
              matched: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the working-scale labels, the parallax image and the decidable pixels.

    Decidable pixels are those where an obstacle of ``config.min_obstacle_height`` would show
    at least ``config.parallax_threshold_px`` of residual parallax. ``measurable`` ((h, w)
    bool, changed in place) are the pixels inside the right image with texture, ``small``
    ((h, w) bool) those whose small shift is measured and trusted: the one-step shift within
    :data:`_LINEAR_RANGE_PX` where the zero-shift correlation holds and
    :func:`~domplane_ros.core.residual.beyond_linear_range` does not object, or where a
    matcher matched. ``noise`` (grey levels, :func:`~domplane_ros.core.residual.pixel_noise`)
    with a one-sided fit: the small shifts are judged by :func:`_judge` knowing their
    standard error; None: against the threshold alone. ``matched`` ((h, w) bool): the fit's
    shift is a stereo matcher's (:func:`_matcher_fit`), measured at any size where it holds;
    None: the one-step shift.
    """
    threshold = float(config.parallax_threshold_px)
    residual = fit.flow_shift  # in place: the fit is not read again
    _copy_where(fit.shift, small, residual)
    residual *= np.float32(px_per_working)
    magnitude = np.abs(residual)
    # kappa * shift_inf is the parallax an obstacle of the minimum height would show.
    decidable = shift_inf >= threshold / height_factor(float(config.min_obstacle_height))
    if noise is not None and fit.energy is not None:
        plane, unsure = _judge(magnitude, fit.energy, small,
                               noise * px_per_working / float(config.window_px), threshold)
    else:
        plane, unsure = small & (magnitude < threshold), None
        if matched is not None:  # plane needs the zero-shift correlation, as before
            plane &= fit.ncc >= float(config.ncc_threshold)
    labels = (plane & decidable).view(np.uint8) * np.uint8(PLANE)
    # Off the plane: a measured parallax at or above the threshold (beyond the noise), or a
    # clear zero-shift mismatch. An obstacle is nearer than infinity by the threshold and
    # below the horizon; where an obstacle of the minimum height would not show, only a
    # clearly larger parallax (the coarse flow is not trusted near the threshold there)
    # counts. A point farther than the plane but nearer than infinity (a hole in the ground)
    # is an obstacle too.
    off = (magnitude >= threshold) | (fit.ncc < _REJECT_NCC)
    if unsure is not None:  # the judged plane may lie at or above the threshold
        off &= ~unsure & ~plane
    # Otherwise no off pixel is plane: plane needs a parallax below the threshold and the
    # zero-shift correlation config.ncc_threshold, which its range keeps at or above
    # _REJECT_NCC (parameters.py).
    off &= measurable & (shift_inf > 0)
    off &= decidable | (residual >= _FAR_FACTOR * threshold)
    residual += shift_inf
    off &= residual >= threshold
    set_where(labels, OBSTACLE, off)
    if fit.energy is not None:  # no texture along the epipolar direction: not measured
        measurable &= fit.energy >= np.float32(MIN_GRADIENT_ENERGY)
    set_where(magnitude, NOT_MEASURED, ~measurable)
    return labels, magnitude, decidable


def _judge(magnitude: np.ndarray, energy: np.ndarray, small: np.ndarray, error_scale: float,
           threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the (h, w) bool plane and unsure pixels among the small measured shifts.

    The shift's standard error is ``se = error_scale / sqrt(energy)`` (full-resolution
    pixels; ``error_scale`` the pixel noise over the window side, in full-resolution pixels,
    the energy taken at least :data:`MIN_GRADIENT_ENERGY`). Plane: ``|r| < threshold
    (1 + (se / spread)^2)`` (:data:`_PRIOR_SPREAD_PX`) and ``se`` below
    :data:`_PLANE_MAX_SE` of the threshold. Unsure: not plane and ``|r| - k se`` below the
    threshold (:data:`_OBSTACLE_SE`): not an obstacle either. Compared without square roots
    or divisions: with ``d = |r| - threshold``, plane is ``d energy < threshold
    error_scale^2 / spread^2``, cleared ``d >= 0`` and ``d^2 energy >= k^2 error_scale^2``.

    Args:
        magnitude: (h, w) float32 |residual parallax|, full-resolution pixels.
        energy: (h, w) float32 confidence of the one-sided shifts (:class:`LocalFit`).
        small: (h, w) bool pixels whose small shift was measured.
        error_scale: Pixel noise over the window side, in full-resolution pixels.
        threshold: The parallax threshold, full-resolution pixels.

    Returns:
        (h, w) bool plane and (h, w) bool unsure pixels.

    """
    scale_sq = np.float32(error_scale * error_scale)
    # numpy with scalars: OpenCV reads a Python number beside an (n, 1) array as a 4-vector.
    confident = np.maximum(energy, np.float32(MIN_GRADIENT_ENERGY))
    excess = magnitude - np.float32(threshold)
    weighted = cv2.multiply(excess, confident)
    plane = weighted < np.float32(threshold * scale_sq / _PRIOR_SPREAD_PX ** 2)
    # se < m threshold  <=>  energy > (error_scale / (m threshold))^2
    plane &= confident > np.float32(scale_sq / (_PLANE_MAX_SE * threshold) ** 2)
    plane &= small
    cleared = cv2.multiply(weighted, excess, dst=weighted) >= np.float32(
        _OBSTACLE_SE ** 2 * scale_sq)
    cleared &= excess >= np.float32(0.0)
    unsure = small & ~plane & ~cleared
    return plane, unsure


def _copy_where(source: np.ndarray, where: np.ndarray, target: np.ndarray) -> None:
    """Copy ``source`` into ``target`` where the (h, w) bool ``where`` holds, in place.

    ``cv2.copyTo`` with the mask viewed as bytes: numpy's boolean indexing and ``np.where``
    take ten times longer on irregular masks.
    """
    cv2.copyTo(source, where.view(np.uint8), target)


def set_where(target: np.ndarray, value: float, where: np.ndarray) -> None:
    """Set ``target`` to ``value`` where the (h, w) bool ``where`` holds, in place.

    The mask's clean-up (:mod:`domplane_ros.core.mask`) sets its labels with it too.
    """
    _copy_where(constant(value, target.shape, target.dtype), where, target)
