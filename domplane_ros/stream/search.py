"""The pipeline's searching state: the prior search spread over pairs, verified before publishing.

A search starts when the pipeline has no plane to warm-start from (the first pair, a reset, a
lock lost or refused). Each pair refines the next ``pipeline.search_candidates_per_frame``
prior candidates by screening energy, the best plane so far (moved through the cameras'
motion), the configured initial homography (once) and the coarse photometric alignment's
planes; :meth:`~domplane_ros.stream.trust.TrustGate.pick` publishes the best of them only if
it is verified and unique. A pair of too few corners gets its planes from the photometric
refinement alone. The lock state itself (locked, tracking, searching) stays in
:class:`~domplane_ros.stream.pipeline.PlanePipeline`, which owns one :class:`PlaneSearch`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.features import Features
from domplane_ros.core.homography import as_homography, corner_distance_px
from domplane_ros.core.prior import PriorSearch, search_candidates
from domplane_ros.core.result import FailedEstimate, PlaneEstimate
from domplane_ros.core.tracking import predict_plane_homography
from domplane_ros.core.verification import REASON_LOW_SUPPORT
from domplane_ros.stream.acceptance import AcceptanceChecks
from domplane_ros.stream.candidates import CandidateWork, photometric_estimate
from domplane_ros.stream.challenge import NEAR_LOCK_PX
from domplane_ros.stream.frame import PairStep
from domplane_ros.stream.ground_rules import weak_below_refusal
from domplane_ros.stream.health import InputCounts
from domplane_ros.stream.refusals import Refusal, SEARCH
from domplane_ros.stream.swap import swap_rivals
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import (BEYOND_RIVAL_SHARE, CHALLENGE_MARGIN, TWIN_RIVAL_SHARE,
                                         Verdict)
import numpy as np

# The swapped rivals stop at the candidates' tolerance (CandidateWork.rival_options); their
# scores then differ from those at the configured tolerance by up to 1.45x either way
# (measured on tuning seeds 30-59: the winner's uniqueness 14.2 against 9.8). Where the
# winner's uniqueness is below this, or the search is ambiguous, the rivals are refined to the
# configured tolerance and the planes picked again, so that the published plane and its
# confidence (which saturates at a uniqueness of 1.4) are the ones the full rivals give.
RIVAL_RECHECK_UNIQUENESS = 2.25

# Every search is in doubt once: as soon as it has a winner, before it publishes, or on its
# last pair without one. In doubt it refines the coarse alignment's further shifted alignments
# (CoarseAligner.peak_candidates: the strongest phase-correlation peaks of strips of the lower
# half) and picks again. On a periodic floor with a wide disparity the dominant shift is often
# a period alias, and the truth is then never a candidate. Rules that chose which winners to
# doubt (a uniqueness under 1.4, a winner never contested, a confidence under 0.75, a
# disparity slope under 0.05 px per row; trust rounds 8-11) each missed a look-alike the next
# one caught; the last, tuning floors_rough seed 150 (a 16 cm checker on a rough rig), was
# published 84 px off at uniqueness 6.9 and confidence 1.0 with no rule in doubt, and the
# further shifts find the truth beside it (refused as ambiguous). Measured (session 14,
# evaluate_trust --no-orb, tuning seeds 0-29, 150-179, 180-209): docs/BENCHMARKS.md, trust
# round 15. Cost: a cold search about 1.3-1.4x the time of one under those rules (paired
# median ratios, 12 rendered scenes each of cold, rough checker/tile/plank, faint tiles).

# A search in doubt that still has no verified plane refines its near misses photometrically
# (CandidateWork.rescued): the NEAR_MISSES best distinct planes refused only for explaining too
# little of the image, with at least NEAR_MISS_RATIO x verification.min_score. Measured: docs/
# BENCHMARKS.md, trust round 8.
NEAR_MISS_RATIO = 0.8
NEAR_MISSES = 2

# A ground search whose pick is ambiguous between planes of this head (not with a plane of
# swapped cameras) refines its contenders photometrically once and picks again
# (PlaneSearch._refine_contenders): the CONTENDERS best ground planes of this head scoring at
# least 1 / CHALLENGE_MARGIN of the best verified one, each refined while that raises its
# score (CandidateWork.contended) and replaced by its refinement only if that is still a ground
# plane of this head. On a faint floor of large tiles (few corners, mostly the boxes') the
# search's fits of the floor lie 3-7 px off it and, mapping the image bottom more than 8 px
# apart, make each other ambiguous; refined, they land on the floor together (tuning faint
# seed 7001: 2.9 and 4.5 px off, 0.53 and 0.55, refined 0.1 px off). A look-alike a period off
# stays one (the refinement fits only samples within REFINE_NEAR_PX of the plane), and only
# gets stronger: a rival is dropped only where its own refinement joins the winner.
CONTENDERS = 6
REFINE_CONTENDERS = True
# A ground search whose pick ends ambiguous between distinct planes judges the period siblings
# of its best verified plane (PlaneSearch._sibling_pick, as a winner's): two look-alikes of a
# periodic floor, each some periods off, can tie within CHALLENGE_MARGIN while neither is the
# floor, and the floor is the sibling of either (rendered floors_rough 23028, a 32 cm checker
# on a rough rig: the look-alikes 125 and 144 px off scored 0.354 and 0.279, 1.27 x apart; a
# verification that moves them a few hundredths ties them and the floor, 0.603, was never
# judged; docs/BENCHMARKS.md rounds 32 and 33: on the tuning sets no decision changed). False:
# the siblings of a winner only.
AMBIGUOUS_SIBLINGS = True
# The reason of a pick ambiguous between planes of this head (Uniqueness.ground_winner).
AMBIGUOUS_DISTINCT = 'ambiguous: a distinct plane'
# Refuse a finished winner verified with less than full confidence that leaves more than
# ground_rules.MAX_BELOW_FRACTION_WEAK of the texture beyond it (ground_rules.weak_below_refusal;
# measured there and in docs/BENCHMARKS.md round 17). False: as before round 17.
WEAK_BELOW_REFUSAL = True

__all__ = ['PlaneSearch', 'propagate']

Motions = tuple[np.ndarray, np.ndarray] | None
# (problem, start, wide) -> the pipeline's warm estimate from ``start``.
WarmEstimate = Callable[[TwoStep | FailedEstimate, np.ndarray, bool],
                        PlaneEstimate | FailedEstimate]


def propagate(h: np.ndarray, motions: Motions) -> np.ndarray | None:
    """Return plane ``h`` moved through the cameras' tracked motions, or None without them.

    Args:
        h: (3, 3) plane homography of the previous pair.
        motions: The left and right cameras' (3, 3) image motions, or None.

    Returns:
        The (3, 3) predicted homography, or None.

    """
    if motions is None:
        return None
    return predict_plane_homography(h, motions[0], motions[1])


@dataclass
class _Search:
    """A prior search spread over frames: candidates tried so far and the best result."""

    tried: set[int] = field(default_factory=set)
    best: np.ndarray | None = None
    initial_tried: bool = False
    rivals: list[np.ndarray] | None = None  # planes of swapped cameras (stream/swap.py)
    rivals_full: bool = False  # rivals refined to the configured tolerance (rechecked)
    peaks_tried: bool = False  # the coarse alignment's further shifts refined (in doubt)
    siblings_tried: bool = False  # the winner's period siblings judged
    contenders_tried: bool = False  # an ambiguous pick's contenders refined (ground)


class PlaneSearch:
    """The prior search of one stream, spread over its pairs until a plane is verified.

    Args:
        config: Returns the pipeline's current configuration.
        trust: Returns the pipeline's current verification gate.
        checks: The pipeline's acceptance checks (bounds, spread, energy).
        counts: Where refusals are counted (the session's input counts).
        warm_estimate: The pipeline's warm estimate (used to refine the best plane so far).

    """

    def __init__(self, config: Callable[[], PlaneNodeConfig], trust: Callable[[], TrustGate],
                 checks: AcceptanceChecks, counts: InputCounts,
                 warm_estimate: WarmEstimate) -> None:
        """Start idle: :meth:`step` begins a search."""
        self._config = config
        self._trust = trust
        self._checks = checks
        self._counts = counts
        self._warm_estimate = warm_estimate
        self._search: _Search | None = None
        self._candidates_cache: dict[tuple[int, int], np.ndarray] = {}

    @property
    def running(self) -> bool:
        """Return whether a search is under way (it has refined candidates)."""
        return self._search is not None

    @property
    def has_best(self) -> bool:
        """Return whether the search carries a best plane so far (worth tracking motion for)."""
        return self._search is not None and self._search.best is not None

    def stop(self) -> None:
        """Drop the search: the next :meth:`step` starts a new one."""
        self._search = None

    def prior_changed(self) -> None:
        """Forget the prior's candidates (the prior changed)."""
        self._candidates_cache.clear()

    def candidates(self, size: tuple[int, int]) -> np.ndarray:
        """Return the prior's (N, 3, 3) candidates for images of ``size`` (width, height)."""
        if size not in self._candidates_cache:
            cfg = self._config()
            self._candidates_cache[size] = search_candidates(cfg.prior, *size,
                                                             cfg.verification.plane)
        return self._candidates_cache[size]

    def step(self, step: PairStep, feats: Features, problem: TwoStep | FailedEstimate,
             size: tuple[int, int], motions: Motions
             ) -> tuple[PlaneEstimate, Verdict] | None:
        """Refine this pair's candidates; return the verified plane to publish, or None.

        ``step`` receives the candidates refined, the warm start's name and, without a plane,
        the reason. A returned plane ends the search (finished: the configured tolerance,
        the polish and the photometric refinement, each taken only if verified).
        """
        step.reinitialised = True
        if self._search is None:
            self._search = _Search()
        search = self._search
        reason = self._checks.too_few_reason(feats)
        if reason or isinstance(problem, FailedEstimate):
            step.reason = reason or problem.reason
            best, verdict, _ = self._photometric_search(step, size)
            refused = ('' if best is None or verdict is None
                       else self._finished_refusal(best, verdict, size))
            if refused:
                step.refuse(SEARCH, refused)
                return None
            return self._done(best, verdict)
        pool, rejection, limit = self._pool(step, search, problem, feats, size, motions)
        step.warm_start = 'search'
        # Swapped cameras cannot be told from one plane that need not be the ground: with
        # verification.plane any there are no swapped rivals (the leaning planes of the
        # candidates are searched instead).
        rivals = (None if self._config().verification.plane == 'any' else
                  lambda: self._rivals(search, step, problem, feats, size))
        roi = self._config().features.roi
        pick = lambda: self._trust().pick(step.left, step.right, pool, roi, rivals)  # noqa: E731
        best, verdict, unverified = self._checked_pick(search, pick)
        if self._in_doubt(search, verdict, limit):
            # A search in doubt (once, with a winner or on its last pair without one): the
            # coarse alignment after its further shifts, judged with the rest.
            search.peaks_tried = True
            more = self._work().coarse(step, problem, feats, size, peaks=True,
                                       known=[plane.homography for plane in pool])
            if more:
                pool += more
                best, verdict, unverified = self._checked_pick(search, pick)
            if verdict is None and self._rescue_near_misses(step, problem, pool, feats, size):
                best, verdict, unverified = self._checked_pick(search, pick)
        if (verdict is None and REFINE_CONTENDERS and not search.contenders_tried
                and unverified.startswith(AMBIGUOUS_DISTINCT)
                and self._config().verification.plane != 'any'):
            search.contenders_tried = True
            if self._refine_contenders(step, search, problem, pool, feats, size):
                best, verdict, unverified = self._checked_pick(search, pick)
        if verdict is not None:
            best, verdict, unverified = self._sibling_pick(step, search, pool, best, pick)
        elif (AMBIGUOUS_SIBLINGS and unverified.startswith(AMBIGUOUS_DISTINCT)
              and self._config().verification.plane != 'any'):
            leader = self._best_verified(step, pool)
            if leader is not None:
                best, verdict, unverified = self._sibling_pick(step, search, pool, leader, pick)
        if not pool and not rejection and len(search.tried) >= limit:
            # The corners gave no plane at all, not even a refused one (every start had too
            # few inliers: a floor of few corners): the coarse planes refined
            # photometrically, judged with the rivals. If none is published the corners'
            # reason stands. (Not where the corners' planes were refused or unverified: there
            # it published look-alikes, e.g. 12.9 px off on faint tiles, tuning seed 305.)
            again = self._photometric_search(step, size, rivals)
            if again[0] is not None:
                best, verdict, unverified = again
        search.best = best.homography if best is not None else None
        if best is not None and verdict is not None:
            if best is step.initial:
                step.warm_start = 'initial'
            done = self._work().finished(step, problem, feats, size, best, verdict)
            unverified = self._finished_refusal(*done, size)
            if not unverified:
                return self._done(*done)
            search.best = None
            if len(search.tried) < limit:
                # The search goes on (else its end says this).
                step.refusals.append(Refusal(SEARCH, unverified))
        if len(search.tried) < limit:
            step.reason = (f'searching the prior: {len(search.tried)} of {limit} candidates '
                           'refined')
            return None
        self._end(step, pool, rejection, unverified)
        return None

    @staticmethod
    def _in_doubt(search: _Search, verdict: Verdict | None, limit: int) -> bool:
        """Return whether the search should try the coarse alignment's further shifts.

        Once per search: as soon as it has a winner (``verdict``), or on its last pair
        (``limit`` candidates tried) without one. Every winner is doubted, not only some: see
        the module's comment on doubt (a look-alike published at confidence 1.0).
        """
        if search.peaks_tried:
            return False
        return verdict is not None or len(search.tried) >= limit

    def _sibling_pick(self, step: PairStep, search: _Search, pool: list[PlaneEstimate],
                      best: PlaneEstimate,
                      pick: Callable[[], tuple[PlaneEstimate | None, Verdict | None, str]]
                      ) -> tuple[PlaneEstimate | None, Verdict | None, str]:
        """Judge the period siblings of ``best`` with the pool and pick again.

        ``best``: the winner, or the best verified plane of a pick ambiguous between distinct
        planes (:data:`AMBIGUOUS_SIBLINGS`).

        :meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.siblings`: on a periodic board
        a look-alike some squares off can win a search that never judged the board's plane;
        its siblings include that plane, which then wins, or the pick is ambiguous. Once per
        search. In ground mode too since session 25: a 32 cm checker floor on a rough rig
        (rendered held-out floors_rough 23028) was published 125 px off at confidence 1.0,
        a look-alike one period to the side whose sibling is the floor (score 0.62 against
        0.34); measured on the tuning seeds 0-39 of every evaluate_trust case: no other
        decision changed (docs/BENCHMARKS.md round 28).
        """
        if search.siblings_tried:
            return pick()
        search.siblings_tried = True
        size = (step.left.shape[1], step.left.shape[0])
        known = [plane.homography for plane in pool]
        for sibling in self._trust().planes.siblings(step.left, step.right, best.homography,
                                                     self._config().features.roi):
            if all(corner_distance_px(sibling, other, *size) >= NEAR_LOCK_PX
                   for other in known):
                pool.append(photometric_estimate(sibling))
                known.append(sibling)
        return pick()

    def _rescue_near_misses(self, step: PairStep, problem: TwoStep,
                            pool: list[PlaneEstimate], feats: Features,
                            size: tuple[int, int]) -> bool:
        """Add the near misses of the pool, refined photometrically; return whether any.

        Near misses: ground planes of the right sign refused only for explaining too little of
        the image, with at least :data:`NEAR_MISS_RATIO` of ``verification.min_score``; the best
        :data:`NEAR_MISSES` distinct ones by score (:meth:`CandidateWork.rescued`). A rescued
        plane joins the pool only if verified and it passes the checks every pool plane passed
        (a valid homography, inliers spread over the region): its features were matched again.
        """
        least = NEAR_MISS_RATIO * self._config().verification.min_score
        judged = self._judged_pool(step, pool)
        # A plane refused for its disparity slope (swapped cameras, no ground plane) is no near
        # miss whatever its verification says: the refinement moves it a pixel or two, not to
        # a slope of the other sign, and would take a ground plane's slot.
        misses = sorted(((v, plane) for v, plane in judged
                         if v.ground and not v.swapped
                         and v.verification.reason == REASON_LOW_SUPPORT
                         and v.verification.score >= least),
                        key=lambda item: -item[0].verification.score)
        work, added, tried = self._work(), False, []
        for verdict, plane in misses:
            if len(tried) == NEAR_MISSES:
                break
            if any(corner_distance_px(plane.homography, other, *size) < NEAR_LOCK_PX
                   for other in tried):
                continue
            tried.append(plane.homography)
            rescued, again = work.rescued(step, problem, plane, verdict)
            if again.accepted and not self._checks.rejection_reason(
                    rescued, feats, size, bounds=False):
                pool.append(rescued)
                added = True
        return added

    def _best_verified(self, step: PairStep, pool: list[PlaneEstimate]
                       ) -> PlaneEstimate | None:
        """Return the pool's best-scoring plane the gate accepts, or None."""
        accepted = [(verdict.score, index) for index, (verdict, _) in
                    enumerate(self._judged_pool(step, pool)) if verdict.accepted]
        return pool[max(accepted)[1]] if accepted else None

    def _judged_pool(self, step: PairStep, pool: list[PlaneEstimate]
                     ) -> list[tuple[Verdict, PlaneEstimate]]:
        """Return each pool plane's verdict on this pair, beside the plane."""
        trust, roi = self._trust(), self._config().features.roi
        return [(trust.judge(step.left, step.right, plane.homography, roi), plane)
                for plane in pool]

    def _refine_contenders(self, step: PairStep, search: _Search, problem: TwoStep,
                           pool: list[PlaneEstimate], feats: Features,
                           size: tuple[int, int]) -> bool:
        """Refine an ambiguous pick's contenders in the pool; return whether any moved.

        See :data:`CONTENDERS`. Not where a plane of swapped cameras (judged in the pool or
        among the search's rivals) scores within the margin of the best verified plane: a
        refined plane of this head could then outscore the swapped cameras' floor.
        """
        trust, roi = self._trust(), self._config().features.roi
        judged = self._judged_pool(step, pool)
        top = max((v.score for v, _ in judged if v.accepted), default=0.0)
        least = top / CHALLENGE_MARGIN
        swapped = [v for v, _ in judged if v.swapped]
        swapped += [trust.judge(step.left, step.right, rival, roi)
                    for rival in search.rivals or []]
        if top <= 0.0 or any(v.score >= least for v in swapped if v.swapped):
            return False
        contenders = sorted(((v, plane) for v, plane in judged
                             if v.ground and not v.swapped and v.score >= least),
                            key=lambda item: -item[0].score)[:CONTENDERS]
        work, moved = self._work(), False
        for verdict, plane in contenders:
            refined, again = work.contended(step, problem, plane, verdict)
            if (refined is plane or not again.ground or again.swapped
                    or self._checks.rejection_reason(refined, feats, size, bounds=False)):
                continue
            pool[next(i for i, other in enumerate(pool) if other is plane)] = refined
            moved = True
        return moved

    def _finished_refusal(self, best: PlaneEstimate, verdict: Verdict, size: tuple[int, int]
                          ) -> str:
        """Return why a finished winner is not published ('' if it is).

        :func:`_finish_refusal`, then the gate's roll and slope of a ground plane
        (:meth:`~domplane_ros.stream.trust.TrustGate.ground_refusal`) and its own mask's near
        field (:meth:`~domplane_ros.stream.trust.TrustGate.near_field_refusal`): only on the
        plane about to be published, never on the pick's unfinished candidates.
        """
        trust = self._trust()
        return (_finish_refusal(verdict)
                or trust.ground_refusal(best.homography, *size, verdict.verification)
                or trust.near_field_refusal(best.homography, self._config().features.roi))

    def _done(self, best: PlaneEstimate | None, verdict: Verdict | None
              ) -> tuple[PlaneEstimate, Verdict] | None:
        if best is None or verdict is None:
            return None
        self._search = None
        return best, verdict

    def _work(self) -> CandidateWork:
        return CandidateWork(self._config(), self._trust(), self._checks)

    def _photometric_search(self, step: PairStep, size: tuple[int, int],
                            rivals: Callable[[], list[np.ndarray]] | None = None
                            ) -> tuple[PlaneEstimate | None, Verdict | None, str]:
        """Pick among the coarse planes refined photometrically (corners too few to tell)."""
        trust = self._trust()
        planes = self._work().photometric_planes(
            step, trust.planes.coarse_candidates(step.left, step.right), size)
        if not planes:
            return None, None, ''
        return trust.pick(step.left, step.right, planes, self._config().features.roi, rivals)

    def _pool(self, step: PairStep, search: _Search, problem: TwoStep, feats: Features,
              size: tuple[int, int], motions: Motions
              ) -> tuple[list[PlaneEstimate], str, int]:
        """Return this frame's refined candidates, the last rejection and the search's size.

        The pool: the configured initial homography (once per search), the best so far, the
        next prior candidates by screening energy and the coarse photometric alignment's.
        """
        cfg = self._config()
        pool: list[PlaneEstimate] = []
        budget = cfg.pipeline.search_candidates_per_frame
        if cfg.initial_homography and not search.initial_tried:
            search.initial_tried = True
            budget -= 1
            step.candidates += 1
            init = as_homography(cfg.initial_homography, 'initial_homography')
            first = problem.estimate(init, cfg.estimator, widen=False)
            if first.ok and not self._checks.rejection_reason(first, feats, size):
                pool.append(first)
                step.initial = first
        best = self._best_so_far(search, problem, feats, size, motions)
        if best is not None and best.ok:
            pool.append(best)
        candidates = self.candidates(size)
        limit = min(cfg.prior.refine_best, candidates.shape[0])
        prior_search = PriorSearch(problem, candidates, cfg.prior.screen_threshold_px)
        chosen = prior_search.ranked(search.tried)[:max(0, min(budget, limit - len(search.tried)))]
        search.tried.update(chosen)
        step.candidates += len(chosen)
        work = self._work()
        refined, rejection = work.refined(prior_search, chosen, feats, size)
        pool += refined
        pool += work.coarse(step, problem, feats, size)
        return pool, rejection, limit

    def _checked_pick(self, search: _Search,
                      pick: Callable[[], tuple[PlaneEstimate | None, Verdict | None, str]]
                      ) -> tuple[PlaneEstimate | None, Verdict | None, str]:
        """Pick; near the margin, pick again with the rivals at the configured tolerance.

        See :data:`RIVAL_RECHECK_UNIQUENESS`: a uniqueness this low, or an ambiguous search,
        is decided by rivals refined as before the eighth speed round.
        """
        out = pick()
        _, verdict, unverified = out
        near = (verdict.uniqueness < RIVAL_RECHECK_UNIQUENESS if verdict is not None
                else unverified.startswith('ambiguous'))
        if search.rivals is None or search.rivals_full or not near:
            return out
        search.rivals, search.rivals_full = None, True
        return pick()

    def _rivals(self, search: _Search, step: PairStep, problem: TwoStep,
                feats: Features, size: tuple[int, int]) -> list[np.ndarray]:
        """Return the search's planes of swapped cameras, found once per search when needed.

        The swap is tested, not assumed absent (stream/swap.py), but only once a plane has
        been verified (:meth:`TrustGate.pick` asks for the rivals then): a search whose
        planes all fail costs no rivals. They stop at the candidates' tolerance
        (:attr:`CandidateWork.rival_options`), or at the configured one once rechecked
        (:meth:`_checked_pick`).
        """
        if search.rivals is None:
            cfg = self._config()
            trust = self._trust()
            candidates = self.candidates(size)
            search.rivals = swap_rivals(
                problem, candidates, min(cfg.prior.refine_best, candidates.shape[0]),
                cfg.estimator if search.rivals_full else self._work().rival_options,
                cfg.prior.screen_threshold_px,
                lambda estimate: self._checks.rejection_reason(estimate, feats, size,
                                                               bounds=False),
                lambda start: trust.planes.polish(step.left, step.right, start,
                                                  cfg.features.roi))
        return search.rivals

    def _best_so_far(self, search: _Search, problem: TwoStep | FailedEstimate, feats: Features,
                     size: tuple[int, int], motions: Motions
                     ) -> PlaneEstimate | FailedEstimate | None:
        """Return the search's best so far, moved to this frame and refined on its features."""
        if search.best is None:
            return None
        start = propagate(search.best, motions)
        best = self._warm_estimate(problem, start if start is not None else search.best, False)
        if best.ok and self._checks.rejection_reason(best, feats, size):
            return None
        return best

    def _end(self, step: PairStep, pool: list[PlaneEstimate], rejection: str,
             unverified: str) -> None:
        """No verified plane: say why, and start again with the next frame's features."""
        if unverified:
            self._counts.add('swapped_cameras' if 'swapped' in unverified
                             else 'unverified_plane')
            step.refuse(SEARCH, f'search found no verified plane: {unverified}')
        elif not pool and rejection:
            self._checks.count_rejection(rejection)
            step.refuse(SEARCH, f'prior search found no plane: {rejection}')
        else:
            step.refuse(SEARCH, 'prior search found no plane')
        self._search = None


def _finish_refusal(verdict: Verdict) -> str:
    """Return why a finished winner is refused ('' if not): a better refused plane, weak evidence.

    :func:`_beyond_refusal`, :func:`_twin_refusal`, then
    :func:`~domplane_ros.stream.ground_rules.weak_below_refusal` (only if
    :data:`WEAK_BELOW_REFUSAL`).
    """
    return (_beyond_refusal(verdict) or _twin_refusal(verdict)
            or (weak_below_refusal(verdict) if WEAK_BELOW_REFUSAL else ''))


def _rival_refusal(verdict: Verdict, rival: float, share: float) -> str:
    """Return the scores' part of a refusal for a better rival ('' if the winner holds).

    The winner must score at least ``share`` x ``rival`` (0: no rival was recorded).
    """
    if not rival or verdict.score >= share * rival:
        return ''
    return f'(score {rival:.2f} against {verdict.score:.2f} for the best plane finished'


def _beyond_refusal(verdict: Verdict) -> str:
    """Return why a finished winner is refused for a better plane beyond it ('' if not).

    :data:`~domplane_ros.stream.verdict.BEYOND_RIVAL_SHARE`: the winner must score at least
    that share of its ``beyond_rival``, the best plane of its pick refused only for the
    texture beyond it.
    """
    scores = _rival_refusal(verdict, verdict.beyond_rival, BEYOND_RIVAL_SHARE)
    return scores and ('ambiguous: a plane refused for the texture beyond it explains the '
                       f'image better {scores}); a plane through obstacles, or the floor not '
                       'found?')


def _twin_refusal(verdict: Verdict) -> str:
    """Return why a finished winner is refused for a better refused twin ('' if not).

    :data:`~domplane_ros.stream.verdict.TWIN_RIVAL_SHARE`: the winner must score at least
    that share of its ``twin_rival``, the best plane of its pick that maps the image bottom as
    it does but was refused though a ground plane (the band between the top and bottom it
    explains).
    """
    scores = _rival_refusal(verdict, verdict.twin_rival, TWIN_RIVAL_SHARE)
    return scores and ('ambiguous: a plane through the same ground at the image bottom '
                       f'explains the image better {scores}, > {1.0 / TWIN_RIVAL_SHARE:g} x) '
                       'but was refused for the band between its top and bottom; an obstacle '
                       'filling the middle of the view, or a far wall aliasing the floor?')
