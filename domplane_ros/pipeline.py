"""One object per stereo stream: features, warm start or prior, estimate, mask.

The live node and the offline replay are thin adapters around :class:`PlanePipeline`, so the
same frames give the same results in both. All state that lives across frames (the last good
homography, its energy, the lock state, the counters) lives here and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import time

from domplane_ros.config import PlaneNodeConfig, PriorConfig
from domplane_ros.estimator import estimate_plane, FailedEstimate, PlaneEstimate
from domplane_ros.features import detect_corners, roi_to_pixels
from domplane_ros.health import homography_problem, inlier_spread, PairChecks, texture_note
from domplane_ros.homography import apply_homography
from domplane_ros.image import check_gray
from domplane_ros.lines import detect_lines, endpoints
from domplane_ros.mask import overlay, plane_mask
from domplane_ros.prior import prior_candidates
import numpy as np

# Lock states reported in diagnostics.
SEARCHING = 'searching'
LOCKED = 'locked'

# Margin (fraction of the image diagonal) around the image-corner positions that the prior's
# candidates reach; a homography moving a corner beyond it violates the prior.
_PRIOR_BOUNDS_MARGIN = 0.15


@dataclass(frozen=True)
class FrameResult:
    """What the pipeline made of one stereo pair.

    Attributes:
        stamp_ns: The pair's stamp (the left image's), nanoseconds.
        ok: Whether a plane was found; if not, ``homography`` is None and the mask is all 0.
        homography: (3, 3) float64 left-to-right homography with ``H[2, 2] == 1``, or None.
        mask: (H, W) uint8 left-image mask: 255 plane, 127 obstacle, 0 unknown.
        estimate: The estimator's result (success or failure value).
        left_points: (N, 2) float64 left corners.
        right_points: (M, 2) float64 right corners.
        reinitialised: True if this frame started from the prior or the configured initial
            homography rather than the last frame's result.
        reason: Why the frame failed ('' when ok).
        state: Lock state after this frame: ``'locked'`` or ``'searching'``.
        timings_ms: Milliseconds spent in ``features``, ``estimate``, ``mask`` and ``total``.
        warnings: Input problems that did not refuse the pair (a stamp jump, a size change),
            each a one-line message (see :mod:`domplane_ros.health`).
        left_lines: (K, 4) float64 left line segments ``(x1, y1, x2, y2)`` (empty unless
            ``features.kind`` is ``lines`` or ``both``).
        right_lines: (L, 4) float64 right line segments.

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

    @property
    def n_inliers(self) -> int:
        """Return the number of inlier left points (0 on failure)."""
        return self.estimate.n_inliers if self.estimate is not None else 0


@dataclass
class PipelineStats:
    """Counters since the pipeline was made."""

    frames: int = 0
    succeeded: int = 0
    failed: int = 0
    reinitialisations: int = 0
    resets: int = 0


