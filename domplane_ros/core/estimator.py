"""The two-step iteration of Fornland & Schnörr, with Cohen's auxiliary variables.

Given left points ``p_i`` and right points ``Q`` (no correspondences), the iteration
alternates

* the local step: predict ``x_i = H(p_i)``, find the closest right point ``c_i`` (one
  cKDTree per right set), and place the auxiliary point ``a_i`` on the segment ``[x_i, c_i]``
  by the potential's rule;
* the global step: re-fit ``H`` to the pairs ``(p_i, a_i)`` by minimising the Euclidean
  energy ``1/2 sum ||H(p_i) - a_i||^2`` (Gauss-Newton in Hartley-normalised coordinates, every
  accepted step lowers it).

Both steps lower the joint energy ``E(H, a)`` (see :mod:`domplane_ros.core.potentials`), so the
recorded sequence is non-increasing for every potential. A step check keeps this true even
where the auxiliary rule is numerical (Geman-McClure): each point keeps its previous auxiliary
point if that is cheaper under the new ``H``. With graduated non-convexity the energy changes
with the scale, so monotonicity holds within each stage (``stage_trace`` says which).

After convergence, a Euclidean refinement fits ``H`` to the inliers' closest points.

Line segments (:mod:`domplane_ros.core.lines`) enter the same iteration: a left segment's two
endpoints are predicted by ``H``, its closest right line is the one nearest in the pixel
distance ``D = sqrt(d(x1)^2 + d(x2)^2)`` of the predicted endpoints to that (infinite) line,
and its auxiliary variables are two points, the predicted endpoints moved toward their
projections onto that line by the potential's rule (``s = step(D)``). The global step is the
same weighted least-squares fit from left points and endpoints to their auxiliary points. With
points and lines together the energy is ``sum over points + line_weight * sum over segments``,
and every step lowers it, so the same monotonicity holds.
"""

from __future__ import annotations

from typing import Any

from domplane_ros.config import EstimatorConfig
from domplane_ros.core.basin import far_start, start_nearness
from domplane_ros.core.homography import (apply_homography, as_points,
                                          check_homography, MIN_W, normalise_scale,
                                          NormalisedRefiner, point_set_reason)
from domplane_ros.core.lines import (as_segments, endpoints, LineMatcher, lines_reason,
                                     screen_line_candidates, segment_lengths)
from domplane_ros.core.nearest import NearestPoints
from domplane_ros.core.potentials import make_potential, Potential
from domplane_ros.core.result import FailedEstimate, PlaneEstimate
from domplane_ros.core.runs import RunRecord, StageEnd, StageState
from domplane_ros.core.screening import best_screened, screen_candidates
from domplane_ros.core.stages import can_widen, gnc_scales
import numpy as np
from scipy.spatial import cKDTree

__all__ = ['FailedEstimate', 'PlaneEstimate', 'TwoStep']

_GLOBAL_STEP_ITERATIONS = 1
_POLISH_ROUNDS = 2
_POLISH_STEPS = 2
_LINE_POLISH_ROUNDS = 12
_LINE_POLISH_TOLERANCE_PX = 1e-3
# Over-relaxation of the global step: the refined H is moved this much further along its
# update, kept if the transfer energy stays at most what it was before the step.
OVER_RELAXATION = 0.5
# Extrapolation of the iteration (``TwoStep.estimate(..., extrapolate=True)``, the lock's
# challengers): from a stage's round EXTRAPOLATE_FROM on, a round that did not stop is
# followed by a trial step that repeats its move ``beta`` times (``H + beta (H - H_before)``),
# kept only if its local step gives a lower joint energy; ``beta`` starts at 1, doubles after
# every kept trial and falls back to 1 after a refused one, and the trial moves no prediction
# more than EXTRAPOLATE_MAX_MOVE_PX. Where most features are outliers, their auxiliary points
# (their own predictions) hold H back and a run creeps 0.2-0.3 px a round for 60 rounds (a
# challenger or a prior candidate at 640 x 480, 13 % inliers); the kept trials cover that in a
# few rounds. Both steps still only lower the energy. Only in a run's last stage (at
# ``threshold_px``): a graduated run's wider stages find their basin as before. Measured
# (docs/speed.md round 15): on the runs of three cold pairs and a 40-pair warm sequence
# 3661 -> 1633 rounds, 1.7 x less time, 26 of 170 planes more than 1 px elsewhere.
EXTRAPOLATE_FROM = 2
EXTRAPOLATE_MAX_MOVE_PX = 1.0


