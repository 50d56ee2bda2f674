"""Independent verification of a plane homography by dense photometric agreement.

The estimator finds a plane from corners alone, and its point energy cannot tell a look-alike
(one tile or plank off on a periodic floor, a plane through an object, a plane from before a
cut) from the true floor. This module checks a plane with evidence the corners do not use: the
whole left image against the right image warped into the left view by the plane.

Method (all at a working width of :attr:`VerificationConfig.working_width_px`):

1. Both images are shrunk (pyrDown, then area averaging); the homography is rescaled.
2. The right image is warped into the left view by ``H`` and by ``len(PROBES)`` *probe*
   hypotheses ``T(d) H``: the same plane moved in the right image by
   :attr:`VerificationConfig.epipolar_probe_shift_px` working pixels left and right and by
   :attr:`VerificationConfig.probe_shift_px` up and down. The sideways probes are the wider
   because ground texture is foreshortened: seen from above at a slant it is squeezed
   vertically and stretched sideways in the image, so its sideways sharpness shows at a larger
   scale (and sideways is the direction in which a plane of the wrong disparity moves).
3. A local zero-mean normalised cross-correlation (NCC, box windows, blind to a gain and offset
   between the cameras) is computed for every hypothesis.
4. A left pixel *supports* the plane when its window is textured, maps inside the right image,
   matches under ``H`` (NCC at least :attr:`VerificationConfig.ncc_threshold`) and matches
   clearly worse under every probe (by :attr:`VerificationConfig.peak_margin`): the plane is
   a sharp peak of agreement there, not a smooth or periodic look-alike.
5. The **score** is the supporting share of the textured pixels of the region of interest.
   Dividing by the textured pixels (not all pixels) makes the score mean the same on a busy
   and on a faint scene: "the share of the image's structure that this plane explains
   uniquely". With :attr:`VerificationConfig.weight_by_contrast` (the default) each textured
   pixel counts by the inverse of its window's grey-level standard deviation (at least
   ``min_texture``): the NCC test is blind to contrast, but the count of textured pixels is
   not, and strongly textured objects put every pixel over the texture threshold while a
   faint floor puts a few of its pixels (its joints, a mottle) there. Counted, the boxes
   standing on a faint tiled floor (1.28 m tiles) were 50-70 % of the textured pixels and the
   true floor scored 0.12-0.25 (tuning seeds 281-458); their supporting bands (the boxes'
   bottoms, at the floor's disparity) decided between fits of the floor a few pixels apart,
   and a plane 5.15 px off it that passed through more of them outscored the truth (0.258
   against 0.193, tuning seed 230). Weighted, the truth scores 0.20-0.74 there (0.291
   against 0.240 on seed 230).
6. The **peak score** is the same share with the sideways probes at ``probe_shift_px`` too:
   a finer test of where the peak lies, for ranking planes a few pixels apart on the same
   pair (the best of several candidates, a challenger against the lock). The score's wider
   sideways probes accept more true planes but tell planes 2 px apart less well: measured on
   60 rendered scenes, the true plane beat the plane moved 2 px sideways by 1.2 times in
   35 % of them by the score, in all of them by the peak score.
7. With :attr:`VerificationConfig.covisible` (off here by default; the pipeline sets it for
   ground planes from ``verification.covisible``, on by default) the score, the peak score and
   the band scores divide by the textured pixels that map inside the right image (the pixels
   both cameras see), not by all textured ones: with a vertical offset or a roll between the
   cameras the near ground leaves the right image, and each of its pixels counted against
   the true plane. A plane that maps most of the image outside would then score on the
   little it maps inside, so a plane must map at least
   :attr:`VerificationConfig.covisible_floor` of the textured pixels inside (else it fails
   as under ``min_overlap``) and the divisor is at least that share of all the textured
   pixels (of the region, or of the band). Measured in docs/BENCHMARKS.md, rounds 20 and 21.

The **confidence** maps the score linearly onto [0, 1] between
:attr:`VerificationConfig.reject_score` (0.10, confidence 0) and
:attr:`VerificationConfig.accept_score` (0.30, confidence 1); a plane is accepted at
confidence 0.5 or more, i.e. a score of 0.20 (the pipeline sets both ends from
``verification.min_score``, 0.22 since session 25, 0.25 before: confidence 0 at 0.12, 0.5 at
0.22, 1 at 0.32; docs/BENCHMARKS.md round 26). Measured
with ``tools/evaluate_verification --count 200`` on the tuning seeds 0-199 (rendered, random
gain and offset; 2026-12-01, session 12; the weighted score, the counted one in brackets, same
scenes and code): the true planes scored 0.238-0.886, median 0.640 (counted 0.124-0.863,
median 0.571), 200 of 200 above 0.20 and 199 above 0.25 (counted 197 and 194). Apart from
exact floor-period look-alikes, no wrong plane more than 10 px from the truth scored above
0.17 (counted: one, a prior candidate 25.5 px off at 0.176); 23 planes 5-10 px off did
(shifted 5 px, a cut or a prior candidate near the truth; counted 25), at most 0.358 (5.8 px
off), 5 of them above 0.25 (counted 4). Of 620 exact period look-alikes 40 scored above 0.20,
6 above 0.25 and 3 above 0.30, at most 0.344 (counted 135, 80 and 46, at most 0.580). The
score is comparable between planes on the same pair: the true plane outscored every wrong
plane of its scene, look-alikes included, in 200 of 200 scenes, by 1.38 times or more
(counted 199: on seed 159 a look-alike scored 0.573 against the truth's 0.558), so a search
should rank its candidates by the score; an absolute threshold alone cannot reject a plane
one period off on a perfectly periodic floor, which matches that floor everywhere. (The first
calibration, of an earlier counted score, gave 90 % of the true planes above 0.20, median
0.46, 57 look-alikes above 0.20 and 11 above 0.30, and 198 of 200 scenes ranked right.) On
the real pairs the weighting lowers the 13 chessboards' reference planes, judged as ground
planes, from 0.120-0.276 (median 0.179) to 0.042-0.115 (median 0.072); KITTI's road scores
0.332 (counted 0.336).

Whether a plane that verifies well was found for swapped cameras is read from the plane's
geometry alone: :func:`~domplane_ros.core.ground_slope.swap_evidence`.

Nothing here imports ROS; the functions take numpy arrays and return frozen values.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Any, Callable, Sequence

import cv2
from domplane_ros.core.features import check_roi
from domplane_ros.core.homography import as_valid_homography
from domplane_ros.core.image import check_gray
from domplane_ros.core.later import Later, MeasuredWhenRead
from domplane_ros.core.working_pair import shrink_pair, WorkingPair
import numpy as np

# Probe directions (the plane moved in the right image; sideways first, then up and down).
PROBES = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
# The sideways probes of the peak score, at probe_shift_px (PlaneVerification.peak_score).
PEAK_PROBES = ((1.0, 0.0), (-1.0, 0.0))

# A window counts as inside the right image only where every pixel of it is interpolated from
# right pixels alone (a coverage of 1 when a constant image is warped). Before session 24 a
# pixel was outside only where its value came mostly from beyond the border (the warp of the
# image with border -1 negative): a plane mapping the left image's last rows a fraction of a
# pixel below the right image's last row mixed the black border into the near ground's
# windows and counted them against the plane (KITTI 000046, the right image moved 0.5 px
# down, truth moved with it: the road's score 0.335 -> 0.279; docs/BENCHMARKS.md round 25).
# False: the old test.
EXACT_COVERAGE = True
_FULLY_COVERED = 1.0 - 1e-4
# With EXACT_COVERAGE, the right image's no-data border counts as outside it too
# (:func:`~domplane_ros.core.working_pair.no_data_valid`: exact zeros connected to its edge, as
# a warp or a rectification with alpha > 0 leaves; docs/BENCHMARKS.md rounds 30-31). False:
# the image's frame alone, as before session 26.
NO_DATA_BORDER = True

# The lowest share of the region's rows over which PlaneVerification.bottom_score is measured.
BOTTOM_BAND = 1.0 / 3.0
# Gaps between supporting pixels closed to find a plane's own region (region_score), working
# pixels (8 full pixels at 640 x 480 and the default scale).
REGION_CLOSE_PX = 2

# Failure reasons, in the order they are checked.
REASON_NO_OVERLAP = 'plane maps too little of the left image inside the right image'
REASON_NO_TEXTURE = 'too few textured pixels to verify'
REASON_LOW_SUPPORT = 'plane explains too little of the image'


@dataclass(frozen=True)
class VerificationConfig:
    """Settings of :func:`verify_plane` (the lead moves this into ``config.py``).

    Attributes:
        working_width_px: Width of the images the check runs on (height scales alike).
        window_px: Side of the NCC window in working pixels (odd).
        ncc_threshold: Least NCC under the plane for a pixel to support it.
        peak_margin: Least amount by which the plane's NCC must beat every probe's.
        probe_shift_px: Shift of the up and down probes (and of the peak score's sideways
            probes) in working pixels.
        epipolar_probe_shift_px: Shift of the left and right probes in working pixels.
        min_texture: Least grey-level standard deviation of a left window to be used.
        min_textured_fraction: Least share of region pixels that are textured, else the
            verification fails with :data:`REASON_NO_TEXTURE`.
        min_overlap: Least share of the textured pixels that map inside the right image.
        reject_score: Score at and below which the confidence is 0.
        accept_score: Score at and above which the confidence is 1.
        weight_by_contrast: Count each textured pixel in the score, the peak score and the
            bottom score by ``1 / max(std, min_texture)`` of its window (see the module
            docstring, step 5) instead of 1.
        covisible: Divide the score, the peak score and the band scores by the textured
            pixels that map inside the right image (the pixels both cameras see) instead of
            all textured pixels (see the module docstring, step 7).
        covisible_floor: With ``covisible``: a plane that maps less than this share of the
            textured pixels inside the right image fails with :data:`REASON_NO_OVERLAP` (as
            under ``min_overlap``, whichever is larger), and each score divides by at least
            this share of the textured pixels (of the region, or of a band, each weighted as
            in the score): a plane that maps most of the image outside cannot score on the
            little it maps inside, and co-visibility raises a score at most
            ``1 / covisible_floor`` times.
    """

    working_width_px: int = 160
    window_px: int = 5
    ncc_threshold: float = 0.9
    peak_margin: float = 0.05
    probe_shift_px: float = 1.5
    epipolar_probe_shift_px: float = 3.0
    min_texture: float = 2.0
    min_textured_fraction: float = 0.02
    min_overlap: float = 0.1
    reject_score: float = 0.10
    accept_score: float = 0.30
    weight_by_contrast: bool = True
    covisible: bool = False
    covisible_floor: float = 0.5

    def __post_init__(self) -> None:
        """Check every field.

        Raises:
            ValueError: If a value is out of its range; the message names the field.

        """
        if int(self.working_width_px) != self.working_width_px or self.working_width_px < 16:
            raise ValueError(f'working_width_px must be an integer >= 16, got '
                             f'{self.working_width_px!r}')
        if (int(self.window_px) != self.window_px or self.window_px < 3
                or self.window_px % 2 == 0):
            raise ValueError(f'window_px must be an odd integer >= 3, got {self.window_px!r}')
        for name in ('ncc_threshold', 'peak_margin', 'min_textured_fraction', 'min_overlap',
                     'covisible_floor'):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f'{name} must be in [0, 1], got {value!r}')
        for name in ('probe_shift_px', 'epipolar_probe_shift_px', 'min_texture'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be positive and finite, got {value!r}')
        if not 0.0 <= self.reject_score < self.accept_score <= 1.0:
            raise ValueError('need 0 <= reject_score < accept_score <= 1, got '
                             f'{self.reject_score!r}, {self.accept_score!r}')


@dataclass(frozen=True)
class PlaneVerification:
    """The verdict on one plane.

    Attributes:
        accepted: Whether the plane passed (``confidence >= 0.5`` and no failure reason).
        score: Share of the textured region pixels that support the plane uniquely, [0, 1].
        confidence: ``score`` mapped linearly from ``reject_score`` (0) to ``accept_score``
            (1), [0, 1]; 0 when a precondition failed.
        support_fraction: Share of the textured region pixels whose NCC under the plane is
            at least ``ncc_threshold`` (without the probe test), [0, 1].
        overlap_fraction: Share of the textured region pixels that map inside the right
            image, [0, 1].
        textured_fraction: Share of the region pixels that are textured, [0, 1].
        reason: Empty when accepted, else why not.
        time_ms: Wall time of the call in milliseconds (a peak score read later not included).
        bottom_score: The score over the lowest :data:`BOTTOM_BAND` of the region only (its
            supporting share of the textured pixels there; 0 if none is textured), [0, 1].
            The ground seen from above fills the bottom of the image, so its plane explains
            part of it; a plane through boxes or a wall above the floor explains none.
        peak_score: The score with the sideways probes at ``probe_shift_px`` as well
            (:data:`PEAK_PROBES`), at most ``score``: for ranking planes a few pixels apart
            on the same pair. Its two probes (a fifth of a verification's time) are measured
            when it is first read: a warm pair's lock is ranked against nothing.
        region_score: Measured only when asked (``verify_plane(..., own_region=True)``, for
            ``verification.plane: any``), else 0: the score over the plane's own region, the
            largest connected region of its supporting pixels once gaps of up to
            :data:`REGION_CLOSE_PX` working pixels are closed: the supporting share of the
            textured pixels there, [0, 1]. A board covering a fifth of a textured room
            explains little of the image but almost all of its own region.
        region_fraction: That region's share of the image, [0, 1] (0 unless measured).
        below_fraction: Share of the textured region pixels that the plane does not explain
            but the plane moved right in the right image (``PROBES[0]``) does, clearly better
            than the plane and the plane moved left, [0, 1]. For a correctly ordered head
            (right camera on the right) that texture has less disparity than the plane: it
            lies beyond the plane, below it if the plane is the ground. Nothing is seen below
            the ground, so the true ground's is small (at most 0.004 on 100 rendered tuning
            scenes), while a plane through boxes standing on a floor sees the floor below it.
        top_score: The score over the highest :data:`BOTTOM_BAND` of the region only, as
            ``bottom_score``, [0, 1].
        middle_score: The score over the band between the two, as ``bottom_score``, [0, 1].
            One surface explains a band between two bands it explains; a plane through a far
            wall that explains the bottom only by aliasing a periodic floor does not (see
            ``stream/ground_rules.py``, ``MIN_MIDDLE_SHARE``).
        middle_texture: The middle band's share of the region's textured pixels (each
            weighted as in the score), [0, 1]: how much ``middle_score`` rests on.
    """

    accepted: bool
    score: float
    confidence: float
    support_fraction: float
    overlap_fraction: float
    textured_fraction: float
    reason: str
    time_ms: float
    bottom_score: float = 0.0
    peak_score: float = MeasuredWhenRead()  # type: ignore[assignment]
    below_fraction: float = 0.0
    region_score: float = 0.0
    region_fraction: float = 0.0
    top_score: float = 0.0
    middle_score: float = 0.0
    middle_texture: float = 0.0


def _check_roi(roi: Sequence[float] | None) -> tuple[float, float, float, float]:
    return (0.0, 0.0, 1.0, 1.0) if roi is None else check_roi(roi)


@dataclass(frozen=True)
class AgreementMaps:
    """Working-scale maps of one verification, for pictures and evaluations.

    Attributes:
        left: (h, w) uint8 left image at working scale.
        warped: (h, w) uint8 right image warped into the left view by the plane.
        ncc: (h, w) float32 NCC under the plane (0 where undefined).
        probes: (len(PROBES), h, w) float32 NCC under each probe.
        best_probe: (h, w) float32 largest NCC under a probe.
        textured: (h, w) bool textured left windows inside the region.
        inside: (h, w) bool windows that map inside the right image.
        support: (h, w) bool pixels supporting the plane uniquely.
        peak_support: (h, w) bool supporting pixels where the plane also beats the
            :data:`PEAK_PROBES` (the pixels of ``peak_score``); None from
            ``agreement_maps(..., peak=False)``.
        weight: (h, w) float32 what each pixel counts in the scores: 0 where not textured,
            else 1 or, with ``weight_by_contrast``, ``1 / max(std, min_texture)``.
    """

    left: np.ndarray
    warped: np.ndarray
    ncc: np.ndarray
    probes: np.ndarray
    best_probe: np.ndarray
    textured: np.ndarray
    inside: np.ndarray
    support: np.ndarray
    peak_support: np.ndarray | None
    weight: np.ndarray


def _ncc(a: np.ndarray, mean_a: np.ndarray, var_a: np.ndarray, b: np.ndarray,
         size: tuple[int, int], min_var: float) -> np.ndarray:
    """Return the (h, w) float32 windowed NCC of ``a`` and ``b`` (near 0 where ``b`` is flat)."""
    mean_b = cv2.blur(b, size)
    var_b = cv2.blur(cv2.multiply(b, b), size) - cv2.multiply(mean_b, mean_b)
    cov = cv2.blur(cv2.multiply(a, b), size) - cv2.multiply(mean_a, mean_b)
    # Flat windows of b get the floor min_var**2 under the root: their NCC tends to 0.
    denom = cv2.sqrt(cv2.max(cv2.multiply(var_a, var_b), min_var * min_var))
    return cv2.divide(cov, denom)


def working_pair(left: np.ndarray, right: np.ndarray,
                 config: VerificationConfig = VerificationConfig(),
                 levels: tuple[np.ndarray, np.ndarray, int] | None = None) -> WorkingPair:
    """Return the pair at ``config.working_width_px``, for :func:`verify_plane`'s ``working``.

    Verifying several planes on one pair (a search's candidates) shrinks the images once.

    Args:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image.
        config: The verification's settings (its working width).
        levels: ``(left level, right level, L)``: the images ``cv2.pyrDown`` L times (the
            pipeline's working level); the shrink starts from them when it halves at least
            L times, and gives the same images as from the full ones.

    Raises:
        ValueError: As :func:`verify_plane` for the images, or if a level's shape is not
            the L-th pyrDown's.

    """
    left, right = _check_pair(left, right)
    return _working(left, right, config, levels)


def _working(left: np.ndarray, right: np.ndarray, config: VerificationConfig,
             levels: tuple[np.ndarray, np.ndarray, int] | None = None) -> WorkingPair:
    return shrink_pair(left, right, config.working_width_px, levels,
                       no_data=NO_DATA_BORDER and EXACT_COVERAGE)


def _maps(left: np.ndarray, right: np.ndarray, hom: np.ndarray, config: VerificationConfig,
          roi: tuple[float, float, float, float],
          working: WorkingPair | None = None, peak: bool = True
          ) -> tuple[AgreementMaps, Callable[[], np.ndarray]]:
    """Return the agreement maps and how to measure their ``peak_support``.

    With ``peak`` False the maps' ``peak_support`` is None and the returned function makes
    it (the same array as with ``peak`` True); else it returns the maps' own.
    """
    if working is None:
        working = _working(left, right, config)
    left_small, scale_left = working.left, working.left_map
    right_small, scale_right = working.right, working.right_map
    small_h, small_w = left_small.shape
    hom_small = scale_right @ hom @ np.linalg.inv(scale_left)
    size = (int(config.window_px), int(config.window_px))
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    a = left_small.astype(np.float32)
    mean_a = cv2.blur(a, size)
    var_a = cv2.blur(a * a, size) - mean_a * mean_a
    min_var = float(config.min_texture) ** 2
    x0, y0, x1, y1 = roi
    region = np.zeros((small_h, small_w), bool)
    region[int(round(y0 * small_h)):int(round(y1 * small_h)),
           int(round(x0 * small_w)):int(round(x1 * small_w))] = True
    textured = region & (var_a >= min_var)
    if config.weight_by_contrast:
        spread = cv2.sqrt(cv2.max(var_a, min_var))
        weight = np.where(textured, 1.0 / spread, 0.0).astype(np.float32)
    else:
        weight = textured.astype(np.float32)
    right_f = right_small.astype(np.float32)
    # The inside test warps a constant image; -1 marks pixels from outside the right image.
    right_f_border = (small_w, small_h)
    warped = cv2.warpPerspective(right_f, hom_small, right_f_border, flags=flags,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    if EXACT_COVERAGE:
        # Every interpolation weight must fall inside the right image: a pixel mapped
        # between its last row and the border mixes the border into the window.
        valid = working.right_valid
        covered = cv2.warpPerspective(np.ones_like(right_f) if valid is None else valid,
                                      hom_small, right_f_border,
                                      flags=flags, borderMode=cv2.BORDER_CONSTANT,
                                      borderValue=0.0)
        outside = cv2.blur((covered < _FULLY_COVERED).astype(np.float32), size) > 0
    else:
        outside = cv2.blur((warped < 0).astype(np.float32), size) > 0
    warped_clean = np.maximum(warped, 0.0)
    ncc = _ncc(a, mean_a, var_a, warped_clean, size, min_var)
    probes = np.empty((len(PROBES),) + ncc.shape, np.float32)
    # Wide sideways, narrow up and down; the peak score's sideways probes are narrow too.
    wide, narrow = float(config.epipolar_probe_shift_px), float(config.probe_shift_px)

    def probe_ncc(dx: float, dy: float) -> np.ndarray:
        probe = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])
        moved = cv2.warpPerspective(right_f, probe @ hom_small, right_f_border, flags=flags,
                                    borderMode=cv2.BORDER_REPLICATE)
        return _ncc(a, mean_a, var_a, moved, size, min_var)

    for index, (dx, dy) in enumerate(PROBES):
        probes[index] = probe_ncc(dx * wide, dy * narrow)
    best_probe = probes.max(axis=0)
    inside = ~outside
    support = (textured & inside & (ncc >= config.ncc_threshold)
               & (ncc >= best_probe + config.peak_margin))

    def peak_support_of() -> np.ndarray:
        peak_support = support.copy()
        for dx, dy in PEAK_PROBES:
            if support.any():
                peak_support &= ncc >= probe_ncc(dx * narrow, dy * narrow) + config.peak_margin
        return peak_support

    peak_support = peak_support_of() if peak else None
    maps = AgreementMaps(left=left_small,
                         warped=np.clip(warped_clean, 0, 255).astype(np.uint8), ncc=ncc,
                         probes=probes, best_probe=best_probe, textured=textured,
                         inside=inside, support=support, peak_support=peak_support,
                         weight=weight)
    return maps, (peak_support_of if peak_support is None else lambda: peak_support)


def agreement_maps(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                   config: VerificationConfig = VerificationConfig(),
                   roi: Sequence[float] | None = None, working: WorkingPair | None = None,
                   peak: bool = True) -> AgreementMaps:
    """Return the working-scale maps behind :func:`verify_plane` (arguments as there).

    ``peak`` False leaves ``peak_support`` None and spares its two probes (a fifth of the
    maps' time), for callers that read only the other maps.

    Raises:
        ValueError: As :func:`verify_plane`.

    """
    left, right = _check_pair(left, right)
    _check_working(working, left, config)
    return _maps(left, right, as_valid_homography(homography), config, _check_roi(roi),
                 working, peak)[0]


def _check_working(working: WorkingPair | None, left: np.ndarray,
                   config: VerificationConfig) -> None:
    if working is not None and (working.full_shape != left.shape
                                or working.width != config.working_width_px):
        raise ValueError(f'working images made for {working.full_shape} at width '
                         f'{working.width}, not {left.shape} at {config.working_width_px}')


def _check_pair(left: Any, right: Any) -> tuple[np.ndarray, np.ndarray]:
    left = check_gray(left, 'left')
    right = check_gray(right, 'right')
    if left.shape != right.shape:
        raise ValueError(f'left and right images differ in size: {left.shape} vs '
                         f'{right.shape}')
    if left.shape[0] < 8 or left.shape[1] < 8:
        raise ValueError(f'images must be at least 8 x 8, got {left.shape}')
    return left, right


def verify_plane(left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                 config: VerificationConfig = VerificationConfig(),
                 roi: Sequence[float] | None = None,
                 working: WorkingPair | None = None, own_region: bool = False
                 ) -> PlaneVerification:
    """Verify a left-to-right plane homography by dense photometric agreement.

    See the module docstring for the method and the meaning of the score and confidence.

    Args:
        left: (H, W) uint8 left image.
        right: (H, W) uint8 right image (same size).
        homography: (3, 3) float plane homography mapping left pixels to right pixels.
        config: Settings.
        roi: Optional (x0, y0, x1, y1) region of the left image in fractions of its size
            (as ``features.roi``); default the whole image.
        working: These images at the working width (:func:`working_pair`), if already
            made; the result is the same.
        own_region: Also measure the score over the plane's own region
            (``PlaneVerification.region_score`` and ``region_fraction``).

    Returns:
        The :class:`PlaneVerification`; a failed check is a value with ``accepted`` False and
        a ``reason``, never an exception.

    Raises:
        ValueError: If an image is not a non-empty (H, W) uint8 array, the sizes differ, the
            homography is not a finite non-singular (3, 3) matrix, the roi is malformed or
            ``working`` was made for another image size or working width.

    """
    start = time.perf_counter()
    left, right = _check_pair(left, right)
    hom = as_valid_homography(homography)
    region = _check_roi(roi)
    _check_working(working, left, config)
    # The peak score is measured when first read (PlaneVerification.peak_score).
    maps, peak_support = _maps(left, right, hom, config, region, working, peak=False)
    verdict = _verdict(maps, config, start, region, peak_support)
    if not own_region:
        return verdict
    score, fraction = region_support(maps)
    return updated(verdict, region_score=score, region_fraction=fraction,
                   time_ms=1000.0 * (time.perf_counter() - start))


def updated(verification: PlaneVerification, **changes: Any) -> PlaneVerification:
    """Return ``dataclasses.replace(verification, **changes)`` with its peak score unread.

    ``replace`` reads every field, which would measure a pending peak score
    (:class:`~domplane_ros.core.later.Later`); this copies it as it is.
    """
    return PlaneVerification(**{**verification.__dict__, **changes})


def own_region(maps: AgreementMaps, close_px: int = REGION_CLOSE_PX) -> np.ndarray:
    """Return the (h, w) bool own region of a plane at the working scale (none if no support).

    The largest 8-connected component of the supporting pixels after a morphological closing
    with a disc of radius ``close_px`` working pixels.
    """
    if not maps.support.any():
        return np.zeros_like(maps.support)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * close_px + 1, 2 * close_px + 1))
    closed = cv2.morphologyEx(maps.support.astype(np.uint8), cv2.MORPH_CLOSE, disc)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    if count <= 1:
        return np.zeros_like(maps.support)
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def region_support(maps: AgreementMaps, close_px: int = REGION_CLOSE_PX
                   ) -> tuple[float, float]:
    """Return a plane's score over its own region and that region's share of the image.

    The region is :func:`own_region`; its score is the supporting share of the textured
    pixels inside it (``PlaneVerification.region_score``).
    """
    own = own_region(maps, close_px)
    textured = int(np.count_nonzero(maps.textured & own))
    score = int(np.count_nonzero(maps.support & own)) / textured if textured else 0.0
    return float(score), float(np.count_nonzero(own)) / own.size


def _share(maps: AgreementMaps, pixels: np.ndarray, rows: slice = slice(None),
           floor: float | None = None) -> float:
    """Return the weighted share of the textured pixels in ``rows`` that are in ``pixels``.

    With a ``floor`` (``VerificationConfig.covisible``) the share is of the textured pixels
    in ``rows`` that map inside the right image, or of ``floor`` x all of them if more.
    """
    weight = maps.weight[rows]
    total = float(weight.sum(dtype=np.float64))
    if floor is not None:
        total = max(float(weight[maps.inside[rows]].sum(dtype=np.float64)), floor * total)
    return float(weight[pixels[rows]].sum(dtype=np.float64)) / total if total > 0 else 0.0


def _band_scores(maps: AgreementMaps, region: tuple[float, float, float, float],
                 floor: float | None = None) -> tuple[float, float, float, float]:
    """Return the supporting shares of the textured pixels in the region's three bands.

    Top, middle and bottom: the highest and lowest :data:`BOTTOM_BAND` of the region's rows
    and the rows between them; then the middle band's share of the region's textured pixels
    (each weighted as in the score). With a ``floor`` each share is :func:`_share`'s
    co-visible one, and the middle band's share is of the textured pixels mapping inside.
    """
    height = maps.textured.shape[0]
    top = int(round((region[1] + BOTTOM_BAND * (region[3] - region[1])) * height))
    bottom = int(round((region[3] - BOTTOM_BAND * (region[3] - region[1])) * height))
    first = int(round(region[1] * height))
    weight = maps.weight if floor is None else np.where(maps.inside, maps.weight, 0.0)
    total = float(weight.sum(dtype=np.float64))
    middle = float(weight[top:bottom].sum(dtype=np.float64))
    return (_share(maps, maps.support, slice(first, top), floor),
            _share(maps, maps.support, slice(top, bottom), floor),
            _share(maps, maps.support, slice(bottom, None), floor),
            middle / total if total > 0 else 0.0)


def _below(maps: AgreementMaps, config: VerificationConfig) -> np.ndarray:
    """Return the (h, w) bool pixels that the plane moved right explains and it does not."""
    right_probe, left_probe = maps.probes[0], maps.probes[1]
    return (maps.textured & maps.inside & ~maps.support
            & (right_probe >= config.ncc_threshold)
            & (right_probe >= left_probe + config.peak_margin)
            & (right_probe >= maps.ncc + config.peak_margin))


def _verdict(maps: AgreementMaps, config: VerificationConfig, start: float,
             region: tuple[float, float, float, float],
             peak_support: Callable[[], np.ndarray]) -> PlaneVerification:
    region_px = max(1, int(np.count_nonzero(maps.textured | ~maps.textured)))
    n_textured = int(np.count_nonzero(maps.textured))
    textured_fraction = n_textured / region_px
    floor = float(config.covisible_floor) if config.covisible else None
    peak: float | Later
    if n_textured == 0:
        overlap = support = score = peak = below = 0.0
    else:
        overlap = int(np.count_nonzero(maps.textured & maps.inside)) / n_textured
        support = int(np.count_nonzero(maps.textured & maps.inside
                                       & (maps.ncc >= config.ncc_threshold))) / n_textured
        score = _share(maps, maps.support, floor=floor)
        peak = Later(lambda: _share(maps, peak_support(), floor=floor))
        below = int(np.count_nonzero(_below(maps, config))) / n_textured
    bands = _band_scores(maps, region, floor)
    span = config.accept_score - config.reject_score
    confidence = float(np.clip((score - config.reject_score) / span, 0.0, 1.0))
    reason = ''
    if textured_fraction < config.min_textured_fraction:
        reason = REASON_NO_TEXTURE
    elif overlap < max(config.min_overlap, floor or 0.0):
        reason = REASON_NO_OVERLAP
    elif confidence < 0.5:
        reason = REASON_LOW_SUPPORT
    if reason and reason != REASON_LOW_SUPPORT:
        confidence = 0.0
    return PlaneVerification(
        accepted=not reason, score=float(score), confidence=confidence,
        support_fraction=float(support), overlap_fraction=float(overlap),
        textured_fraction=float(textured_fraction), reason=reason,
        time_ms=1000.0 * (time.perf_counter() - start), bottom_score=bands[2],
        peak_score=peak, below_fraction=float(below), top_score=bands[0],
        middle_score=bands[1], middle_texture=bands[3])
