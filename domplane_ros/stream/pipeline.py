"""One object per stereo stream: features, warm start or prior, estimate, mask.

The live node and the offline replay are thin adapters around :class:`PlanePipeline`, so the
same frames give the same results in both. The estimation state that lives across frames (the
last good homography, its energy, the lock state, the pipeline's statistics) lives here; the
stream's bookkeeping (pair counters, input-problem counts, the status) lives in
:class:`~domplane_ros.stream.session.StreamSession`, whose counts the pipeline adds to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
import time

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.features import detect_corners, Features
from domplane_ros.core.image import check_gray
from domplane_ros.core.pyramid import WorkingImage
from domplane_ros.core.result import FailedEstimate, PlaneEstimate
from domplane_ros.core.stages import can_widen
from domplane_ros.core.verification import REASON_LOW_SUPPORT
from domplane_ros.stream.acceptance import AcceptanceChecks
from domplane_ros.stream.candidates import CandidateWork, PHOTOMETRIC
from domplane_ros.stream.detection import (carried_features, detect_features, full_mask,
                                           level_features, level_mask)
from domplane_ros.stream.frame import debug_overlay, FrameResult, PairStep, stage_timings_ms
from domplane_ros.stream.health import InputCounts, PairChecks, texture_note
from domplane_ros.stream.lock_challenge import LockChallenge
from domplane_ros.stream.motion import FrameTracker, Tracked
from domplane_ros.stream.refusals import (CUT, ESTIMATE, GATE, Refusal, RefusalCounts, RESET,
                                          tracking_ended, view_changed)
from domplane_ros.stream.search import PlaneSearch, propagate
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import Verdict
from domplane_ros.stream.warm import WarmFit
import numpy as np

__all__ = ['FrameResult', 'LOCKED', 'PipelineStats', 'PlanePipeline', 'SEARCHING', 'TRACKING',
           'debug_overlay']

# Lock states reported in diagnostics.
LOCKED = 'locked'        # the last frame gave a plane; the next one warm-starts from it
TRACKING = 'tracking'    # an estimate failed; the last plane is carried through the motion
SEARCHING = 'searching'  # no warm start: the prior search runs, a few candidates per frame

# A locked (or tracking) pair whose previous pair cannot be tracked into it (a lost track,
# _track_lost): True drops the lock and searches in this pair, False warm-starts from the lock
# as before session 15. Measured (evaluate_trust cuts, tuning seeds 0-60, docs/BENCHMARKS.md
# round 16): re-lock later than 3 pairs after 4 cuts -> 1 (22, whose true plane the gate
# refuses), published 455 -> 475 of 488 pairs, correct 431 -> 457, wrong 0 -> 0.
SEARCH_ON_LOST_TRACK = True


@dataclass
class PipelineStats:
    """Counters since the pipeline was made."""

    frames: int = 0
    succeeded: int = 0
    failed: int = 0
    reinitialisations: int = 0
    resets: int = 0
    predictions: int = 0
    candidates: int = 0
    carried: int = 0  # pairs whose corners were carried from an earlier pair, not detected
    # Lock losses and refusals by kind (stream/refusals.py).
    refusals: RefusalCounts = field(default_factory=RefusalCounts)


class PlanePipeline:
    """Dominant-plane estimation over a stream of stereo pairs.

    The lock state machine: ``'locked'`` while frames give a plane (each warm-starts from
    the prediction, else the last homography); after a failed or suspicious estimate,
    ``'tracking'`` for up to ``pipeline.max_tracking_frames`` frames, carrying the last plane
    forward through the cameras' tracked motion; then ``'searching'``: the prior candidates are
    screened cheaply every frame and ``pipeline.search_candidates_per_frame`` of them refined,
    the best so far carried forward, until ``prior.refine_best`` have been tried.

    Args:
        config: The whole configuration (the node's parameters).
        counts: Where input problems are counted (default: a new
            :class:`~domplane_ros.stream.health.InputCounts`; a session passes its own).

    """

    def __init__(self, config: PlaneNodeConfig | None = None,
                 counts: InputCounts | None = None) -> None:
        """Start with no warm start: the first frames search the prior."""
        self.config = config if config is not None else PlaneNodeConfig()
        self.stats = PipelineStats()
        self._last_h: np.ndarray | None = None
        self._last_energy_per_point: float | None = None
        self.counts = counts if counts is not None else InputCounts()
        self.checks = PairChecks(self.counts)
        self._checks = AcceptanceChecks(self.counts, lambda: self.config)
        self._state = SEARCHING
        self._tracking_frames = 0
        self._photometric = False  # the lock is a plane of too few corners (photometric)
        # A lock dropped between pairs (reset, a changed prior): the next pair's lock loss.
        self._dropped: Refusal | None = None
        self._searcher = PlaneSearch(lambda: self.config, lambda: self._trust, self._checks,
                                     self.counts, lambda *args: self._warm.estimate(*args))
        self._tracker = FrameTracker()
        self._trust = TrustGate(self.config.verification, prior=self.config.prior,
                                mask=self.config.mask)
        self._warm = WarmFit(lambda: self.config, lambda: self._trust, self._work)
        self._challenge = LockChallenge(lambda: self.config, lambda: self._trust, self._work,
                                        self._checks, self._searcher.candidates)

    @property
    def last_homography(self) -> np.ndarray | None:
        """Return the last plane (or the one carried while tracking), or None."""
        return None if self._last_h is None else self._last_h.copy()

    @property
    def state(self) -> str:
        """Return the lock state: ``'locked'``, ``'tracking'`` or ``'searching'``."""
        return self._state

    def update_config(self, config: PlaneNodeConfig) -> None:
        """Use a new configuration from the next frame on, keeping the warm start.

        A changed prior, initial homography, ``verification.plane``, ``verification.scale``
        or ``verification.covisible`` drops the warm start (the last two change what a score
        measures). Other changed ``verification.*`` settings keep the lock with its score
        history and reference (:data:`~domplane_ros.stream.trust.LOCK_REFERENCE`): its scores
        are measured at the same working width over the same pixels, and a lock whose
        reference were dropped would take its next plane, slid or not, as the plane it
        started from.
        """
        old, new = self.config.verification, config.verification
        if (config.prior != self.config.prior
                or config.initial_homography != self.config.initial_homography
                or (new.plane, new.scale, new.covisible) != (old.plane, old.scale, old.covisible)):
            self.reset('a changed prior, initial homography, verification.plane, '
                       'verification.scale or verification.covisible dropped the warm start')
            self._checks.clear()
            self._searcher.prior_changed()
        if config.verification != self.config.verification:
            trust = TrustGate(config.verification, prior=config.prior, mask=config.mask)
            trust.take_lock(self._trust)
            self._trust = trust
        self._trust.prior = config.prior
        self._trust.mask = config.mask
        self.config = config

    def reset(self, why: str = 'the warm start was dropped (reset)') -> None:
        """Drop the warm start: the next frames search the prior.

        A lock dropped here is the next pair's lock loss (kind ``reset``, saying ``why``).
        """
        if self._last_h is not None or self._state != SEARCHING:
            self.stats.resets += 1
            self._dropped = Refusal(RESET, why)
        self._last_h = None
        self._last_energy_per_point = None
        self._state = SEARCHING
        self._tracking_frames = 0
        self._photometric = False
        self._searcher.stop()
        self._challenge.stop()
        self._tracker.clear()
        self._trust.reset()

    def process(self, left: np.ndarray, right: np.ndarray, stamp_ns: int,
                reset: bool = False, joint_speed: float | None = None,
                stream_gap_ns: int | None = None) -> FrameResult:
        """Estimate the plane for one stereo pair.

        Args:
            left: (H, W) uint8 left grey image.
            right: (H', W') uint8 right grey image.
            stamp_ns: The pair's stamp in nanoseconds; a stamp older than the last one (clock
                reset, bag loop) or more than ``pipeline.max_stamp_jump_s`` newer drops the
                warm start.
            reset: Drop the warm start before this frame.
            joint_speed: Largest head joint speed in rad/s, if known (None: no joint input).
            stream_gap_ns: The longest gap between consecutive pairs the cameras delivered
                since the last pair processed, when the caller drops pairs (the node's
                newest-wins hand-over while a search runs): the stamp jump is this gap, so a
                slow search does not drop the warm start it is building. None: the jump is
                measured from the last pair processed.

        Returns:
            The :class:`FrameResult`; it is never a non-finite homography. Pairs that
            :class:`~domplane_ros.stream.health.PairChecks` refuses (sizes differ, a frozen camera,
            a black or saturated frame), too few features, inliers with too little spread
            (``pipeline.min_inlier_spread``) and homographies outside the prior are failures
            with the reason, a mask of zeros and no homography; like any failure they move
            the lock state to ``'tracking'`` (then ``'searching'``).

        Raises:
            ValueError: If an image is not a 2-D uint8 array, or ``joint_speed`` is not
                finite.

        """
        t0 = time.perf_counter()
        _check_frame(left, right, joint_speed)
        check = self.checks.check(left, right, stamp_ns, self.config.pipeline, stream_gap_ns)
        if reset or check.reset:
            self.reset('; '.join(check.warnings) if check.reset and check.warnings
                       else 'the warm start was dropped before this pair (a reset pair)')
        dropped, self._dropped = self._dropped, None
        self.stats.frames += 1
        cfg = self.config
        fast = joint_speed is not None and abs(joint_speed) > cfg.pipeline.fast_joint_velocity
        if check.refused:
            return self._refused(left, stamp_ns, check.refused, check.warnings, t0, fast,
                                 dropped)
        work = (WorkingImage.of(left, cfg.features.max_width, cfg.features.max_megapixels),
                WorkingImage.of(right, cfg.features.max_width, cfg.features.max_megapixels))
        feats, track_pts, tracked, carried, spans = self._features(*work)
        motions = tracked.motions
        self.stats.carried += carried is not None
        t3 = time.perf_counter()
        # Every plane of this pair shares one shrink, from the working level.
        self._trust.begin_pair(left, right, (work[0].image, work[1].image, work[0].level))
        try:
            step = self._estimate(PairStep(left=left, right=right,
                                           track_lost=self._track_lost(tracked, feats),
                                           lock_lost=dropped),
                                  feats, motions, fast)
        finally:
            self._trust.end_pair()
        t4 = time.perf_counter()
        estimate, h, mask, parallax = self._publish(step, *work, feats)
        reason = '' if step.accepted else (step.reason or estimate.reason)
        if not step.accepted and reason.startswith(('too few left', 'too few right')):
            self.counts.add('too_few_features')
            reason += f' (left {texture_note(left)}; right {texture_note(right)})'
        if not step.keep_previous:
            self._tracker.keep(*work, track_pts, carried)
        self.stats.refusals.add(step.lock_lost, step.refusals, step.accepted)
        t5 = time.perf_counter()
        return FrameResult(stamp_ns=stamp_ns, ok=step.accepted, homography=h, mask=mask,
                           parallax=parallax, estimate=estimate,
                           left_points=feats.left_points,
                           right_points=feats.right_points, reinitialised=step.reinitialised,
                           reason=reason, state=self._state,
                           timings_ms=stage_timings_ms(t0, spans, t3, t4, t5,
                                                       step.challenge_s),
                           warnings=check.warnings, left_lines=feats.left_lines,
                           right_lines=feats.right_lines, warm_start=step.warm_start,
                           prediction=step.prediction, candidates=step.candidates,
                           fast_motion=fast, confidence=step.confidence,
                           refusals=tuple(step.refusals), lock_lost=step.lock_lost)

    def _estimate(self, step: PairStep, feats: Features,
                  motions: tuple[np.ndarray, np.ndarray] | None, fast: bool) -> PairStep:
        """Estimate this frame's plane as the lock state says: warm start, then search."""
        height, width = step.left.shape
        size = (width, height)
        # One two-step problem per frame: the right set's KD-tree, line matcher and refiner
        # serve every start tried on it (warm, wide, best so far, initial, prior candidates).
        problem = self._problem(feats)
        if self._state != SEARCHING:
            self._track_or_lock(step, feats, problem, size, motions, fast)
        if self._state == SEARCHING:
            self._search_step(step, feats, problem, size, motions)
        return step

    def _publish(self, step: PairStep, left: WorkingImage, right: WorkingImage, feats: Features
                 ) -> tuple[PlaneEstimate | FailedEstimate, np.ndarray | None, np.ndarray,
                            np.ndarray | None]:
        """Return the frame's estimate, homography, mask and parallax; keep an accepted plane.

        The mask is computed on the working level (``mask.scale`` of it) and scaled up to the
        full image, so its cost grows with the working resolution, not the camera's; the
        residual parallax keeps the mask's working scale, in full-resolution pixels.
        """
        estimate = step.estimate if step.estimate is not None else FailedEstimate(step.reason)
        parallax = None
        if step.accepted:
            h = estimate.homography
            scale = left.scale
            out = level_mask(left.image, right.image, scale, h, self.config.mask,
                             self.config.prior)
            mask, parallax = full_mask(left, out.labels), out.parallax
            if scale != 1.0:
                # Working-level pixels to full-resolution pixels (-1: not measured).
                parallax = np.where(parallax >= 0, parallax * np.float32(scale),
                                    parallax).astype(np.float32)
            self._last_h = h
            self._last_energy_per_point = (None if estimate.potential == PHOTOMETRIC else
                                           estimate.final_energy / max(feats.n_left, 1))
            self.stats.succeeded += 1
        else:
            h = None
            mask = np.zeros(left.full.shape, np.uint8)
            self.stats.failed += 1
        return estimate, h, mask, parallax

    def _refused(self, left: np.ndarray, stamp_ns: int, reason: str,
                 warnings: tuple[str, ...], t0: float, fast: bool,
                 dropped: Refusal | None) -> FrameResult:
        """Return the failed frame of a refused pair: a failure like any other.

        The plane is carried as in the ``'tracking'`` state (or the search goes on); the
        refused images are not kept for tracking. ``dropped``: the lock dropped before it.
        """
        self.stats.failed += 1
        step = PairStep(keep_previous=True, reason=reason, lock_lost=dropped)
        if self._state != SEARCHING:
            self._lose_frame(step, None)
        self.stats.refusals.add(step.lock_lost, (), False)
        empty = np.zeros((0, 2), np.float64)
        total_ms = 1e3 * (time.perf_counter() - t0)
        return FrameResult(stamp_ns=stamp_ns, ok=False, homography=None,
                           mask=np.zeros(left.shape, np.uint8), estimate=FailedEstimate(reason),
                           left_points=empty, right_points=empty, reinitialised=False,
                           reason=reason, state=self._state,
                           timings_ms={'features': 0.0, 'tracking': 0.0, 'estimate': 0.0,
                                       'challenge': 0.0, 'mask': 0.0, 'total': total_ms},
                           warnings=warnings, fast_motion=fast, lock_lost=step.lock_lost)

    def _tracking_points(self, left: WorkingImage, right: WorkingImage,
                         corners: tuple[np.ndarray, np.ndarray]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Return the working-level corners to track from (detected if only lines are used)."""
        if not self.config.tracking.enabled or self.config.features.kind != 'lines':
            return corners
        features = level_features(self.config.features, left.level)
        return detect_corners(left.image, features), detect_corners(right.image, features)

    # --- Features and temporal prediction ------------------------------------------------
    def _features(self, left: WorkingImage, right: WorkingImage
                  ) -> tuple[Features, tuple[np.ndarray, np.ndarray], Tracked,
                             tuple[np.ndarray, np.ndarray] | None, tuple[float, float]]:
        """Return the pair's features, working-level corners, its view of the previous pair.

        Also, for corners carried from an earlier pair (:mod:`domplane_ros.stream.motion`),
        which detected corner each is (None: detected in this pair), and the seconds spent on
        features and on tracking.
        """
        searching = self._state == SEARCHING
        t0 = time.perf_counter()
        tracked = self._tracker.track(
            left, right, self.config,
            motion=not searching or self._searcher.has_best,
            carry=not searching)
        t1 = time.perf_counter()
        carried = None
        if tracked.corners is not None and tracked.alive is not None:
            carried = carried_features(left, right, tracked.corners, tracked.counts,
                                       self.config)
        if carried is not None:
            feats, corners, kept = carried
            alive = (tracked.alive[0][kept[0]], tracked.alive[1][kept[1]])
            return feats, corners, tracked, alive, (time.perf_counter() - t1, t1 - t0)
        feats, corners = detect_features(left, right, self.config)
        corners = self._tracking_points(left, right, corners)
        return feats, corners, tracked, None, (time.perf_counter() - t1, t1 - t0)

    def _track_lost(self, tracked: Tracked, feats: Features) -> bool:
        """Return whether this pair does not continue the previous one (a cut).

        The previous pair's corners could not be tracked into it (``tracked.lost``) although
        it has corners enough to track (``tracking.min_tracks`` in each image): a blank or
        textureless pair (a drop-out) says nothing, as in :meth:`_view_changed`.
        """
        least = self.config.tracking.min_tracks
        return tracked.lost and min(feats.n_left, feats.n_right) >= least

    # --- Locked and tracking ---------------------------------------------------------------
    def _track_or_lock(self, step: PairStep, feats: Features, problem: TwoStep | FailedEstimate,
                       size: tuple[int, int], motions: tuple[np.ndarray, np.ndarray] | None,
                       fast: bool) -> None:
        assert self._last_h is not None
        if step.track_lost and SEARCH_ON_LOST_TRACK:
            # The previous pair cannot be tracked into this one: the view jumped (a cut). The
            # lock is no warm start here (it slid onto near planes of the new floor, 2.65 and
            # 4.48 px off, and passed the gate): search in this pair.
            self._start_search(step, step.refuse(
                CUT, 'lost track: the previous pair cannot be tracked into this one'))
            return
        prediction = propagate(self._last_h, motions)
        if prediction is not None and self._checks.bounds_reason(prediction, size, count=False):
            prediction = None
        step.prediction = prediction
        if prediction is not None:
            self.stats.predictions += 1
        # The last homography is only tried without a prediction: when the cameras moved, it
        # is stale, and a stale start can slide into a look-alike.
        starts = [('prediction', prediction) if prediction is not None
                  else ('last', self._last_h)]
        reason = few_corners = self._checks.too_few_reason(feats)
        for name, init in starts if not reason else ():
            # Plain first (a good start costs nothing more); where that is refused, once more
            # with the potential graduated from the same start (a far start's wide basin).
            tries = (False, True) if can_widen(self.config.estimator) else (False,)
            outcomes = []
            for widen in tries:
                estimate = self._warm.estimate(problem, init,
                                               fast and prediction is None, widen)
                if not widen:
                    estimate = self._warm.anchored(problem, init, estimate)
                outcomes.append((estimate, *self._warm_check(step, estimate, feats, size,
                                                             fast, count=not widen)))
                if not outcomes[-1][1]:
                    break
            estimate, reason, verdict = outcomes[-1] if not outcomes[-1][1] else outcomes[0]
            if len(outcomes) > 1 and not reason:
                estimate, verdict = self._warm.kept_start(step, problem, init, estimate, verdict)
            step.estimate, step.warm_start = estimate, name
            if verdict is not None and not verdict.accepted:
                # A verified lock does not slide into a look-alike: search at once.
                self._start_search(step, step.refuse(verdict.lock_refusal or GATE,
                                                     verdict.reason))
                return
            if not reason:
                self._verified(step, estimate, verdict)
                started = time.perf_counter()
                if self._challenge_step(step, verdict, problem, feats, size, motions):
                    step.challenge_s = time.perf_counter() - started
                return
        if reason and reason != few_corners:
            step.refuse(ESTIMATE, reason)
        # A plane of few corners (too few now, or a photometric lock): refine it photometrically.
        few = self._photometric or reason == few_corners
        if reason and few:
            start = prediction if prediction is not None else self._last_h
            verdict = self._photometric_lock(step, start, size)
            if verdict is not None and verdict.accepted:
                return
            if verdict is not None:
                # Refused: carried as 'tracking' below (a photometric lock, or a pair the view
                # change does not refute) with the warm reason; the refusal is kept.
                step.refusals.append(Refusal(verdict.lock_refusal or GATE, verdict.reason))
            if not self._photometric and self._view_changed(step, start, verdict):
                # A corner lock whose corners are gone, and a textured image that neither the
                # lock nor its photometric refinement explains: the view changed (a cut to a
                # scene of few corners). Search at once, as a refused warm estimate does,
                # instead of carrying it. Measured: cut tuning seed 186 (9 corners after the
                # cut) re-locked after 4 pairs, the lock carried 2 pairs as 'tracking' first.
                # A blank or textureless pair (a drop-out) says nothing: carried as before.
                step.reason = reason
                step.refusals.append(view_changed(reason))
                self._start_search(step, step.refusals[-1])
                return
        step.reason = reason
        self._lose_frame(step, prediction)

    def _view_changed(self, step: PairStep, start: np.ndarray, refined: Verdict | None
                      ) -> bool:
        """Return whether the pair's texture refutes the lock (too few corners to tell).

        The lock's photometric refinement (``refined``, None if it gave no plane) or else the
        lock itself (``start``, carried to this pair) is refused for explaining too little of
        a textured image (:data:`~domplane_ros.core.verification.REASON_LOW_SUPPORT`); not
        for too little texture or overlap.
        """
        if refined is None:
            refined = self._trust.judge(step.left, step.right, start,
                                        self.config.features.roi, locked=True)
        return refined.verification.reason == REASON_LOW_SUPPORT

    def _photometric_lock(self, step: PairStep, start: np.ndarray, size: tuple[int, int]
                          ) -> Verdict | None:
        """Too few corners while locked: publish the start refined photometrically if verified.

        Returns the gate's verdict on the refined start (accepted: published), or None if the
        refinement gave no plane.
        """
        planes = self._work().photometric_planes(step, [start], size)
        if not planes:
            return None
        verdict = self._trust.judge(step.left, step.right, planes[0].homography,
                                    self.config.features.roi, locked=True)
        if verdict.accepted:
            self._verified(step, planes[0], verdict)
        return verdict

    def _warm_check(self, step: PairStep, estimate: PlaneEstimate | FailedEstimate,
                    feats: Features, size: tuple[int, int], fast: bool, count: bool
                    ) -> tuple[str, Verdict | None]:
        """Return why a warm estimate is refused ('' if not) and the verification's verdict."""
        if not estimate.ok:
            return estimate.reason, None
        # A fast head (joint input) may change the energy legitimately: no energy check.
        reason = self._checks.suspicion_reason(estimate, feats.n_left, size,
                                               self._last_energy_per_point, energy=not fast,
                                               count=count)
        reason = reason or self._checks.input_problem(estimate, feats.left_points, size, count)
        if reason:
            return reason, None
        verdict = self._trust.judge(step.left, step.right, estimate.homography,
                                    self.config.features.roi, locked=True)
        return verdict.reason, verdict

    def _verified(self, step: PairStep, estimate: PlaneEstimate, verdict: Verdict) -> None:
        """Publish a verified plane: lock on it."""
        step.estimate, step.accepted, step.confidence = estimate, True, verdict.confidence
        self._photometric = estimate.potential == PHOTOMETRIC
        if self._photometric:
            step.warm_start = PHOTOMETRIC
        self._trust.record(verdict)
        self._state = LOCKED
        self._searcher.stop()
        self._tracking_frames = 0

    def _challenge_step(self, step: PairStep, lock: Verdict, problem: TwoStep | FailedEstimate,
                        feats: Features, size: tuple[int, int],
                        motions: tuple[np.ndarray, np.ndarray] | None) -> bool:
        """Run the lock's challenge task of this pair (stream/lock_challenge.py); lock on a winner.

        The lock was verified in this pair already (``lock``). Returns whether a task ran.
        """
        ran, won = self._challenge.step(step, lock, problem, feats, size, motions)
        if won is not None:
            self._verified(step, *won)
        return ran

    def _work(self) -> CandidateWork:
        """Return the candidate work on this pair's settings, gate and checks."""
        return CandidateWork(self.config, self._trust, self._checks)

    def _lose_frame(self, step: PairStep, prediction: np.ndarray | None) -> None:
        """Failed or suspicious: carry the plane forward (tracking) or give up (searching)."""
        self._tracking_frames += 1
        if self._tracking_frames <= self.config.pipeline.max_tracking_frames:
            self._state = TRACKING
            if prediction is not None:
                self._last_h = prediction
            else:
                # The carried plane still belongs to the previous frame: track from there.
                step.keep_previous = True
            return
        self._start_search(step, tracking_ended(self._tracking_frames - 1, step.reason))

    def _problem(self, feats: Features) -> TwoStep | FailedEstimate:
        """Return the two-step iteration over this frame's features, or why there is none."""
        lines = self.config.features.kind != 'points'
        return TwoStep.from_features(
            feats.left_points, feats.right_points, feats.left_lines if lines else None,
            feats.right_lines if lines else None, self.config.estimator.line_weight)

    # --- Searching -------------------------------------------------------------------------
    def _start_search(self, step: PairStep, lost: Refusal) -> None:
        """Drop the lock (``lost``: why, kept as the pair's lock loss): search from now on."""
        step.lock_lost = lost
        self._state = SEARCHING
        self._trust.lock_lost()
        self._tracking_frames = 0
        self._last_h = None
        self._last_energy_per_point = None
        self._searcher.stop()
        self._challenge.stop()

    def _search_step(self, step: PairStep, feats: Features, problem: TwoStep | FailedEstimate,
                     size: tuple[int, int], motions: tuple[np.ndarray, np.ndarray] | None
                     ) -> None:
        """Run the search's step (stream/search.py); lock on the plane it verified, if any."""
        if not self._searcher.running:
            self.stats.reinitialisations += 1
        found = self._searcher.step(step, feats, problem, size, motions)
        self.stats.candidates += step.candidates
        if found is not None:
            self._verified(step, *found)


def _check_frame(left: np.ndarray, right: np.ndarray, joint_speed: float | None) -> None:
    """Raise ValueError for an image that is not 2-D uint8 or a non-finite joint speed."""
    check_gray(left, 'left')
    check_gray(right, 'right')
    if joint_speed is not None and not math.isfinite(joint_speed):
        raise ValueError(f'joint_speed must be finite, got {joint_speed!r}')