class TwoStep:
    """The two-step iteration over one feature set, its search structures built once.

    One object per feature set: the KD-tree over the right points, the right lines' matcher
    and the normalised refiner are built here and serve every run from any start (a warm
    start, each prior candidate) and the prior screening. Build it with :meth:`from_features`.

    The global step works on *rows*: one row per left point and two per left segment (its
    endpoints). A feature's share of the energy is the weighted sum over its rows, so points
    and lines enter one joint energy ``sum_f w_f (1/2 ||H(p_f) - a_f||^2 + P(d(a_f)))`` with
    ``w = 1`` for points and ``line_weight`` for segments (``||.||`` over the feature's rows).
    """

    def __init__(self, left: np.ndarray, right: np.ndarray, tree: cKDTree | None,
                 left_segments: np.ndarray | None = None,
                 matcher: LineMatcher | None = None, line_weight: float = 1.0) -> None:
        self.left = left
        self.right = right
        self.tree = tree
        self.n_points = left.shape[0]
        # Closest right points, re-queried only where a prediction moved far enough.
        self.nearest = NearestPoints(right, tree) if tree is not None else None
        self.matcher = matcher
        self.left_segments = (left_segments if left_segments is not None and matcher is not None
                              else np.zeros((0, 4)))
        self.n_lines = self.left_segments.shape[0]
        self.line_weight = float(line_weight)
        self.src = np.concatenate([left, endpoints(self.left_segments)])
        self.src_h = np.column_stack([self.src, np.ones(self.src.shape[0])])
        frame = [right] + ([endpoints(matcher.segments)] if matcher is not None else [])
        self.refiner = NormalisedRefiner(self.src, np.concatenate(frame))
        self.row_feature = np.concatenate([np.arange(self.n_points), np.repeat(
            np.arange(self.n_points, self.n_points + self.n_lines), 2)])
        self.feature_weight = np.concatenate([np.ones(self.n_points),
                                              np.full(self.n_lines, self.line_weight)])
        self.row_weight = (None if self.n_lines == 0 or self.line_weight == 1.0
                           else self.feature_weight[self.row_feature])
        # The runs' stage ends by start and settings (:meth:`_estimate_from`), and the
        # screening energies by candidate set (:meth:`screening_energy`).
        self._runs: dict[tuple, RunRecord] = {}
        self._screened: dict[tuple[bytes, float], np.ndarray] = {}

    @property
    def n_features(self) -> int:
        """Return the number of features (points plus segments)."""
        return self.n_points + self.n_lines

    def apply(self, h: np.ndarray) -> np.ndarray:
        """Return the (rows, 2) predictions of every row under ``h``."""
        uvw = self.src_h @ h.T
        if uvw.shape[0] == 0 or np.abs(uvw[:, 2]).min() < MIN_W:
            return apply_homography(h, self.src)
        return uvw[:, :2] / uvw[:, 2:3]

    def match(self, pred: np.ndarray, bound: float | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return per-feature closest distances and indices, and per-row closest positions.

        The closest position of a point row is its closest right point, of a segment's
        endpoint row its projection onto the segment's closest right line. With ``bound``,
        a point whose closest right point is ``bound`` or further gets distance inf, index
        -1 and its own prediction as closest position (the query stops early there).
        """
        n = self.n_points
        if n and not self.n_lines:
            r, idx, closest = self.nearest.query_closest(pred, bound)
            far = np.flatnonzero(idx < 0)
            closest[far] = pred[far]
            return r, idx, closest
        r = np.empty(self.n_features)
        idx = np.empty(self.n_features, np.int64)
        closest = np.empty_like(pred)
        if n:
            r[:n], idx[:n] = self.nearest.query(pred[:n], bound)
            closest[:n] = self.right[idx[:n]]
            far = np.flatnonzero(idx[:n] < 0)
            closest[far] = pred[far]
        if self.n_lines:
            d, li, c1, c2 = self.matcher.closest(pred[n::2], pred[n + 1::2])
            r[n:], idx[n:] = d, li
            closest[n::2] = c1
            closest[n + 1::2] = c2
        return r, idx, closest

    def local_step(self, pred: np.ndarray, potential: Potential
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                              np.ndarray]:
        """Return closest distances, indices, aux rows, penalties, weighted terms, closest rows.

        Distances, indices, penalties and terms are per feature; aux and closest per row.
        """
        r, idx, closest = self.match(pred, potential.saturation_px)
        s = potential.step(r)
        frac = np.divide(s, r, out=np.zeros_like(r), where=r > 0)
        aux = pred + (closest - pred) * (frac if self.n_lines == 0
                                         else frac[self.row_feature])[:, None]
        penalty = potential.penalty(r - s)
        terms = 0.5 * s * s + penalty
        if self.n_lines:  # points weigh 1
            terms *= self.feature_weight
        return r, idx, aux, penalty, terms, closest

    def run_stage(self, h: np.ndarray, potential: Potential, options: EstimatorConfig,
                  energies: list[float]) -> tuple[np.ndarray, int, bool, tuple]:
        """Iterate one stage from ``h``; append energies.

        Returns:
            ``(H, iterations, converged, (pred, r, idx, closest))`` with the predictions of
            the final ``H``, their closest distances and indices, and closest positions.

        """
        return self._iterate(self._stage_start(h, potential, energies), potential, options,
                             energies)[:4]

    def _stage_start(self, h: np.ndarray, potential: Potential, energies: list[float]
                     ) -> StageState:
        """Return the state of a stage before its first round (its energy appended)."""
        pred = self.apply(h)
        r, idx, aux, penalty, terms, closest = self.local_step(pred, potential)
        energy = float(terms.sum())
        energies.append(energy)
        return StageState(0, h, pred, r, idx, aux, penalty, energy, closest)

    def _iterate(self, state: StageState, potential: Potential, options: EstimatorConfig,
                 energies: list[float], extrapolate: bool = False
                 ) -> tuple[np.ndarray, int, bool, tuple, StageState | None]:
        """Iterate a stage on from ``state`` (round ``state.rounds + 1``); append energies.

        Returns :meth:`run_stage`'s tuple and, where the stage stopped only because a round
        moved the predictions less than ``options.tolerance_px``, its state there (from which
        a smaller tolerance iterates on exactly as a fresh run would), else None. With
        ``extrapolate`` each round that does not stop is followed by a trial step
        (:meth:`_trial`, :data:`EXTRAPOLATE_FROM`); a kept trial appends its energy too.
        """
        h, pred, r, idx, aux = state.h, state.pred, state.r, state.idx, state.aux
        penalty, energy, closest = state.penalty, state.energy, state.closest
        weights = self.row_weight
        beta = state.beta
        if state.h_before is not None and extrapolate and state.rounds >= EXTRAPOLATE_FROM:
            # Resumed where a larger tolerance stopped: that round's trial step first.
            trial, beta = self._trial(h, state.h_before, state.move, beta, potential, energy)
            if trial is not None:
                h, pred, (r, idx, aux, penalty, energy, closest) = trial
                energies.append(energy)
        for it in range(state.rounds + 1, options.max_iterations + 1):
            h_new = self.refiner.refine(h, aux, weights, _GLOBAL_STEP_ITERATIONS,
                                        OVER_RELAXATION)[0]
            pred_new = self.apply(h_new)
            r_new, idx_new, aux_new, pen_new, terms_new, closest_new = self.local_step(
                pred_new, potential)
            # Step check: keep a previous auxiliary variable where it is cheaper under the
            # new H (per feature: a segment keeps both auxiliary endpoints or neither).
            diff = pred_new - aux
            sq = np.einsum('ij,ij->i', diff, diff)
            if self.n_lines:
                sq = np.bincount(self.row_feature, weights=sq, minlength=self.n_features)
            old_terms = 0.5 * sq + penalty
            if self.n_lines:
                old_terms *= self.feature_weight
            keep_old = old_terms < terms_new
            if np.any(keep_old):
                keep_rows = keep_old[self.row_feature]
                aux_new[keep_rows] = aux[keep_rows]
                pen_new[keep_old] = penalty[keep_old]
                terms_new = np.where(keep_old, old_terms, terms_new)
            energy_new = float(terms_new.sum())
            if energy_new > energy * (1.0 + 1e-12):
                # Both steps lower the energy in exact arithmetic; a near-degenerate fit (a
                # handful of features) can break that numerically: the step is not taken.
                return h, it, True, (pred, r, idx, closest), None
            move = float(np.abs(pred_new - pred).max()) if pred.size else 0.0
            energies.append(energy_new)
            decrease = energy - energy_new
            h_before = h
            h, pred, aux, penalty, energy = h_new, pred_new, aux_new, pen_new, energy_new
            r, idx, closest = r_new, idx_new, closest_new
            settled = decrease <= options.energy_tolerance * max(energy, 1e-300)
            if move < options.tolerance_px or settled:
                stop = None if settled else StageState(it, h, pred, r, idx, aux, penalty,
                                                       energy, closest, move, beta, h_before)
                return h, it, True, (pred, r, idx, closest), stop
            if extrapolate and it >= EXTRAPOLATE_FROM:
                trial, beta = self._trial(h, h_before, move, beta, potential, energy)
                if trial is not None:
                    h, pred, (r, idx, aux, penalty, energy, closest) = trial
                    energies.append(energy)
        return h, options.max_iterations, False, (pred, r, idx, closest), None

    def _trial(self, h: np.ndarray, h_before: np.ndarray, move: float, beta: float,
               potential: Potential, energy: float
               ) -> tuple[tuple[np.ndarray, np.ndarray, tuple] | None, float]:
        """Return the extrapolation's trial step after a round, and the next ``beta``.

        The round moved ``h_before`` to ``h`` (its predictions at most ``move`` px). The trial
        ``h + beta (h - h_before)``, ``beta`` capped so that it moves the predictions about
        :data:`EXTRAPOLATE_MAX_MOVE_PX` at most (to first order), is ``(h, pred, (r, idx, aux,
        penalty, energy, closest))`` after its local step; None (and ``beta`` back to 1) where
        it is not finite, maps a row to infinity or does not lower the joint ``energy``.
        """
        if move > 0.0:
            beta = min(beta, EXTRAPOLATE_MAX_MOVE_PX / move)
        trial = h + beta * (h - h_before)
        if not np.all(np.isfinite(trial)):
            return None, 1.0
        w = self.src_h @ trial[2]
        if w.size and np.abs(w).min() < MIN_W:
            return None, 1.0  # a row at infinity: the global step could not move from there
        pred = self.apply(trial)
        if not np.all(np.isfinite(pred)):
            return None, 1.0
        r, idx, aux, penalty, terms, closest = self.local_step(pred, potential)
        trial_energy = float(terms.sum())
        if not trial_energy < energy:
            return None, 1.0
        return (trial, pred, (r, idx, aux, penalty, trial_energy, closest)), 2.0 * beta

    def polish(self, h: np.ndarray, threshold_px: float, matched: tuple
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Euclidean refinement: fit H to the inliers' closest positions, re-match, repeat.

        For segments the closest positions are the endpoints' projections onto the matched
        lines, so this minimises the point-to-line distances of the inlier segments.

        Args:
            h: (3, 3) float64 converged homography.
            threshold_px: Inlier threshold.
            matched: ``(pred, r, idx, closest)`` of ``h`` from the last local step.

        Returns:
            The refined H, and the per-feature closest distances and indices of its
            predictions.

        """
        pred, r, idx, closest = matched
        # With segments the targets (projections onto the matched lines) move with H, so the
        # refit is repeated until the predictions settle, not only until the matches do.
        rounds = _POLISH_ROUNDS if self.n_lines == 0 else _LINE_POLISH_ROUNDS
        for _ in range(rounds):
            inl = r < threshold_px
            if np.count_nonzero(inl) < 8:
                break
            inl_rows = inl[self.row_feature]
            target = np.where(inl_rows[:, None], closest, pred)
            weights = inl_rows.astype(np.float64)
            if self.row_weight is not None:
                weights = weights * self.row_weight
            h_new, _, _ = self.refiner.refine(h, target, weights, _POLISH_STEPS)
            if check_homography(h_new):
                break
            pred_new = self.apply(h_new)
            r_new, idx_new, closest_new = self.match(pred_new, threshold_px)
            same = np.array_equal(idx_new[inl], idx[inl]) and np.array_equal(
                r_new < threshold_px, inl)
            settled = float(np.max(np.abs(pred_new - pred))) < _LINE_POLISH_TOLERANCE_PX
            h, pred, r, idx, closest = h_new, pred_new, r_new, idx_new, closest_new
            if same and (self.n_lines == 0 or settled):
                break
        return h, r, idx

    @classmethod
    def from_features(cls, left_points: Any, right_points: Any, left_lines: Any = None,
                      right_lines: Any = None, line_weight: float = 1.0
                      ) -> TwoStep | FailedEstimate:
        """Validate a feature set and build its iteration, or say why it cannot fix H.

        Points alone must be 4 or more, distinct and not collinear in each image; lines alone
        4 or more and not one pencil (all concurrent or parallel). With both, a feature kind
        that cannot fix H on its own is left out, and it fails only if neither can.

        Args:
            left_points: (N, 2) float64 left points; None or (0, 2) with lines only.
            right_points: (M, 2) float64 right points.
            left_lines: Optional (K, 4) float64 left segments; with neither line set given,
                the points are used alone.
            right_lines: Optional (L, 4) float64 right segments.
            line_weight: Weight of a segment's energy relative to a point's.

        Returns:
            The :class:`TwoStep`, or a :class:`FailedEstimate` with the reason.

        Raises:
            ValueError: If an array does not have shape (N, 2) (points) or (N, 4) (segments).

        """
        use_lines = left_lines is not None or right_lines is not None
        none = np.zeros((0, 2))
        left = as_points(none if left_points is None and use_lines else left_points,
                         'left_points')
        right = as_points(none if right_points is None and use_lines else right_points,
                          'right_points')
        has_points = left.shape[0] > 0 or right.shape[0] > 0 or not use_lines
        point_reason = _points_reason(left, right) if has_points else ''
        if not use_lines:
            if point_reason:
                return FailedEstimate(point_reason)
            return cls(left, right, cKDTree(right))
        left_seg = as_segments(np.zeros((0, 4)) if left_lines is None else left_lines,
                               'left_lines')
        right_seg = as_segments(np.zeros((0, 4)) if right_lines is None else right_lines,
                                'right_lines')
        line_reason = lines_reason(left_seg, 'left') or lines_reason(right_seg, 'right')
        if line_reason:
            if point_reason or not has_points:
                return FailedEstimate('; and '.join(r for r in (point_reason, line_reason) if r))
            return cls(left, right, cKDTree(right))
        if point_reason:
            left, right = none, none
        left_seg = left_seg[segment_lengths(left_seg) > 0]
        right_seg = right_seg[segment_lengths(right_seg) > 0]
        tree = cKDTree(right) if right.shape[0] else None
        return cls(left, right, tree, left_seg, LineMatcher(right_seg), line_weight)

    def start_nearness(self, h: np.ndarray, threshold_px: float) -> str:
        """Say how near the start ``h`` looks: ``'near'``, ``'doubtful'`` or ``'far'``.

        See :func:`domplane_ros.core.basin.start_nearness`.
        """
        return start_nearness(self, h, threshold_px)

    def estimate(self, init: np.ndarray, options: EstimatorConfig, *,
                 widen: bool | None = None, extrapolate: bool = False
                 ) -> PlaneEstimate | FailedEstimate:
        """Run the iteration from ``init`` (the warm start), then the Euclidean refinement.

        Args:
            init: (3, 3) float64 initial homography.
            options: Estimator settings (its ``line_weight`` was fixed at construction).
            widen: Whether the truncated quadratic is graduated from ``options.gnc_start_px``
                (GNC), which widens its basin. None (a warm start): by how near the start
                looks (:meth:`start_nearness`): near, plain (and the far start's multi-start
                only if that fails); far, widened in a multi-start
                (:func:`domplane_ros.core.basin.far_start`);
                doubtful, both, the result of lowest energy kept. False: never (the prior's
                candidates, whose search covers far starts and whose look-alikes a wide stage
                slides into). True: one graduated run from ``init`` (the pipeline's retry of a
                refused warm plane: there the multi-start's moved starts reached a look-alike
                after a cut that passed the verification). Other potentials ignore it.
            extrapolate: Follow the last stage's rounds by extrapolated trial steps, kept
                where they lower the energy (:data:`EXTRAPOLATE_FROM`): fewer rounds where
                most features are outliers, at another minimum now and then. Not with
                ``widen`` None for a potential that can widen (the near/far choice).

        Returns:
            :class:`PlaneEstimate`, or :class:`FailedEstimate` for a singular or non-finite
            ``init`` or result, or too few inliers.

        Raises:
            ValueError: If ``extrapolate`` is asked for the near/far choice.

        """
        reason = check_homography(init)
        if reason:
            return FailedEstimate(f'initial {reason}')
        h = normalise_scale(init)
        if not can_widen(options) or widen is not None:
            return self._estimate_from(h, options, can_widen(options) and bool(widen),
                                       extrapolate)
        if extrapolate:
            raise ValueError('extrapolate needs widen given (True or False) for potential '
                             f'{options.potential!r}')
        nearness = self.start_nearness(h, options.threshold_px)
        plain = None if nearness == 'far' else self._estimate_from(h, options, False)
        if nearness == 'near' and plain.ok:
            return plain
        return far_start(self, h, lambda start: self._estimate_from(start, options, True),
                         options, plain)

    def _estimate_from(self, h: np.ndarray, options: EstimatorConfig, far: bool,
                       extrapolate: bool = False) -> PlaneEstimate | FailedEstimate:
        """Iterate every stage from the valid start ``h``, refine, and say how it ended.

        The stages' ends are kept per start and settings (:class:`RunRecord`): the same start
        run again with a tolerance no larger (a search's swapped rivals, rechecked at the
        configured tolerance after the candidates') re-uses the stages that end the same and
        iterates on from where the earlier run stopped, with the results of a fresh run.
        """
        energies: list[float] = []
        stages: list[int] = []
        iterations = 0
        converged = False
        key = RunRecord.key(h, options, far, extrapolate)
        earlier = self._runs.get(key)
        if earlier is not None and earlier.tolerance_px < options.tolerance_px:
            earlier = None  # it iterated past where this run stops
        record = RunRecord(options.tolerance_px)
        scales = gnc_scales(options, far)
        for k, scale in enumerate(scales):
            potential = make_potential(options.potential, options.lambda_weight, scale)
            # Only the last stage extrapolates: a graduated run's wider stages find their
            # basin as the plain iteration does.
            trials = extrapolate and k == len(scales) - 1
            before = len(energies)
            end = earlier.stages[k] if earlier is not None else None
            if end is None:
                out = self._iterate(self._stage_start(h, potential, energies), potential,
                                    options, energies, trials)
            else:
                energies.extend(end.energies)
                out = end.result
                if end.stopped is not None and not end.stopped.move < options.tolerance_px:
                    out = self._iterate(end.stopped, potential, options, energies, trials)
                    earlier = None  # the later stages start elsewhere
            record.stages.append(StageEnd(energies[before:], out))
            h, its, converged, matched = out[:4]
            stages.extend([k] * (len(energies) - before))
            iterations += its
        self._runs[key] = record
        trace = np.asarray(energies)
        stage_trace = np.asarray(stages, np.int64)
        reason = check_homography(h)
        if reason:
            return FailedEstimate(reason, iterations, trace, 0, stage_trace)
        if options.euclidean_refinement:
            h, r, idx = self.polish(h, options.threshold_px, matched)
        else:
            _, r, idx, _ = matched
        r, idx = self._complete(h, r, idx)
        inliers = r < options.threshold_px
        if np.count_nonzero(inliers) < options.min_inliers:
            return FailedEstimate(
                f'too few inliers: {np.count_nonzero(inliers)} < min_inliers '
                f'{options.min_inliers}', iterations, trace, int(np.count_nonzero(inliers)),
                stage_trace)
        n = self.n_points
        idx = idx.astype(np.int64)
        return PlaneEstimate(
            homography=normalise_scale(h), inliers=inliers[:n], matches=idx[:n],
            residuals_px=r[:n], iterations=iterations, energy_trace=trace,
            stage_trace=stage_trace, converged=converged, final_energy=float(trace[-1]),
            potential=options.potential, line_inliers=inliers[n:], line_matches=idx[n:],
            line_residuals_px=r[n:], left_lines=self.left_segments)

    def _complete(self, h: np.ndarray, r: np.ndarray, idx: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Return the distances and indices with the points a bounded query missed filled in."""
        far = np.flatnonzero(idx[:self.n_points] < 0)
        if far.size == 0:
            return r, idx
        r, idx = r.copy(), idx.copy()
        r[far], idx[far] = self.tree.query(apply_homography(h, self.left[far]))
        return r, idx

    def screening_energy(self, candidates: np.ndarray, threshold_px: float) -> np.ndarray:
        """Return (M,) truncated closest-feature energies of candidate homographies.

        Points cost ``sum min(d, t)^2`` (:func:`domplane_ros.core.screening.screen_candidates`),
        segments the same with the closest-line distance, weighted by the line weight.

        Args:
            candidates: (M, 3, 3) float64 homographies.
            threshold_px: Truncation ``t``, pixels.

        """
        key = (np.ascontiguousarray(candidates, np.float64).tobytes(), float(threshold_px))
        if key in self._screened:  # the same set screened again (a search's rechecked rivals)
            return self._screened[key].copy()
        costs = np.zeros(candidates.shape[0])
        if self.n_points:
            costs += screen_candidates(candidates, self.left, self.tree, threshold_px)
        if self.n_lines:
            costs += self.line_weight * screen_line_candidates(
                candidates, self.left_segments, self.matcher, threshold_px)
        self._screened[key] = costs.copy()
        return costs

    def best_screened(self, candidates: np.ndarray, threshold_px: float, count: int
                      ) -> np.ndarray:
        """Return the indices of the ``count`` candidates of lowest screening energy.

        Points alone: :func:`domplane_ros.core.screening.best_screened` (a strided coarse pass,
        an exact pass over a short list); with segments, the best of
        :meth:`screening_energy`.

        Args:
            candidates: (M, 3, 3) float64 homographies.
            threshold_px: Truncation ``t``, pixels.
            count: How many indices to return.

        Returns:
            (min(count, M),) intp indices, lowest energy first.

        """
        if self.n_points and not self.n_lines:
            return best_screened(candidates, self.left, self.tree, threshold_px, count)
        costs = self.screening_energy(candidates, threshold_px)
        return np.argsort(costs, kind='stable')[:count]


def _points_reason(left: np.ndarray, right: np.ndarray) -> str:
    if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
        return 'points have non-finite coordinates'
    return point_set_reason(left, 'left') or point_set_reason(right, 'right')