class PlanePipeline:
    """Dominant-plane estimation over a stream of stereo pairs.

    Args:
        config: The whole configuration (the node's parameters).

    """

    def __init__(self, config: PlaneNodeConfig | None = None) -> None:
        """Start with no warm start: the first frame re-initialises."""
        self.config = config if config is not None else PlaneNodeConfig()
        self.stats = PipelineStats()
        self._last_h: np.ndarray | None = None
        self._last_energy_per_point: float | None = None
        self.checks = PairChecks(self.config.pipeline.max_clipped_fraction,
                                 self.config.pipeline.max_stamp_jump_s)
        self._bounds_cache: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    @property
    def last_homography(self) -> np.ndarray | None:
        """Return the warm start for the next frame, or None (the next frame re-initialises)."""
        return None if self._last_h is None else self._last_h.copy()

    @property
    def state(self) -> str:
        """Return the lock state: ``'locked'`` while a warm start exists."""
        return LOCKED if self._last_h is not None else SEARCHING

    def update_config(self, config: PlaneNodeConfig) -> None:
        """Use a new configuration from the next frame on, keeping the warm start.

        A changed prior or initial homography drops the warm start.
        """
        if (config.prior != self.config.prior
                or config.initial_homography != self.config.initial_homography):
            self.reset()
            self._bounds_cache.clear()
        self.config = config
        self.checks.max_clipped_fraction = config.pipeline.max_clipped_fraction
        self.checks.max_stamp_jump_s = config.pipeline.max_stamp_jump_s

    def reset(self) -> None:
        """Drop the warm start: the next frame re-initialises from the prior."""
        if self._last_h is not None:
            self.stats.resets += 1
        self._last_h = None
        self._last_energy_per_point = None

    def process(self, left: np.ndarray, right: np.ndarray, stamp_ns: int,
                reset: bool = False) -> FrameResult:
        """Estimate the plane for one stereo pair.

        Args:
            left: (H, W) uint8 left grey image.
            right: (H', W') uint8 right grey image.
            stamp_ns: The pair's stamp in nanoseconds; a stamp older than the last one (clock
                reset, bag loop) or more than ``pipeline.max_stamp_jump_s`` newer drops the
                warm start.
            reset: Drop the warm start before this frame.

        Returns:
            The :class:`FrameResult`; it is never a non-finite homography. Pairs that
            :class:`~domplane_ros.health.PairChecks` refuses (sizes differ, a frozen camera,
            a black or saturated frame), too few features, inliers with too little spread
            (``pipeline.min_inlier_spread``) and homographies outside the prior are failures
            with the reason, a mask of zeros and no homography.

        Raises:
            ValueError: If an image is not a 2-D uint8 array.

        """
        t0 = time.perf_counter()
        check_gray(left, 'left')
        check_gray(right, 'right')
        check = self.checks.check(left, right, stamp_ns)
        if reset or check.reset:
            self.reset()
        self.stats.frames += 1
        cfg = self.config
        if check.refused:
            return self._refused(left, stamp_ns, check.refused, check.warnings, t0)
        feats = _detect(left, right, cfg)
        left_pts, right_pts = feats[0], feats[1]
        n_features = left_pts.shape[0] + feats[2].shape[0]
        t1 = time.perf_counter()
        height, width = left.shape
        reinit = self._last_h is None
        estimate = self._estimate(feats, (width, height))
        if estimate.ok and not reinit:
            reason = self._suspicious(estimate, n_features, (width, height))
            if reason:
                # The warm start went astray: start again from the prior in this frame.
                reinit = True
                self._last_h = None
                estimate = self._estimate(feats, (width, height))
        elif not estimate.ok and not reinit:
            reinit = True
            self._last_h = None
            estimate = self._estimate(feats, (width, height))
        if reinit:
            self.stats.reinitialisations += 1
        reason = estimate.reason
        if estimate.ok:
            reason = self._suspicious(estimate, n_features, (width, height), energy=False)
            if reason:
                self.checks.counts['outside_prior'] += 1
            else:
                reason = self._input_problem(estimate, left_pts, (width, height))
        elif (n_features < cfg.estimator.min_inliers
              or right_pts.shape[0] + feats[3].shape[0] < 4):
            self.checks.counts['too_few_features'] += 1
            reason += (f' (left {texture_note(left)}; right {texture_note(right)})')
        t2 = time.perf_counter()
        if estimate.ok and not reason:
            h = estimate.homography
            mask = plane_mask(left, right, h, cfg.mask)
            self._last_h = h
            self._last_energy_per_point = estimate.final_energy / max(n_features, 1)
            self.stats.succeeded += 1
            ok = True
        else:
            mask = np.zeros(left.shape, np.uint8)
            self._last_h = None
            self._last_energy_per_point = None
            self.stats.failed += 1
            h = None
            ok = False
        t3 = time.perf_counter()
        timings = {'features': 1e3 * (t1 - t0), 'estimate': 1e3 * (t2 - t1),
                   'mask': 1e3 * (t3 - t2), 'total': 1e3 * (t3 - t0)}
        return FrameResult(stamp_ns=stamp_ns, ok=ok, homography=h, mask=mask,
                           estimate=estimate, left_points=left_pts, right_points=right_pts,
                           reinitialised=reinit, reason='' if ok else reason,
                           state=self.state, timings_ms=timings, warnings=check.warnings,
                           left_lines=feats[2], right_lines=feats[3])

    def _refused(self, left: np.ndarray, stamp_ns: int, reason: str,
                 warnings: tuple[str, ...], t0: float) -> FrameResult:
        """Return the failed frame of a refused pair; the warm start is dropped."""
        self._last_h = None
        self._last_energy_per_point = None
        self.stats.failed += 1
        empty = np.zeros((0, 2), np.float64)
        total_ms = 1e3 * (time.perf_counter() - t0)
        return FrameResult(stamp_ns=stamp_ns, ok=False, homography=None,
                           mask=np.zeros(left.shape, np.uint8), estimate=FailedEstimate(reason),
                           left_points=empty, right_points=empty, reinitialised=False,
                           reason=reason, state=self.state,
                           timings_ms={'features': 0.0, 'estimate': 0.0, 'mask': 0.0,
                                       'total': total_ms},
                           warnings=warnings)

    def _input_problem(self, estimate: PlaneEstimate, left_pts: np.ndarray,
                       size: tuple[int, int]) -> str:
        """Return why a converged estimate must not be published ('' if it may be)."""
        problem = homography_problem(estimate.homography)
        if problem:
            self.checks.counts['invalid_homography'] += 1
            return problem
        min_spread = self.config.pipeline.min_inlier_spread
        if min_spread > 0:
            x0, y0, x1, y1 = roi_to_pixels(self.config.features.roi, *size)
            # Inlier corners and the endpoints of inlier segments.
            inliers = np.concatenate([
                left_pts[estimate.inliers],
                endpoints(estimate.left_lines[estimate.line_inliers])])
            spread = inlier_spread(inliers, float((x1 - x0) * (y1 - y0)))
            if spread < min_spread:
                self.checks.counts['degenerate_geometry'] += 1
                return (f'degenerate geometry: the inliers span {100 * spread:.2f} % of the '
                        f'region of interest (< pipeline.min_inlier_spread {min_spread:g}); '
                        'collinear or packed in one patch, they do not constrain the plane')
        return ''

    def _estimate(self, feats: tuple[np.ndarray, ...], size: tuple[int, int]
                  ) -> PlaneEstimate | FailedEstimate:
        cfg = self.config
        left_pts, right_pts, left_lines, right_lines = feats
        n_left = left_pts.shape[0] + left_lines.shape[0]
        n_right = right_pts.shape[0] + right_lines.shape[0]
        if n_left < cfg.estimator.min_inliers:
            return FailedEstimate(f'too few left features: {n_left} < '
                                  f'min_inliers {cfg.estimator.min_inliers}')
        if n_right < 4:
            return FailedEstimate(f'too few right features: {n_right}')
        lines = ({} if cfg.features.kind == 'points'
                 else {'left_lines': left_lines, 'right_lines': right_lines})
        if self._last_h is not None:
            warm = replace(cfg.estimator, gnc_start_px=min(cfg.estimator.gnc_start_px,
                                                           cfg.pipeline.warm_gnc_start_px))
            return estimate_plane(left_pts, right_pts, self._last_h, warm, **lines)
        if cfg.initial_homography:
            first = estimate_plane(left_pts, right_pts, np.array(cfg.initial_homography),
                                   cfg.estimator, **lines)
            if first.ok and not self._suspicious(first, n_left, size, energy=False):
                return first
        return estimate_plane(left_pts, right_pts, None, cfg.estimator, prior=cfg.prior,
                              image_size=size, **lines)

    def _suspicious(self, estimate: PlaneEstimate, n_points: int, size: tuple[int, int],
                    energy: bool = True) -> str:
        """Return why an estimate should not be trusted ('' if it can be)."""
        cfg = self.config.pipeline
        if energy and self._last_energy_per_point is not None:
            per_point = estimate.final_energy / max(n_points, 1)
            limit = cfg.max_energy_ratio * max(self._last_energy_per_point, 1e-3)
            if per_point > limit:
                return (f'energy jump: {per_point:.3g} per point > {cfg.max_energy_ratio} x '
                        f'last {self._last_energy_per_point:.3g}')
        if cfg.check_prior_bounds:
            low, high = self._prior_bounds(size)
            corners = _image_corners(*size)
            mapped = apply_homography(estimate.homography, corners)
            if np.any(mapped < low) or np.any(mapped > high):
                return 'homography outside the prior: an image corner maps beyond its range'
        return ''

    def _prior_bounds(self, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        if size not in self._bounds_cache:
            cands = prior_candidates(_bounds_prior(self.config.prior), *size)
            corners = _image_corners(*size)
            mapped = np.stack([apply_homography(h, corners) for h in cands])
            margin = _PRIOR_BOUNDS_MARGIN * float(np.hypot(*size))
            self._bounds_cache[size] = (mapped.min(axis=0) - margin,
                                        mapped.max(axis=0) + margin)
        return self._bounds_cache[size]


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


def _detect(left: np.ndarray, right: np.ndarray, cfg: PlaneNodeConfig
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return left and right corners and segments, as ``features.kind`` asks."""
    kind = cfg.features.kind
    none_pts = np.zeros((0, 2))
    none_seg = np.zeros((0, 4))
    if kind == 'lines':
        left_pts = right_pts = none_pts
    else:
        left_pts = detect_corners(left, cfg.features)
        right_pts = detect_corners(right, cfg.features)
    if kind == 'points':
        left_seg = right_seg = none_seg
    else:
        left_seg = detect_lines(left, cfg.features)
        right_seg = detect_lines(right, cfg.features)
    return left_pts, right_pts, left_seg, right_seg


def _bounds_prior(prior: PriorConfig) -> PriorConfig:
    """Return the prior sampled at its range ends and middle, for the bounds check."""
    return replace(prior, samples=3)


def _image_corners(width: int, height: int) -> np.ndarray:
    return np.array([[0.0, 0.0], [width - 1.0, 0.0], [width - 1.0, height - 1.0],
                     [0.0, height - 1.0]])
