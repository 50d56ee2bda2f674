"""What the pipeline made of one stereo pair, its debug picture, and its working state."""

from __future__ import annotations

from dataclasses import dataclass, field

from domplane_ros.core.mask import NOT_MEASURED, overlay, ParallaxMask
from domplane_ros.core.result import FailedEstimate, PlaneEstimate
from domplane_ros.stream.refusals import Refusal
import numpy as np


@dataclass(frozen=True)
class FrameResult:
    """What the pipeline made of one stereo pair.

    Attributes:
        stamp_ns: The pair's stamp (the left image's), nanoseconds.
        ok: Whether a plane was found; if not, ``homography`` is None and the mask is all 0.
        homography: (3, 3) float64 left-to-right homography with ``H[2, 2] == 1``, or None.
        mask: (H, W) uint8 left-image mask: 255 plane, 127 obstacle, 0 unknown.
        parallax: (h, w) float32 residual parallax after the plane warp at the mask's working
            scale, full-resolution pixels, ``NOT_MEASURED`` (-1) where not measured; None
            when no plane was found (see :func:`parallax_image`).
        estimate: The estimator's result (success or failure value).
        left_points: (N, 2) float64 left corners.
        right_points: (M, 2) float64 right corners.
        reinitialised: True if this frame worked on the prior search (or the configured
            initial homography) rather than a warm start.
        reason: Why the frame failed ('' when ok).
        state: Lock state after this frame: ``'locked'``, ``'tracking'`` or ``'searching'``.
        timings_ms: Milliseconds spent in ``features``, ``tracking``, ``estimate``, ``mask``
            and ``total``; ``challenge`` is the part of ``estimate`` spent on the lock's
            challenge (:mod:`domplane_ros.stream.challenge`).
        warnings: Input problems that did not refuse the pair (a stamp jump, a size change),
            each a one-line message (see :mod:`domplane_ros.stream.health`).
        left_lines: (K, 4) float64 left line segments ``(x1, y1, x2, y2)`` (empty unless
            ``features.kind`` is ``lines`` or ``both``).
        right_lines: (L, 4) float64 right line segments.
        warm_start: Where this frame's estimate started: ``'prediction'`` (the last
            homography moved through the tracked camera motion), ``'last'`` (the last
            homography as is), ``'search'`` (prior candidates), ``'initial'`` (the
            configured initial homography), ``'challenger'`` (a plane that beat the lock),
            ``'photometric'`` (too few corners: the coarse alignment's or the prediction's
            plane refined photometrically, no corner inliers).
        prediction: (3, 3) float64 predicted homography ``M_right H M_left^-1`` of this frame,
            or None when tracking gave none.
        candidates: Prior candidates refined in this frame (at most
            ``pipeline.search_candidates_per_frame``).
        fast_motion: True if the head's joints moved faster than
            ``pipeline.fast_joint_velocity``.
        confidence: The published plane's verification confidence in [0, 1] (0.5 at
            ``verification.min_score``, 1 at 0.1 above it); 0 when no plane was published.
        refusals: Every refusal that turned this pair's course, in order
            (:mod:`domplane_ros.stream.refusals`): the warm plane (after its widened retry)
            or the warm start, the photometric refinement of a lock, the search's finished
            winner and the search's end, and a challenger refused as not the ground (the
            lock stays). ``reason`` is the last word only: a warm plane
            refused and re-found by a search in the same pair has a plane, no reason, and
            its refusal here. Candidates judged inside a search are not listed.
        lock_lost: Why the lock held before this pair was lost in it, or None.

    """

    stamp_ns: int
    ok: bool
    homography: np.ndarray | None
    mask: np.ndarray
    estimate: PlaneEstimate | FailedEstimate
    left_points: np.ndarray
    right_points: np.ndarray
    reinitialised: bool
    reason: str
    state: str
    timings_ms: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    left_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    right_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    warm_start: str = ''
    prediction: np.ndarray | None = None
    candidates: int = 0
    fast_motion: bool = False
    confidence: float = 0.0
    parallax: np.ndarray | None = None
    refusals: tuple[Refusal, ...] = ()
    lock_lost: Refusal | None = None

    @property
    def n_inliers(self) -> int:
        """Return the number of inlier left points (0 on failure)."""
        return self.estimate.n_inliers if self.estimate is not None else 0


def debug_overlay(left: np.ndarray, result: FrameResult) -> np.ndarray:
    """Return the (H, W, 3) uint8 RGB debug image of a frame: mask tint, features.

    Inlier corners are cyan circles and inlier segments cyan lines; the rest magenta (all of
    them when no plane was found).

    Args:
        left: (H, W) uint8 left image of the frame.
        result: The pipeline's result for it.

    """
    pts = result.left_points
    segs = result.left_lines
    est = result.estimate
    if result.ok and pts.shape[0] == est.inliers.shape[0]:
        inl = est.inliers
    else:
        inl = np.zeros(pts.shape[0], bool)
    if result.ok and segs.shape[0] == est.line_inliers.shape[0]:
        line_inl = est.line_inliers
    else:
        line_inl = np.zeros(segs.shape[0], bool)
    return overlay(left, result.mask, pts[inl], pts[~inl], segs[line_inl], segs[~line_inl])


def parallax_image(result: FrameResult) -> np.ndarray:
    """Return the (H, W) float32 residual parallax of a frame at the mask's size.

    Full-resolution pixels, nearest-neighbour upsampled from the mask's working scale;
    ``NOT_MEASURED`` (-1) where it was not measured, everywhere when no plane was found.
    """
    if result.parallax is None:
        return np.full(result.mask.shape, NOT_MEASURED, np.float32)
    return ParallaxMask(result.mask, result.parallax).parallax_image()


@dataclass
class PairStep:
    """What the pipeline's estimation of one pair got to (its working state, not a result)."""

    estimate: PlaneEstimate | FailedEstimate | None = None
    accepted: bool = False
    reason: str = ''
    warm_start: str = ''
    prediction: np.ndarray | None = None
    candidates: int = 0
    reinitialised: bool = False
    keep_previous: bool = False
    confidence: float = 0.0
    initial: PlaneEstimate | None = None
    left: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    right: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.uint8))
    challenge_s: float = 0.0
    track_lost: bool = False  # the previous pair could not be tracked into this one
    refusals: list[Refusal] = field(default_factory=list)
    lock_lost: Refusal | None = None

    def refuse(self, kind: str, reason: str) -> Refusal:
        """Keep a refusal (:mod:`~domplane_ros.stream.refusals`) as the pair's reason so far."""
        self.reason = reason
        self.refusals.append(Refusal(kind, reason))
        return self.refusals[-1]


def stage_timings_ms(t0: float, spans: tuple[float, float], t3: float, t4: float, t5: float,
                     challenge_s: float = 0.0) -> dict[str, float]:
    """Return the milliseconds of the features, tracking, estimate and mask, and the total.

    ``spans`` are the seconds of the features and the tracking (which interleave); the
    estimate runs from ``t3`` to ``t4`` (``challenge_s`` seconds of it on the lock's
    challenge), the mask from ``t4`` to ``t5``.
    """
    return {'features': 1e3 * spans[0], 'tracking': 1e3 * spans[1],
            'estimate': 1e3 * (t4 - t3), 'challenge': 1e3 * challenge_s,
            'mask': 1e3 * (t5 - t4), 'total': 1e3 * (t5 - t0)}
