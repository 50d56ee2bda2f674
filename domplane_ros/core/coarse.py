"""Coarse photometric alignment: initial homographies that need no tight camera model.

The prior's grid (:mod:`domplane_ros.core.prior`) only covers heads that match its camera
model: principal points at the centre, equal focal lengths, no roll, no relative pitch. A
hand-assembled head breaks that model by a few degrees and a few pixels, which moves every grid
candidate 10-40 px from the truth, out of the two-step iteration's basin. This module proposes
candidates from the images themselves, coarse to fine: a dense, pyramidal photometric
alignment of the left image to the right one (OpenCV's DIS optical flow, Kroeger et al., ECCV
2016) at a working width of a few hundred pixels, checked forward-backward, to which a
homography is fitted robustly (MAGSAC++) over the whole image and over its lower part (where a
floor or road usually is). The candidates then go to the same two-step refinement as the grid's
and are ranked by the plane's verification, so a flow that followed a wall or a periodic
look-alike costs a refinement, not a wrong plane.

The flow's coarsest level cannot follow a disparity of a third of the image (a wide baseline
over a near floor): there it follows the far field or nothing. So the right image is also
shifted by the lower half's dominant displacement (phase correlation, ``cv2.phaseCorrelate``)
and aligned again; each alignment gives its own candidates. Measured on 30 rough-rig tuning
scenes: the nearest candidate was more than 25 px from the truth on 5 (all with the floor's
disparity over 90 px at 640 px), within 2.5 px on all 5 with the shifted alignment, which
alone failed on one other scene (its shift had the wrong sign).

The lower half's dominant displacement is itself a guess: perspective smears the floor's
displacement over tens of pixels, and a periodic floor (tiles, planks) correlates as well one
period off, so the strongest peak is often an alias. The right image is therefore also aligned
after a few more displacements: the strongest phase-correlation peaks of horizontal strips of
the lower half (each strip smears less), at half the working width, of a ground plane's sign
(the right camera sees the floor further left): :meth:`CoarseAligner.peak_candidates`, for a
search in doubt only (they cost a dense flow each).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any, Generator

import cv2
import numpy as np

# The photometric refinement (CoarseAligner.refine), at its working width: samples every
# REFINE_STEP_PX pixels, kept when forward and backward flow agree within
# REFINE_MAX_FORWARD_BACKWARD_PX and the residual flow is under REFINE_NEAR_PX (the plane's
# own pixels); the correction is fitted to them by MAGSAC++ at REFINE_THRESHOLD_PX, if at least
# REFINE_MIN_SAMPLES are kept (all in pixels at the refinement's working width).
REFINE_STEP_PX = 2
REFINE_MAX_FORWARD_BACKWARD_PX = 0.3
REFINE_NEAR_PX = 2.0
REFINE_THRESHOLD_PX = 0.3
REFINE_MIN_SAMPLES = 50

# The residual parallax test of a plane (CoarseAligner.beyond_share), at the alignment's working
# width: a flow sample lies *beyond* the plane when its residual flow after warping by the plane
# points the way of less disparity by more than BEYOND_PX pixels (at the working width).
BEYOND_PX = 1.0

# Images smaller than this on either side (at the working width) give no plane: the flow needs
# a few pyramid levels of its patches (OpenCV's DIS refuses images under 12 px).
MIN_SIZE_PX = 32

_PRESETS = {'ultrafast': cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
            'fast': cv2.DISOPTICAL_FLOW_PRESET_FAST,
            'medium': cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}


@dataclass(frozen=True)
class CoarseConfig:
    """Settings of the coarse photometric candidates.

    Attributes:
        width_px: Working width in pixels (the images are reduced to it, never enlarged).
        preset: DIS optical flow preset: ``'ultrafast'``, ``'fast'`` or ``'medium'``.
        step_px: Spacing of the flow samples at the working width, pixels.
        min_gradient: Smoothed gradient magnitude (Sobel, grey levels) below which a sample is
            too weakly textured to trust its flow.
        max_forward_backward_px: Largest forward-backward flow disagreement kept, pixels at
            the working width.
        threshold_px: MAGSAC++ inlier threshold at the working width, pixels.
        lower_parts: Top edges (fractions of the height) of the image parts homographies
            are fitted to; 0.0 is the whole image.
        planes_per_part: Homographies fitted one after the other in each part, each to the
            samples the previous ones left out (a box or a wall that dominates a part hides
            the floor from the first fit only).
        min_shift_px: The right image is aligned a second time, shifted by the lower half's
            dominant displacement, when that is at least this long (pixels at the working
            width); ``inf``: never.
        refine_width_px: Largest working width of the photometric refinement
            (:meth:`CoarseAligner.refine`); smaller images are refined at full resolution.
        refine_preset: DIS optical flow preset of the refinement.
        refine_min_gradient: ``min_gradient`` of the refinement's samples. Lower than the
            alignment's: the refinement starts near the plane, and on a faint floor the
            samples over ``min_gradient`` are mostly those of the boxes standing on it (their
            bottoms are at the floor's disparity), which pulled the fit off the floor (tuning
            faint seed 230, 1.28 m tiles: from the true plane to 1.07 px at 20, 0.25 px at 8,
            0.05 px at 4); the floor's own faint texture keeps it there.
        finish_width_px: Largest working width of the refinement that finishes a published
            plane of a search or a challenge (``refine(..., finish=True)``, up to twice) and
            of a search's near-miss rescue (up to twice for each of two planes); the other
            refinements (the few-corner paths) work at ``refine_width_px``.
        shift_peaks: Further shifted alignments: the strongest phase-correlation peaks of
            ``shift_strips`` horizontal strips of the lower half whose displacement points left
            by at least ``min_shift_px`` (a ground plane's disparity); 0: only the dominant
            shift. Measured on rough-rig tuning scenes (seeds 0-89 and 200-239, documented
            default prior): docs/BENCHMARKS.md, trust round 8.
        shift_strips: Horizontal strips of the lower half correlated for ``shift_peaks``.
    """

    width_px: int = 320
    preset: str = 'medium'
    step_px: int = 3
    min_gradient: float = 20.0
    max_forward_backward_px: float = 0.5
    threshold_px: float = 1.0
    lower_parts: tuple[float, ...] = (0.0, 0.5, 0.7)
    planes_per_part: int = 2
    min_shift_px: float = 4.0
    refine_width_px: int = 640
    refine_preset: str = 'medium'
    refine_min_gradient: float = 4.0
    finish_width_px: int = 1280
    shift_peaks: int = 4
    shift_strips: int = 3

    def __post_init__(self) -> None:
        """Check the values.

        Raises:
            ValueError: If a value is out of range or the preset is unknown.

        """
        for name in ('preset', 'refine_preset'):
            if getattr(self, name) not in _PRESETS:
                raise ValueError(f'{name} must be one of {sorted(_PRESETS)}, got '
                                 f'{getattr(self, name)!r}')
        for name in ('width_px', 'refine_width_px', 'finish_width_px'):
            if not 32 <= getattr(self, name) <= 4096:
                raise ValueError(f'{name} must be in [32, 4096], got {getattr(self, name)}')
        if self.step_px < 1 or self.threshold_px <= 0 or self.max_forward_backward_px <= 0:
            raise ValueError('step_px, threshold_px and max_forward_backward_px must be positive')
        if not (self.min_gradient >= 0 and self.refine_min_gradient >= 0):
            raise ValueError('min_gradient and refine_min_gradient must be non-negative, got '
                             f'{self.min_gradient!r}, {self.refine_min_gradient!r}')
        if not self.min_shift_px > 0:
            raise ValueError(f'min_shift_px must be positive, got {self.min_shift_px!r}')
        if not all(0.0 <= part < 1.0 for part in self.lower_parts):
            raise ValueError(f'lower_parts must lie in [0, 1), got {self.lower_parts!r}')
        if self.shift_peaks < 0 or self.shift_strips < 1:
            raise ValueError(f'shift_peaks must be >= 0 and shift_strips >= 1, got '
                             f'{self.shift_peaks!r} and {self.shift_strips!r}')
        if int(self.planes_per_part) != self.planes_per_part or self.planes_per_part < 1:
            raise ValueError(f'planes_per_part must be an integer >= 1, got '
                             f'{self.planes_per_part!r}')


class CoarseAligner:
    """Candidate plane homographies from a dense coarse-to-fine photometric alignment.

    One object per stream: it keeps its DIS optical flow instance (allocated once).

    Args:
        config: The settings; default :class:`CoarseConfig`.

    """

    def __init__(self, config: CoarseConfig | None = None) -> None:
        """Create the flow object."""
        self.config = config or CoarseConfig()
        self._flow = cv2.DISOpticalFlow_create(_PRESETS[self.config.preset])
        self._refine_flow = cv2.DISOpticalFlow_create(_PRESETS[self.config.refine_preset])

    def candidates(self, left: np.ndarray, right: np.ndarray, shifted: bool = True
                   ) -> np.ndarray:
        """Return candidate left-to-right homographies of the dominant plane.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image (the same size).
            shifted: Also align after the lower half's dominant shift (when it is at least
                ``min_shift_px``); False: the plain alignment only.

        Returns:
            (K, 3, 3) float64 homographies at full resolution, ``H[2, 2] == 1``; K is 0 when
            the images give too few trustworthy flow samples or are smaller than
            :data:`MIN_SIZE_PX` at the working width.

        Raises:
            ValueError: If the images are not 2-D uint8 arrays of the same size.

        """
        cfg = self.config
        small_l, small_r, scale = _working_pair(left, right, cfg.width_px)
        if min(small_l.shape) < MIN_SIZE_PX:
            return np.zeros((0, 3, 3))
        to_full = np.diag([1.0 / scale, 1.0 / scale, 1.0])
        from_full = np.diag([scale, scale, 1.0])
        rows = small_l.shape[0]
        out = [to_full @ h @ from_full
               for h in self._fitted(*self._samples(small_l, small_r), rows)]
        shift = _dominant_shift(small_l, small_r) if shifted else (0.0, 0.0)
        if shifted and math.hypot(*shift) >= cfg.min_shift_px:
            out += self._aligned_after(small_l, small_r, shift, scale)
        return np.stack([h / h[2, 2] for h in out]) if out else np.zeros((0, 3, 3))

    def peak_candidates(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return the planes of the further shifted alignments (the strips' peaks).

        The right image is aligned again after each of up to ``shift_peaks`` displacements:
        the strongest phase-correlation peaks of ``shift_strips`` horizontal strips of the
        lower half (:func:`_strip_peaks`) that point left by at least ``min_shift_px`` and lie
        more than ``min_shift_px`` from the dominant shift and from each other. These cost a
        dense flow each and give many planes, so they are for a search in doubt (see
        :class:`~domplane_ros.stream.search.PlaneSearch`), not for every pair.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image (the same size).

        Returns:
            (K, 3, 3) float64 homographies at full resolution, ``H[2, 2] == 1`` (K may be 0).

        Raises:
            ValueError: If the images are not 2-D uint8 arrays of the same size.

        """
        cfg = self.config
        small_l, small_r, scale = _working_pair(left, right, cfg.width_px)
        if min(small_l.shape) < MIN_SIZE_PX or cfg.shift_peaks == 0:
            return np.zeros((0, 3, 3))
        out = []
        for shift in self._peak_shifts(small_l, small_r):
            out += self._aligned_after(small_l, small_r, shift, scale)
        return np.stack([h / h[2, 2] for h in out]) if out else np.zeros((0, 3, 3))

    def _aligned_after(self, small_l: np.ndarray, small_r: np.ndarray,
                       shift: tuple[float, float], scale: float) -> list[np.ndarray]:
        """Return the full-resolution planes of the alignment after ``shift`` (working px).

        ``small_l`` and ``small_r`` are the (h, w) uint8 images at the working width, ``scale``
        their size over the full images'; the planes are (3, 3) float64, not normalised.
        """
        src, dst = self._samples(small_l, _translated(small_r, -shift[0], -shift[1]))
        dst += np.asarray(shift, np.float32)
        to_full = np.diag([1.0 / scale, 1.0 / scale, 1.0])
        from_full = np.diag([scale, scale, 1.0])
        return [to_full @ h @ from_full for h in self._fitted(src, dst, small_l.shape[0])]

    def _peak_shifts(self, left: np.ndarray, right: np.ndarray) -> list[tuple[float, float]]:
        """Return up to ``shift_peaks`` strip peaks (dx, dy), working px, strongest first.

        ``left`` and ``right`` are the (h, w) uint8 images at the working width. Each peak lies
        more than ``min_shift_px`` from the dominant shift and from those before it.
        """
        cfg = self.config
        shifts = [_dominant_shift(left, right)]
        rows = left.shape[0]
        edges = np.linspace(rows // 2, rows, cfg.shift_strips + 1).astype(int)
        peaks = []
        for top, bottom in zip(edges[:-1], edges[1:]):
            peaks += _strip_peaks(left[top:bottom], right[top:bottom], cfg.shift_peaks,
                                  cfg.min_shift_px)
        for dx, dy, _ in sorted(peaks, key=lambda peak: -peak[2]):
            if len(shifts) > cfg.shift_peaks:
                break
            if all(math.hypot(dx - x, dy - y) > cfg.min_shift_px for x, y in shifts):
                shifts.append((dx, dy))
        return shifts[1:]

    def plain_steps(self, left: np.ndarray, right: np.ndarray
                    ) -> Generator[None, None, np.ndarray]:
        """Return :meth:`candidates` without the shifted alignment, as two resumable steps.

        The forward flow, then the backward flow, the samples and the fits: the first
        ``next()`` runs the first step (about 40 % of the whole), the second the rest and
        raises ``StopIteration`` whose ``value`` is ``candidates(left, right,
        shifted=False)``, the same planes bit for bit (the flows start from nothing, so other
        calls in between change nothing). The images are copied: the caller may reuse its
        buffers.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image (the same size).

        Returns:
            A generator; its return value is (K, 3, 3) float64 as :meth:`candidates`.

        Raises:
            ValueError: If the images are not 2-D uint8 arrays of the same size (at once).

        """
        _check_pair(left, right)
        scale = min(1.0, self.config.width_px / left.shape[1])
        small_l = _reduce(left, scale).copy()
        small_r = _reduce(right, scale).copy()
        return self._plain_steps(small_l, small_r, scale)

    def _plain_steps(self, small_l: np.ndarray, small_r: np.ndarray, scale: float
                     ) -> Generator[None, None, np.ndarray]:
        if min(small_l.shape) < MIN_SIZE_PX:
            return np.zeros((0, 3, 3))
        forward = self._flow.calc(small_l, small_r, None)
        yield
        backward = self._flow.calc(small_r, small_l, None)
        to_full = np.diag([1.0 / scale, 1.0 / scale, 1.0])
        from_full = np.diag([scale, scale, 1.0])
        out = [to_full @ h @ from_full for h in self._fitted(
            *self._matched(small_l, forward, backward), small_l.shape[0])]
        return np.stack([h / h[2, 2] for h in out]) if out else np.zeros((0, 3, 3))

    def _fitted(self, src: np.ndarray, dst: np.ndarray, height: int) -> list[np.ndarray]:
        """Return the homographies fitted to each image part's samples, one after the other."""
        cfg = self.config
        out = []
        for top in cfg.lower_parts:
            keep = src[:, 1] >= top * height
            part_src, part_dst = src[keep], dst[keep]
            for _ in range(cfg.planes_per_part):
                fitted = _fit(part_src, part_dst, cfg.threshold_px)
                if fitted is None:
                    break
                h, inliers = fitted
                out.append(h)
                part_src, part_dst = part_src[~inliers], part_dst[~inliers]
        return out

    def refine(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
               near_px: float = REFINE_NEAR_PX, finish: bool = False) -> np.ndarray | None:
        """Return a plane moved onto the dense flow that is left after warping by it.

        The right image is warped into the left view by ``homography`` and aligned to the left
        image by DIS flow (``refine_preset``) at full resolution up to ``refine_width_px``
        (the flow's noise grows with the image's reduction: from the corners' finished plane
        of 71 rendered 640x480 tuning scenes, cold and rough rigs, the median error after one
        refinement was 0.27 px at 320 px wide, 0.10 px at 640, against 0.14 px for the
        corners, medium preset; at 640 px no plane came out more than 0.1 px worse than the
        corners'; the fast preset was about as good there but moved KITTI 000046's road
        plane from 0.6 to 1.3 px); a homography is fitted robustly
        (MAGSAC++, :data:`REFINE_THRESHOLD_PX`) to the textured samples whose residual flow is
        under ``near_px``, the plane's own pixels, and composed with the plane.
        This is a photometric refinement: it corrects the bias of the corners' closest-point
        fit on anisotropic texture (planks, tiles), where corners are found at slightly
        different floor points in the two views. The caller verifies the result.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image (the same size).
            homography: (3, 3) float64 left-to-right plane homography.
            near_px: Largest residual flow of the samples fitted, pixels at the working width.
            finish: Work at ``finish_width_px`` instead of ``refine_width_px`` (a search's
                winner: KITTI 000046, 1242 px wide, whole image, came 0.60 / 0.67 px from the
                road with the default / KITTI prior refined at 640 px, 0.49 / 0.48 px at full
                resolution).

        Returns:
            (3, 3) float64 homography with ``H[2, 2] == 1``, or None if too few samples, no
            model or images smaller than :data:`MIN_SIZE_PX`.

        Raises:
            ValueError: If the images are not 2-D uint8 arrays of the same size.

        """
        width = self.config.finish_width_px if finish else self.config.refine_width_px
        small_l, small_r, scale = _working_pair(left, right, width)
        if min(small_l.shape) < MIN_SIZE_PX:
            return None
        to_small = np.diag([scale, scale, 1.0])
        to_full = np.diag([1.0 / scale, 1.0 / scale, 1.0])
        h_small = to_small @ np.asarray(homography, np.float64) @ to_full
        warped, covered = _warped_into_left(small_l, small_r, h_small)
        src, dst = self._samples(small_l, warped, REFINE_STEP_PX,
                                 REFINE_MAX_FORWARD_BACKWARD_PX, self._refine_flow,
                                 self.config.refine_min_gradient)
        rows, cols = src[:, 1].astype(np.intp), src[:, 0].astype(np.intp)
        near = (np.hypot(*(dst - src).T) < near_px) & covered[rows, cols]
        if np.count_nonzero(near) < REFINE_MIN_SAMPLES:
            return None
        fitted = _fit(src[near], dst[near], REFINE_THRESHOLD_PX)
        if fitted is None:
            return None
        out = np.asarray(homography, np.float64) @ to_full @ fitted[0] @ to_small
        if not np.all(np.isfinite(out)) or abs(out[2, 2]) < 1e-12:
            return None
        return out / out[2, 2]

    def beyond_share(self, left: np.ndarray, right: np.ndarray, homography: np.ndarray,
                     swapped: bool = False) -> float:
        """Return the share of the textured flow samples that lie beyond the plane.

        Nothing is seen beyond the ground: every point of the scene stands on it or above it,
        nearer the head along its ray, so its disparity is at least the plane's. The right
        image is warped into the left view by ``homography`` and aligned to the left image by
        DIS flow at ``width_px``; a sample (every :data:`REFINE_STEP_PX` pixels, textured,
        forward and backward flow agreeing within ``max_forward_backward_px``, inside the
        warp) lies beyond the plane when its residual flow points by more than
        :data:`BEYOND_PX` the way of less disparity: right for a correctly ordered head
        (the right camera sees nearer points further left), left for ``swapped`` cameras (the
        plane is read as one of swapped cameras, whose disparity has the other sign). A
        periodic floor's look-alike of the other hypothesis matches the floor's repeats but
        not what is not periodic (the boxes, the tiles' shading), and that residual lies beyond
        it. The test is local: parallax beyond the flow's reach is not measured.

        Args:
            left: (H, W) uint8 left image.
            right: (H, W) uint8 right image (the same size).
            homography: (3, 3) float64 left-to-right plane homography.
            swapped: Read the plane as one of swapped cameras.

        Returns:
            The share in [0, 1]; 0 when no sample is kept or the images are smaller than
            :data:`MIN_SIZE_PX`.

        Raises:
            ValueError: If the images are not 2-D uint8 arrays of the same size.

        """
        small_l, small_r, scale = _working_pair(left, right, self.config.width_px)
        if min(small_l.shape) < MIN_SIZE_PX:
            return 0.0
        h_small = (np.diag([scale, scale, 1.0]) @ np.asarray(homography, np.float64)
                   @ np.diag([1.0 / scale, 1.0 / scale, 1.0]))
        warped, covered = _warped_into_left(small_l, small_r, h_small)
        src, dst = self._samples(small_l, warped, REFINE_STEP_PX)
        inside = covered[src[:, 1].astype(np.intp), src[:, 0].astype(np.intp)]
        if not np.any(inside):
            return 0.0
        residual = (dst[inside, 0] - src[inside, 0]) * (-1.0 if swapped else 1.0)
        return float(np.count_nonzero(residual > BEYOND_PX) / residual.size)

    def _samples(self, left: np.ndarray, right: np.ndarray, step: int | None = None,
                 max_forward_backward: float | None = None, dis: Any = None,
                 min_gradient: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return (N, 2) float32 left samples and their flow targets in the right image.

        Samples every ``step`` pixels (default ``step_px``) whose flow agrees forward and
        backward within ``max_forward_backward`` (default ``max_forward_backward_px``), by
        the DIS flow ``dis`` (default the alignment's), where the gradient is over
        ``min_gradient`` (default the config's).
        """
        dis = self._flow if dis is None else dis
        return self._matched(left, dis.calc(left, right, None), dis.calc(right, left, None),
                             step, max_forward_backward, min_gradient)

    def _matched(self, left: np.ndarray, forward: np.ndarray, backward: np.ndarray,
                 step: int | None = None, max_forward_backward: float | None = None,
                 min_gradient: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return :meth:`_samples` from the (H, W, 2) float32 forward and backward flows."""
        cfg = self.config
        step = cfg.step_px if step is None else step
        limit = cfg.max_forward_backward_px if max_forward_backward is None \
            else max_forward_backward
        least = cfg.min_gradient if min_gradient is None else min_gradient
        height, width = left.shape
        ys, xs = np.mgrid[2:height - 2:step, 2:width - 2:step]
        flow = forward[ys, xs]
        tx = (xs + flow[..., 0]).astype(np.float32)
        ty = (ys + flow[..., 1]).astype(np.float32)
        # The maps keep the grid's 2-D shape: remap refuses maps of 32767 columns or more.
        back = cv2.remap(backward, tx, ty, cv2.INTER_LINEAR).reshape(-1, 2)
        ys, xs, flow, tx, ty = ys.ravel(), xs.ravel(), flow.reshape(-1, 2), tx.ravel(), ty.ravel()
        disagreement = np.hypot(flow[:, 0] + back[:, 0], flow[:, 1] + back[:, 1])
        grad = _gradient(left)[ys, xs]
        keep = ((tx >= 0) & (tx <= width - 1) & (ty >= 0) & (ty <= height - 1)
                & (disagreement < limit) & (grad > least))
        src = np.stack([xs[keep], ys[keep]], axis=1).astype(np.float32)
        dst = np.stack([tx[keep], ty[keep]], axis=1).astype(np.float32)
        return src, dst


def _check_pair(left: np.ndarray, right: np.ndarray) -> None:
    """Raise ValueError unless both images are 2-D uint8 arrays of the same size."""
    if (left.ndim != 2 or left.dtype != np.uint8 or right.shape != left.shape
            or right.dtype != np.uint8):
        raise ValueError('left and right must be 2-D uint8 images of the same size, got '
                         f'{left.shape} {left.dtype} and {right.shape} {right.dtype}')


def _warped_into_left(small_l: np.ndarray, small_r: np.ndarray, h_small: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Return the right image warped into the left view by ``h_small`` and where it covers."""
    size = (small_l.shape[1], small_l.shape[0])
    flags = cv2.WARP_INVERSE_MAP
    warped = cv2.warpPerspective(small_r, h_small, size, flags=cv2.INTER_LINEAR | flags,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    covered = cv2.warpPerspective(np.full_like(small_r, 255), h_small, size,
                                  flags=cv2.INTER_NEAREST | flags) > 0
    return warped, covered


def _working_pair(left: np.ndarray, right: np.ndarray, width_px: int
                  ) -> tuple[np.ndarray, np.ndarray, float]:
    """Check the pair; return both (h, w) uint8 images reduced to at most ``width_px`` wide.

    Returns the reduced left and right images and the scale (at most 1) they were reduced by.
    Raises ValueError as :func:`_check_pair`.
    """
    _check_pair(left, right)
    scale = min(1.0, width_px / left.shape[1])
    return _reduce(left, scale), _reduce(right, scale), scale


def _dominant_shift(left: np.ndarray, right: np.ndarray) -> tuple[float, float]:
    """Return the lower half's dominant left-to-right displacement (phase correlation), px."""
    half = left.shape[0] // 2
    a = left[half:].astype(np.float32)
    b = right[half:].astype(np.float32)
    window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(a, b, window)
    if not (math.isfinite(dx) and math.isfinite(dy)):
        return 0.0, 0.0
    return float(dx), float(dy)


def _strip_peaks(left: np.ndarray, right: np.ndarray, count: int, min_shift_px: float
                 ) -> list[tuple[float, float, float]]:
    """Return up to ``count`` phase-correlation peaks (dx, dy, height) of one image strip.

    ``left`` and ``right`` are the strip's (h, w) uint8 rows of the two images (no peak if
    either side is under 8 px, or the strip has no texture). The strips are correlated at
    half their size (the floor's texture is smoothed, the peaks sharpen); only displacements
    pointing left by at least ``min_shift_px`` are kept (pixels of the strip's full size),
    strongest first.
    """
    if min(left.shape) < 8:
        return []
    a = cv2.resize(left, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA).astype(np.float32)
    b = cv2.resize(right, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA).astype(np.float32)
    window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    spectrum = np.conj(np.fft.fft2((a - a.mean()) * window)) * np.fft.fft2((b - b.mean()) * window)
    spectrum /= np.abs(spectrum) + 1e-9
    surface = np.fft.fftshift(np.real(np.fft.ifft2(spectrum))).astype(np.float32)
    if not surface.max() > surface.min():
        return []  # an untextured strip (a black border): every pixel would be a 'peak'
    centre_y, centre_x = surface.shape[0] // 2, surface.shape[1] // 2
    ys, xs = np.nonzero(surface == cv2.dilate(surface, np.ones((3, 3), np.uint8)))
    dx, dy = 2.0 * (xs - centre_x), 2.0 * (ys - centre_y)
    keep = dx <= -min_shift_px
    order = np.argsort(-surface[ys[keep], xs[keep]])[:count]
    return [(float(dx[keep][i]), float(dy[keep][i]), float(surface[ys[keep][i], xs[keep][i]]))
            for i in order]


def _translated(image: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Return the image moved by (dx, dy) pixels (linear interpolation, border black)."""
    move = np.float32([[1.0, 0.0, dx], [0.0, 1.0, dy]])
    return cv2.warpAffine(image, move, (image.shape[1], image.shape[0]), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def _reduce(image: np.ndarray, scale: float) -> np.ndarray:
    if scale >= 1.0:
        return np.ascontiguousarray(image)  # DIS refuses a view that is not contiguous
    return cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def _gradient(image: np.ndarray) -> np.ndarray:
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1)
    return cv2.GaussianBlur(cv2.magnitude(gx, gy), (5, 5), 0)


def _fit(src: np.ndarray, dst: np.ndarray, threshold_px: float
         ) -> tuple[np.ndarray, np.ndarray] | None:
    """Fit a homography robustly: it and its (N,) bool inliers; None if too few or no model."""
    if src.shape[0] < 20:
        return None
    h, inliers = cv2.findHomography(src, dst, cv2.USAC_MAGSAC, threshold_px, maxIters=2000,
                                    confidence=0.999)
    if h is None or not np.all(np.isfinite(h)) or abs(h[2, 2]) < 1e-12 or inliers is None:
        return None
    return h, inliers.ravel().astype(bool)
