"""The two-step iteration of Fornland & Schnörr, with Cohen's auxiliary variables.

Given left points ``p_i`` and right points ``Q`` (no correspondences), the iteration
alternates

* the local step: predict ``x_i = H(p_i)``, find the closest right point ``c_i`` (one
  cKDTree per right set), and place the auxiliary point ``a_i`` on the segment ``[x_i, c_i]``
  by the potential's rule;
* the global step: re-fit ``H`` to the pairs ``(p_i, a_i)`` by minimising the Euclidean
  energy ``1/2 sum ||H(p_i) - a_i||^2`` (Gauss-Newton in Hartley-normalised coordinates, every
  accepted step lowers it).

Both steps lower the joint energy ``E(H, a)`` (see :mod:`domplane_ros.potentials`), so the
recorded sequence is non-increasing for every potential. A step check keeps this true even
where the auxiliary rule is numerical (Geman-McClure): each point keeps its previous auxiliary
point if that is cheaper under the new ``H``. With graduated non-convexity the energy changes
with the scale, so monotonicity holds within each stage (``stage_trace`` says which).

After convergence, a Euclidean refinement fits ``H`` to the inliers' closest points.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from domplane_ros.config import EstimatorConfig, PriorConfig
from domplane_ros.homography import (apply_homography, as_homography, as_points,
                                     check_homography, count_distinct, FailedEstimation,
                                     normalise_scale, NormalisedRefiner)
from domplane_ros.potentials import make_potential, Potential
from domplane_ros.prior import prior_candidates, screen_candidates
import numpy as np
from scipy.spatial import cKDTree

_GLOBAL_STEP_ITERATIONS = 2
_POLISH_ROUNDS = 2
_POLISH_STEPS = 2
OVER_RELAXATION = 0.5


@dataclass(frozen=True)
class PlaneEstimate:
    """A successful dominant-plane estimate.

    Attributes:
        homography: (3, 3) float64, left pixel to right pixel, ``H[2, 2] == 1``.
        inliers: (N,) bool, left points on the plane (a right point within the threshold).
        matches: (N,) int64, index of each left point's closest right point.
        residuals_px: (N,) float64 final distance from each prediction to its closest point.
        iterations: Two-step iterations used, over all stages.
        energy_trace: (K,) float64 joint energy after every local step.
        stage_trace: (K,) int64 graduated non-convexity stage of each energy value.
        converged: Whether the last stage met a tolerance before the iteration cap.
        final_energy: Last value of the energy trace.
        potential: Name of the potential used.
        candidates_tried: Prior candidates that got the full iteration (0 for a warm start).

    """

    homography: np.ndarray
    inliers: np.ndarray
    matches: np.ndarray
    residuals_px: np.ndarray
    iterations: int
    energy_trace: np.ndarray
    stage_trace: np.ndarray
    converged: bool
    final_energy: float
    potential: str
    candidates_tried: int = 0
    ok: bool = field(default=True, init=False)
    reason: str = field(default='', init=False)

    @property
    def n_inliers(self) -> int:
        """Return the number of inlier left points."""
        return int(np.count_nonzero(self.inliers))

    def __bool__(self) -> bool:
        """Return True: this is a success."""
        return True


@dataclass(frozen=True)
class FailedEstimate(FailedEstimation):
    """A failed estimate: the reason, and what the iteration got to, if it ran."""

    iterations: int = 0
    energy_trace: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_inliers: int = 0
    stage_trace: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    ok: bool = field(default=False, init=False)


def _options(options: EstimatorConfig | None, overrides: dict[str, Any]) -> EstimatorConfig:
    base = options if options is not None else EstimatorConfig()
    return replace(base, **overrides) if overrides else base


def gnc_scales(options: EstimatorConfig) -> list[float]:
    """Return the scales (pixels) of the stages: one for most potentials, several for GNC.

    Args:
        options: Estimator settings.

    Returns:
        Decreasing scales ending at ``options.threshold_px``.

    """
    if options.potential != 'geman_mcclure' or options.gnc_start_px <= options.threshold_px:
        return [options.threshold_px]
    scales = []
    s = options.gnc_start_px
    while s > options.threshold_px * 1.0001:
        scales.append(s)
        s *= options.gnc_factor
    scales.append(options.threshold_px)
    return scales


class _TwoStep:
    """State of one run: left points, the right tree, and the normalised refiner."""

    def __init__(self, left: np.ndarray, right: np.ndarray, tree: cKDTree) -> None:
        self.left = left
        self.right = right
        self.tree = tree
        self.refiner = NormalisedRefiner(left, right)

    def local_step(self, pred: np.ndarray, potential: Potential
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return closest distances, match indices, aux points, and their energy terms."""
        r, idx = self.tree.query(pred)
        closest = self.right[idx]
        s = potential.step(r)
        frac = np.divide(s, r, out=np.zeros_like(r), where=r > 0)
        aux = pred + (closest - pred) * frac[:, None]
        penalty = potential.penalty(r - s)
        return r, idx, aux, penalty, 0.5 * s * s + penalty

    def run_stage(self, h: np.ndarray, potential: Potential, options: EstimatorConfig,
                  energies: list[float]) -> tuple[np.ndarray, int, bool, tuple]:
        """Iterate one stage from ``h``; append energies.

        Returns:
            ``(H, iterations, converged, (pred, r, idx))`` with the predictions of the final
            ``H`` and their closest-point distances and indices.

        """
        pred = apply_homography(h, self.left)
        r, idx, aux, penalty, terms = self.local_step(pred, potential)
        energy = float(np.sum(terms))
        energies.append(energy)
        for it in range(1, options.max_iterations + 1):
            h_new, e_before, _ = self.refiner.refine(h, aux, None, _GLOBAL_STEP_ITERATIONS)
            if OVER_RELAXATION > 0:
                ext = self.refiner.extrapolate(h, h_new, aux, OVER_RELAXATION, e_before)
                if ext is not None:
                    h_new = ext[0]
            pred_new = apply_homography(h_new, self.left)
            r, idx, aux_new, pen_new, terms_new = self.local_step(pred_new, potential)
            # Step check: keep a previous auxiliary point where it is cheaper under the new H.
            diff = pred_new - aux
            old_terms = 0.5 * np.einsum('ij,ij->i', diff, diff) + penalty
            keep_old = old_terms < terms_new
            if np.any(keep_old):
                aux_new[keep_old] = aux[keep_old]
                pen_new[keep_old] = penalty[keep_old]
                terms_new = np.where(keep_old, old_terms, terms_new)
            energy_new = float(np.sum(terms_new))
            move = float(np.max(np.abs(pred_new - pred))) if pred.size else 0.0
            energies.append(energy_new)
            decrease = energy - energy_new
            h, pred, aux, penalty, energy = h_new, pred_new, aux_new, pen_new, energy_new
            if move < options.tolerance_px or decrease <= options.energy_tolerance * max(
                    energy, 1e-300):
                return h, it, True, (pred, r, idx)
        return h, options.max_iterations, False, (pred, r, idx)

    def polish(self, h: np.ndarray, threshold_px: float, matched: tuple
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Euclidean refinement: fit H to the inliers' closest points, re-match, repeat.

        Args:
            h: (3, 3) float64 converged homography.
            threshold_px: Inlier threshold.
            matched: ``(pred, r, idx)`` of ``h`` from the last local step.

        Returns:
            The refined H, and the closest distances and indices of its predictions.

        """
        pred, r, idx = matched
        for _ in range(_POLISH_ROUNDS):
            inl = r < threshold_px
            if np.count_nonzero(inl) < 8:
                break
            target = np.where(inl[:, None], self.right[idx], pred)
            h_new, _, _ = self.refiner.refine(h, target, inl.astype(np.float64),
                                              _POLISH_STEPS)
            if check_homography(h_new):
                break
            pred_new = apply_homography(h_new, self.left)
            r_new, idx_new = self.tree.query(pred_new)
            same = np.array_equal(idx_new[inl], idx[inl]) and np.array_equal(
                r_new < threshold_px, inl)
            h, pred, r, idx = h_new, pred_new, r_new, idx_new
            if same:
                break
        return h, r, idx


def _check_inputs(left: Any, right: Any) -> tuple[np.ndarray, np.ndarray, str]:
    left = as_points(left, 'left_points')
    right = as_points(right, 'right_points')
    if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
        return left, right, 'points have non-finite coordinates'
    for pts, side in ((left, 'left'), (right, 'right')):
        if pts.shape[0] < 4:
            return left, right, f'need at least 4 {side} points, got {pts.shape[0]}'
        if count_distinct(pts, 4) < 4:
            return left, right, f'fewer than 4 distinct {side} points'
        centred = pts - pts.mean(axis=0)
        sv = np.linalg.svd(centred, compute_uv=False)
        if sv[1] <= 1e-6 * max(sv[0], 1e-300):
            return left, right, f'{side} points are collinear'
    return left, right, ''


def _estimate_from(state: _TwoStep, init: np.ndarray, options: EstimatorConfig
                   ) -> PlaneEstimate | FailedEstimate:
    energies: list[float] = []
    stages: list[int] = []
    h = init
    iterations = 0
    converged = False
    for k, scale in enumerate(gnc_scales(options)):
        potential = make_potential(options.potential, options.lambda_weight, scale)
        before = len(energies)
        h, its, converged, matched = state.run_stage(h, potential, options, energies)
        stages.extend([k] * (len(energies) - before))
        iterations += its
    trace = np.asarray(energies)
    reason = check_homography(h)
    if reason:
        return FailedEstimate(reason, iterations, trace, 0, np.asarray(stages, np.int64))
    if options.euclidean_refinement:
        h, r, idx = state.polish(h, options.threshold_px, matched)
    else:
        _, r, idx = matched
    h = normalise_scale(h)
    inliers = r < options.threshold_px
    if np.count_nonzero(inliers) < options.min_inliers:
        return FailedEstimate(
            f'too few inliers: {np.count_nonzero(inliers)} < min_inliers '
            f'{options.min_inliers}', iterations, trace, int(np.count_nonzero(inliers)),
            np.asarray(stages, np.int64))
    return PlaneEstimate(
        homography=h, inliers=inliers, matches=idx.astype(np.int64), residuals_px=r,
        iterations=iterations, energy_trace=trace, stage_trace=np.asarray(stages, np.int64),
        converged=converged, final_energy=float(trace[-1]), potential=options.potential)


def estimate_plane(left_points: Any, right_points: Any, init: Any = None,
                   options: EstimatorConfig | None = None, *,
                   prior: PriorConfig | None = None,
                   image_size: tuple[int, int] | None = None,
                   **overrides: Any) -> PlaneEstimate | FailedEstimate:
    """Estimate the dominant plane's homography from two point sets without correspondences.

    Args:
        left_points: (N, 2) float64 left image points (x, y).
        right_points: (M, 2) float64 right image points.
        init: Optional (3, 3) (or 9 values, row-major) initial homography: the warm start.
            Without it, candidates from ``prior`` are screened and the best few iterated.
        options: Estimator settings; keyword ``overrides`` (e.g. ``potential='huber'``,
            ``lambda_weight=0.3``, ``threshold_px=2.0``, ``max_iterations=50``) replace
            fields of it.
        prior: Camera set-up ranges, used when ``init`` is None (defaults to
            ``PriorConfig()``).
        image_size: ``(width, height)`` of the left image, needed with the prior (principal
            point at its centre).
        **overrides: Fields of :class:`~domplane_ros.config.EstimatorConfig`.

    Returns:
        :class:`PlaneEstimate`, or :class:`FailedEstimate` with the reason (too few,
        repeated, collinear or non-finite points, a singular initial homography, too few
        inliers).

    Raises:
        ValueError: If the arrays do not have shape (N, 2), ``init`` is not 3x3, an override
            is invalid, or neither ``init`` nor ``image_size`` is given.

    """
    options = _options(options, overrides)
    if init is None and image_size is None:
        raise ValueError('give an initial homography (init) or the image_size for the prior')
    left, right, reason = _check_inputs(left_points, right_points)
    if reason:
        return FailedEstimate(reason)
    tree = cKDTree(right)
    state = _TwoStep(left, right, tree)
    if init is not None:
        h0 = as_homography(init, 'init')
        reason = check_homography(h0)
        if reason:
            return FailedEstimate(f'initial {reason}')
        return _estimate_from(state, normalise_scale(h0), options)
    return _search_prior(state, prior or PriorConfig(), options, image_size)


def _search_prior(state: _TwoStep, prior: PriorConfig, options: EstimatorConfig,
                  image_size: tuple[int, int]) -> PlaneEstimate | FailedEstimate:
    width, height = image_size
    candidates = prior_candidates(prior, width, height)
    costs = screen_candidates(candidates, state.left, state.tree, prior.screen_threshold_px)
    order = np.argsort(costs)[:prior.refine_best]
    best: PlaneEstimate | FailedEstimate | None = None
    for i in order:
        result = _estimate_from(state, candidates[i], options)
        if best is None or _better(result, best):
            best = result
    assert best is not None
    if isinstance(best, PlaneEstimate):
        return replace(best, candidates_tried=len(order))
    return best


def _better(a: PlaneEstimate | FailedEstimate, b: PlaneEstimate | FailedEstimate) -> bool:
    if a.ok != b.ok:
        return bool(a.ok)
    if not a.ok:
        return a.n_inliers > b.n_inliers
    return a.final_energy < b.final_energy
