"""The candidate planes of a search and of the lock's challenge: refined, checked, finished.

The prior's candidates are many and most end on other planes, so they stop iterating early
(:data:`CANDIDATE_TOLERANCE_PX`); the one that wins the verification is then iterated to the
configured tolerance and verified again (:meth:`CandidateWork.finished`) before it is
published. The swapped cameras' rivals (:mod:`domplane_ros.stream.swap`) stop there too; the
coarse alignment's few starts keep the configured tolerance (:meth:`CandidateWork.coarse`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterable

from domplane_ros.config import EstimatorConfig, PlaneNodeConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.features import Features
from domplane_ros.core.homography import check_homography, corner_distance_px, normalise_scale
from domplane_ros.core.prior import PriorSearch
from domplane_ros.core.result import PlaneEstimate
from domplane_ros.stream.acceptance import AcceptanceChecks
from domplane_ros.stream.challenge import distinct_starts, NEAR_LOCK_PX
from domplane_ros.stream.frame import PairStep
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import Verdict
import numpy as np

__all__ = ['CANDIDATE_TOLERANCE_PX', 'CandidateWork', 'PHOTOMETRIC', 'PHOTOMETRIC_MIN_PEAK',
           'photometric_estimate', 'TIGHT_POLISH_RATIO']

# The prior's candidates (search and challenge) stop iterating once a round moves every
# prediction by less than this (pixels); the winner is then iterated to
# ``estimator.tolerance_px`` and verified again. Measured: 37 % fewer rounds on 12 rendered
# cold starts; evaluate_trust on the tuning seeds published as many correct planes (one more
# cold start, one rough rig fewer) and no wrong one. At 0.2 px: 63 % fewer rounds, but three
# fewer correct planes (a cut never re-locked).
CANDIDATE_TOLERANCE_PX = 0.1

# The finished plane is polished once more on the features within this fraction of
# ``estimator.threshold_px`` (the Euclidean refinement's inliers, 3 px by default): the wide
# inlier band lets the closest points of a planked or tiled floor's neighbouring corners bias
# the fit by 1-2 px. Measured on tuning seeds 0-29 (published planes under 1 px): cold start
# 25 -> 27 of 28, rough rigs 18 -> 19; faint tiles with ``both`` 21 -> 22 of 25 (seeds 0-39).
# The polished plane replaces the finished one only if it is verified, moved the points by at
# most TIGHT_POLISH_MAX_MOVE_PX (median) and keeps TIGHT_POLISH_MIN_PEAK of its peak score:
# unguarded, the same polish of every estimate published a 5.4 px wrong plane (faint tiles).
TIGHT_POLISH_RATIO = 0.5
TIGHT_POLISH_MAX_MOVE_PX = 2.0
TIGHT_POLISH_MIN_PEAK = 0.97

# Then the photometric refinement (CoarsePlanes.refined: the dense flow left after warping by
# plane, at full resolution up to CoarseConfig.finish_width_px, 1280 px wide; the figures below
# are of 640 x 480 pairs, refined at full resolution either way) replaces the plane if it is
# verified and keeps PHOTOMETRIC_MIN_PEAK of the peak score, up to PHOTOMETRIC_FINISH_ROUNDS
# times. Corners are found at slightly different floor points in the two views of planks and
# tiles, which biases their fit by up to 1-2 px; the flow has no such bias. Measured on tuning
# seeds 30-89 (cold start, rough rigs; documented default prior): published / correct 57 / 55
# and 53 / 51 before (refined at 320 px, taken only with a 5 % higher peak score), 57 / 57 and
# 53 / 53 after, median error 0.14 -> 0.096 px and 0.15 -> 0.094 px, no wrong plane either way.
# The peak score (at 160 px) cannot rank planes a few tenths of a pixel apart, so it only
# guards against a refinement that went elsewhere.
PHOTOMETRIC_MIN_PEAK = 0.97
PHOTOMETRIC_FINISH_ROUNDS = 2
# The search's winner is refined up to WINNER_FINISH_ROUNDS times, until a round settles (moves
# the predictions less than PHOTOMETRIC_SETTLED_PX) or loses peak score (under
# PHOTOMETRIC_MIN_PEAK of the best peak of the rounds before). A refinement's step is shorter
# than the plane's distance from the road where the start is a few pixels off: on real rough
# rigs (KITTI 000046 perturbed, tuning draws; docs/BENCHMARKS.md round 27) winners 3.0-3.1 px
# off ended 2.2-2.4 px off after two rounds and published so, and 0.52-0.56 px off after three
# more (the peak score rising each round: 0.196 -> 0.219 -> 0.250 -> 0.253). A near miss's
# rescue and a contender keep PHOTOMETRIC_FINISH_ROUNDS.
WINNER_FINISH_ROUNDS = 6
# A refinement that moved the corners' predictions by less than this (median, pixels) has
# settled: no second round (each costs a dense flow, about 100 ms CPU at 640 x 480).
PHOTOMETRIC_SETTLED_PX = 0.3

# A pair whose corners are too few to fix a plane (fewer than ``estimator.min_inliers``: a
# large checker seen close up shows about ten) gets its planes from the photometric refinement
# alone, repeated up to PHOTOMETRIC_ROUNDS times from each start (the coarse alignment's in a
# search, the prediction while locked). Measured on the cut that never re-locked (tuning cut
# seed 4, 10 corners): all five coarse starts, 0.3-5.7 px off, ended 0.10-0.11 px off in 3
# rounds. Such a plane is published only if verified (and, in a search, unique among the
# planes judged); it carries no corner inliers (``potential`` is ``'photometric'``).
# The first round keeps the samples whose residual flow is under PHOTOMETRIC_FIRST_NEAR_PX
# (pixels at the refinement's width: 8 px at 640 x 480, which it refines at full resolution,
# 16 px at 1280 x 720): a locked head's prediction can be 5-8 px off.
PHOTOMETRIC_ROUNDS = 3
PHOTOMETRIC_FIRST_NEAR_PX = 8.0
PHOTOMETRIC = 'photometric'


@dataclass(frozen=True)
class CandidateWork:
    """The candidate work of one pair, on the pipeline's settings, gate and checks."""

    config: PlaneNodeConfig
    trust: TrustGate
    checks: AcceptanceChecks

    @property
    def options(self) -> EstimatorConfig:
        """Return the estimator settings of the prior's candidates (search and challenge).

        They stop at :data:`CANDIDATE_TOLERANCE_PX` (the slow tail of the iteration, tens of
        rounds that move the plane by hundredths of a pixel, is left to the winner:
        :meth:`finished`). The coarse alignment's few starts and the configured initial
        homography keep the configured tolerance: they are the search's only route to rigs
        outside the prior's model, and a coarse start on a periodic floor can need the tail
        to gather its inliers (measured: the look-alike that names a swap on a tiled floor,
        tuning seed 68; stopped at this tolerance it is refused unverified instead, and the
        winner's uniqueness moves, docs/speed.md eighth round).
        """
        options = self.config.estimator
        if options.tolerance_px >= CANDIDATE_TOLERANCE_PX:
            return options
        return replace(options, tolerance_px=CANDIDATE_TOLERANCE_PX)

    @property
    def rival_options(self) -> EstimatorConfig:
        """Return the estimator settings of the swapped cameras' rivals: the candidates'.

        Measured (docs/speed.md, eighth round): stopped at :data:`CANDIDATE_TOLERANCE_PX`
        instead of the configured tolerance, the rivals' scores, the winners' uniqueness and
        every published plane stayed the same, at a quarter fewer rounds of a cold pair.
        """
        return self.options

    def finished(self, step: PairStep, problem: TwoStep, feats: Features,
                 size: tuple[int, int], best: PlaneEstimate, verdict: Verdict
                 ) -> tuple[PlaneEstimate, Verdict]:
        """Iterate the winning candidate to the configured tolerance and verify it again.

        Returns the finished plane and its verdict (with the candidate's uniqueness among
        the planes judged beside it), or the candidate and its own verdict where the finished
        plane is refused (both are verified).
        """
        if best.potential == PHOTOMETRIC:
            return best, verdict  # refined photometrically already; the corners cannot
        final = problem.estimate(best.homography, self.config.estimator, widen=False)
        again = None
        if final.ok and not self.checks.rejection_reason(final, feats, size, bounds=False):
            again = self.trust.judge(step.left, step.right, final.homography,
                                     self.config.features.roi)
        if again is None or not again.accepted:
            # The corners' iteration left the candidate for a refused plane: the candidate
            # itself is still refined photometrically (faint tiles, tuning seed 317: a fit
            # 5.2 px off the floor, whose refinement lands 0.07 px from it, was published
            # unrefined).
            final, again = self.photometric(step, problem, best, verdict)
            return final, again.with_pick(verdict)
        final, again = self.tightened(step, problem, final, again)
        final, again = self.photometric(step, problem, final, again)
        return (replace(final, candidates_tried=best.candidates_tried),
                again.with_pick(verdict))

    def tightened(self, step: PairStep, problem: TwoStep, estimate: PlaneEstimate,
                  verdict: Verdict) -> tuple[PlaneEstimate, Verdict]:
        """Polish a verified plane on its closest features only; keep it if it stays verified.

        The Euclidean refinement is run again from ``estimate`` with the inlier threshold
        :data:`TIGHT_POLISH_RATIO` x ``estimator.threshold_px``. The result replaces the
        estimate only if it moved the point predictions by at most
        :data:`TIGHT_POLISH_MAX_MOVE_PX` (median), is verified, and keeps
        :data:`TIGHT_POLISH_MIN_PEAK` of the peak score; its inliers are counted at the
        configured threshold.
        """
        threshold = self.config.estimator.threshold_px
        pred = problem.apply(estimate.homography)
        matched = (pred, *problem.match(pred, threshold))
        polished, _, _ = problem.polish(estimate.homography, TIGHT_POLISH_RATIO * threshold,
                                        matched)
        if check_homography(polished):
            return estimate, verdict
        polished = normalise_scale(polished)
        new_pred = problem.apply(polished)
        # The corners' predictions; with segments only (features.kind lines), the endpoints'.
        n = problem.n_points or new_pred.shape[0]
        moved = np.linalg.norm(new_pred[:n] - pred[:n], axis=1) if n else np.full(1, np.inf)
        if not float(np.median(moved)) <= TIGHT_POLISH_MAX_MOVE_PX:
            return estimate, verdict
        again = self.trust.judge(step.left, step.right, polished, self.config.features.roi)
        if not (again.accepted
                and again.peak_score >= TIGHT_POLISH_MIN_PEAK * verdict.peak_score):
            return estimate, verdict
        return self.moved(problem, estimate, polished), again

    def photometric(self, step: PairStep, problem: TwoStep, estimate: PlaneEstimate,
                    verdict: Verdict) -> tuple[PlaneEstimate, Verdict]:
        """Move a verified plane onto the dense flow if that still verifies as well.

        See :data:`PHOTOMETRIC_MIN_PEAK`: each refinement must be verified and keep that share
        of the best peak score so far; at most :data:`WINNER_FINISH_ROUNDS` rounds, fewer when
        one settles (:data:`PHOTOMETRIC_SETTLED_PX`).
        """
        best_peak = verdict.peak_score
        for _ in range(WINNER_FINISH_ROUNDS):
            least = PHOTOMETRIC_MIN_PEAK * best_peak
            refined = self.trust.planes.refined(step.left, step.right, estimate.homography,
                                                finish=True)
            if refined is None or check_homography(refined):
                break
            again = self.trust.judge(step.left, step.right, refined, self.config.features.roi)
            if not (again.accepted and again.peak_score >= least):
                break
            moved = self.moved(problem, estimate, refined)
            settled = _median_move(problem, estimate.homography, refined) < PHOTOMETRIC_SETTLED_PX
            estimate, verdict = moved, again
            best_peak = max(best_peak, again.peak_score)
            if settled:
                break
        return estimate, verdict

    def photometric_planes(self, step: PairStep, starts: Iterable[np.ndarray],
                           size: tuple[int, int]) -> list[PlaneEstimate]:
        """Return planes for a pair whose corners are too few: starts refined photometrically.

        Each distinct start is refined up to :data:`PHOTOMETRIC_ROUNDS` times; a start no
        refinement could move gives no plane. The planes are not verified here.
        """
        out = []
        for start in distinct_starts(starts, size):
            plane = None
            for _ in range(PHOTOMETRIC_ROUNDS):
                moved = (self.trust.planes.refined(step.left, step.right, start,
                                                   PHOTOMETRIC_FIRST_NEAR_PX) if plane is None
                         else self.trust.planes.refined(step.left, step.right, plane))
                if moved is None or check_homography(moved):
                    break
                plane = moved
            if plane is not None:
                out.append(photometric_estimate(plane))
        return out

    def rescued(self, step: PairStep, problem: TwoStep, estimate: PlaneEstimate,
                verdict: Verdict) -> tuple[PlaneEstimate, Verdict]:
        """Refine a near miss photometrically while that raises its score; return the last.

        A near miss: a plane refused only for explaining too little of the image, whose score
        is close to ``verification.min_score`` (the search decides which, see
        :data:`~domplane_ros.stream.search.NEAR_MISS_RATIO`). A plane a pixel off the floor
        scores a tenth less than the floor itself (tuning rough rigs 12 and 47: 1.0 px off,
        0.23 against the truth's 0.26-0.27). Up to :data:`PHOTOMETRIC_FINISH_ROUNDS` rounds at
        the finishing width, stopping at the first verified plane or a round that does not
        raise the score or that would put the features' predictions more than
        :data:`TIGHT_POLISH_MAX_MOVE_PX` (median) from the near miss's own: the rescue is for a
        plane a pixel off, not for one a tile period away. The caller picks among the results
        as usual (uniqueness, rivals).
        """
        start = estimate.homography
        for _ in range(PHOTOMETRIC_FINISH_ROUNDS):
            refined = self.trust.planes.refined(step.left, step.right, estimate.homography,
                                                finish=True)
            if (refined is None or check_homography(refined)
                    or _median_move(problem, start, refined) > TIGHT_POLISH_MAX_MOVE_PX):
                break
            again = self.trust.judge(step.left, step.right, refined, self.config.features.roi)
            if again.verification.score <= verdict.verification.score:
                break
            estimate, verdict = self.moved(problem, estimate, refined), again
            if verdict.accepted:
                break
        return estimate, verdict

    def contended(self, step: PairStep, problem: TwoStep, estimate: PlaneEstimate,
                  verdict: Verdict) -> tuple[PlaneEstimate, Verdict]:
        """Refine a contender of an ambiguous pick photometrically while that raises its score.

        Up to :data:`PHOTOMETRIC_FINISH_ROUNDS` rounds at the finishing width, stopping at a
        round that does not raise the score (verified or not: a rival refined only gets
        stronger). Returns ``estimate`` itself and ``verdict`` if no round did. The search
        decides what to do with it (:data:`~domplane_ros.stream.search.CONTENDERS`).
        """
        for _ in range(PHOTOMETRIC_FINISH_ROUNDS):
            refined = self.trust.planes.refined(step.left, step.right, estimate.homography,
                                                finish=True)
            if refined is None or check_homography(refined):
                break
            again = self.trust.judge(step.left, step.right, refined, self.config.features.roi)
            if again.verification.score <= verdict.verification.score:
                break
            estimate, verdict = self.moved(problem, estimate, refined), again
        return estimate, verdict

    def moved(self, problem: TwoStep, estimate: PlaneEstimate, homography: np.ndarray
              ) -> PlaneEstimate:
        """Return the estimate at another homography, its features matched again."""
        n = problem.n_points
        r, idx, _ = problem.match(problem.apply(homography))
        inliers = r < self.config.estimator.threshold_px
        return replace(estimate, homography=normalise_scale(homography), inliers=inliers[:n],
                       matches=idx[:n], residuals_px=r[:n], line_inliers=inliers[n:],
                       line_matches=idx[n:], line_residuals_px=r[n:])

    def coarse(self, step: PairStep, problem: TwoStep, feats: Features,
               size: tuple[int, int], peaks: bool = False,
               known: Iterable[np.ndarray] = ()) -> list[PlaneEstimate]:
        """Return the refined, unrejected planes of the coarse photometric alignment.

        A start within :data:`~domplane_ros.stream.challenge.NEAR_LOCK_PX` of one refined
        already, or of a ``known`` plane, is not refined (the parts of the image often give
        the same plane). ``peaks``: the further shifted alignments' planes instead
        (:meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.coarse_candidates`).
        """
        out = []
        known = list(known)
        starts = self.trust.planes.coarse_candidates(step.left, step.right, peaks=peaks)
        for start in distinct_starts(starts, size):
            if any(corner_distance_px(start, other, *size) < NEAR_LOCK_PX for other in known):
                continue
            result = problem.estimate(start, self.config.estimator, widen=False)
            if result.ok and not self.checks.rejection_reason(result, feats, size, bounds=False):
                out.append(result)
        return out

    def refined(self, prior_search: PriorSearch, indices: list[int], feats: Features,
                size: tuple[int, int]) -> tuple[list[PlaneEstimate], str]:
        """Refine each candidate of ``indices``: the unrejected planes and the last rejection."""
        out: list[PlaneEstimate] = []
        rejection = ''
        for index in indices:
            result, rejected = prior_search.refine(
                [index], self.options,
                lambda estimate: self.checks.rejection_reason(estimate, feats, size))
            rejection = rejected or rejection
            if result is not None and result.ok:
                out.append(result)
        return out, rejection


def _median_move(problem: TwoStep, first: np.ndarray, second: np.ndarray) -> float:
    """Return the median distance between two planes' predictions of the features, pixels."""
    return float(np.median(np.linalg.norm(problem.apply(second) - problem.apply(first),
                                          axis=1)))


def photometric_estimate(homography: np.ndarray) -> PlaneEstimate:
    """Return a plane found without corners (:data:`PHOTOMETRIC`): no inliers, no energy."""
    return PlaneEstimate(
        homography=normalise_scale(homography), inliers=np.zeros(0, bool),
        matches=np.zeros(0, np.int64), residuals_px=np.zeros(0), iterations=0,
        energy_trace=np.zeros(0), stage_trace=np.zeros(0, np.int64), converged=True,
        final_energy=0.0, potential=PHOTOMETRIC)
