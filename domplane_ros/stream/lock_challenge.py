"""The lock's challenge run pair by pair: one task per locked pair, a winner replaces the lock.

Every ``verification.challenge_period`` locked pairs a :class:`~domplane_ros.stream.challenge.
Challenge` starts (its tasks and their order are described there). :class:`LockChallenge`
runs its next task on each locked pair of the pipeline
(:class:`~domplane_ros.stream.pipeline.PlanePipeline`): the coarse alignment's steps
(:meth:`~domplane_ros.stream.coarse_planes.CoarsePlanes.coarse_steps`), the prior's short
screening, or one start refined on the pair's features, checked, verified
(:meth:`~domplane_ros.stream.trust.TrustGate.pick`) and taken if it beats the lock
(:meth:`~domplane_ros.stream.trust.TrustGate.beats`), once finished, like a search's winner
(:meth:`~domplane_ros.stream.candidates.CandidateWork.finished`), and only if it is a ground
plane of the prior (:meth:`~domplane_ros.stream.trust.TrustGate.ground_refusal`). The
pipeline publishes the winner and locks on it.
"""

from __future__ import annotations

from typing import Callable

from domplane_ros.config import PlaneNodeConfig
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.features import Features
from domplane_ros.core.result import FailedEstimate, PlaneEstimate
from domplane_ros.stream.acceptance import AcceptanceChecks
from domplane_ros.stream.candidates import CandidateWork
from domplane_ros.stream.challenge import (Challenge, COARSE, COARSE_START, COARSE_STEP,
                                           PRIOR_START, PRIOR_STARTS, SCREEN, Task)
from domplane_ros.stream.frame import PairStep
from domplane_ros.stream.refusals import challenge_refused, challenger_won
from domplane_ros.stream.trust import TrustGate
from domplane_ros.stream.verdict import CHALLENGE_MARGIN, Verdict
import numpy as np

__all__ = ['LockChallenge']

# Whether a task ran in this pair, and the challenger that won, finished (to publish), if any.
Outcome = tuple[bool, tuple[PlaneEstimate, Verdict] | None]


class LockChallenge:
    """The challenge of the lock in progress, on the pipeline's current settings and gate.

    Args:
        config: Returns the pipeline's current configuration.
        trust: Returns the pipeline's trust gate.
        work: Returns the candidate work on this pair's settings, gate and checks.
        checks: The pipeline's acceptance checks.
        candidates: The prior's (N, 3, 3) candidates for images of a size (width, height).

    """

    def __init__(self, config: Callable[[], PlaneNodeConfig], trust: Callable[[], TrustGate],
                 work: Callable[[], CandidateWork], checks: AcceptanceChecks,
                 candidates: Callable[[tuple[int, int]], np.ndarray]) -> None:
        """Start with no challenge in progress."""
        self._config = config
        self._trust = trust
        self._work = work
        self._checks = checks
        self._candidates = candidates
        self._challenge: Challenge | None = None

    def stop(self) -> None:
        """End the challenge in progress, if any (a lost lock, a reset)."""
        self._challenge = None

    def step(self, step: PairStep, lock: Verdict, problem: TwoStep | FailedEstimate,
             feats: Features, size: tuple[int, int],
             motions: tuple[np.ndarray, np.ndarray] | None) -> Outcome:
        """Every few locked pairs, let other planes challenge the lock, one task per pair.

        See :mod:`domplane_ros.stream.challenge`. The lock was verified in this pair already
        (``lock``); only the challengers are. A challenger that wins sets the pair's warm
        start (``'challenger'``) and lock loss, resets the gate's lock history and ends the
        challenge; the caller locks on it.

        Returns:
            Whether a task ran in this pair, and the winner finished with its verdict (None
            if none won).

        """
        if isinstance(problem, FailedEstimate) or step.estimate is None:
            return False, None
        trust, config = self._trust(), self._config()
        if self._challenge is None:
            if not trust.challenge_due():
                return False, None
            self._challenge = Challenge()
        else:
            self._challenge.follow(motions)
        task = self._challenge.next_task()
        if task is None:
            self._challenge = None
            return False, None
        if task.kind == COARSE:
            # The alignment's first step (its forward flow) and the screening share a pair.
            steps = trust.planes.coarse_steps(step.left, step.right)
            if steps is not None:
                self._challenge.align(Task(COARSE_STEP, steps=steps),
                                      step.estimate.homography, size)
            if self._challenge.take(SCREEN):
                task = Task(SCREEN)
        elif task.kind == COARSE_STEP:
            self._challenge.align(task, step.estimate.homography, size)
        if task.kind == SCREEN:
            candidates = self._candidates(size)
            self._challenge.add_prior_starts(candidates[i] for i in problem.best_screened(
                candidates, config.prior.screen_threshold_px, PRIOR_STARTS))
        elif task.kind in (COARSE_START, PRIOR_START):
            won = self._challenger(step, task, lock, problem, feats, size)
            if won is not None:
                self._challenge = None
                return True, won
        if self._challenge.done:
            self._challenge = None
        return True, None

    def _challenger(self, step: PairStep, task: Task, lock: Verdict, problem: TwoStep,
                    feats: Features, size: tuple[int, int]
                    ) -> tuple[PlaneEstimate, Verdict] | None:
        """Refine one start, verify it; return it finished if it beats the lock, else None."""
        trust, config = self._trust(), self._config()
        options = self._work().options if task.kind == PRIOR_START else config.estimator
        # Extrapolated: most features are outliers to a challenger's start and the plain
        # iteration creeps (docs/speed.md round 15).
        result = problem.estimate(task.start, options, widen=False, extrapolate=True)
        if not result.ok or self._checks.rejection_reason(
                result, feats, size, bounds=task.kind == PRIOR_START):
            return None
        best, verdict, _ = trust.pick(step.left, step.right, [result], config.features.roi)
        if best is None or verdict is None or not trust.beats(verdict, lock):
            return None
        done = self._work().finished(step, problem, feats, size, best, verdict)
        refused = (trust.ground_refusal(done[0].homography, *size, done[1].verification)
                   or trust.near_field_refusal(done[0].homography, config.features.roi))
        if refused:
            step.refusals.append(challenge_refused(refused))
            return None
        step.warm_start = 'challenger'
        step.lock_lost = challenger_won(verdict.peak_score, CHALLENGE_MARGIN, lock.peak_score)
        trust.reset()
        return done
