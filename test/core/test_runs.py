"""A run of the two-step iteration repeated with a smaller tolerance goes on where it stopped."""

from __future__ import annotations

from dataclasses import replace

from domplane_ros.config import EstimatorConfig, PriorConfig
from domplane_ros.core import estimator
from domplane_ros.core.estimator import TwoStep
from domplane_ros.core.prior import plane_homography, prior_candidates, swapped_candidates
from domplane_ros.sim.synthetic import displace_homography, point_scene
import numpy as np
import pytest

SHORT = EstimatorConfig(tolerance_px=0.1)
FULL = EstimatorConfig()  # 0.05 px


def _scene(seed):
    rng = np.random.default_rng(seed)
    h = plane_homography(650, 0.2, 30, 1.0, 640, 480)
    scene = point_scene(rng, 400, homography=h)
    return scene, displace_homography(h, 8.0, rng)


def _counted(problem):
    """Count the global steps (one a round, and the polish's) of ``problem``."""
    calls = [0]
    refine = problem.refiner.refine

    def counting(*args, **kwargs):
        calls[0] += 1
        return refine(*args, **kwargs)
    problem.refiner.refine = counting
    return calls


def _same(a, b):
    assert a.homography.tobytes() == b.homography.tobytes()
    assert a.iterations == b.iterations
    assert a.energy_trace.tobytes() == b.energy_trace.tobytes()
    assert np.array_equal(a.stage_trace, b.stage_trace)
    assert np.array_equal(a.inliers, b.inliers) and np.array_equal(a.matches, b.matches)
    assert a.residuals_px.tobytes() == b.residuals_px.tobytes()
    assert a.converged == b.converged


@pytest.mark.parametrize('potential,widen,extrapolate', [
    ('truncated_quadratic', False, False), ('truncated_quadratic', True, False),
    ('geman_mcclure', False, False), ('truncated_quadratic', False, True),
    ('truncated_quadratic', True, True)])
def test_a_smaller_tolerance_goes_on_from_the_stop_with_a_fresh_runs_results(potential, widen,
                                                                             extrapolate):
    short_opts, full_opts = (replace(SHORT, potential=potential),
                             replace(FULL, potential=potential))
    went_on = saved = 0
    for seed in range(6):
        scene, start = _scene(seed)
        fresh_problem = TwoStep.from_features(scene.left, scene.right)
        fresh_calls = _counted(fresh_problem)
        fresh = fresh_problem.estimate(start, full_opts, widen=widen, extrapolate=extrapolate)
        problem = TwoStep.from_features(scene.left, scene.right)
        short = problem.estimate(start, short_opts, widen=widen, extrapolate=extrapolate)
        calls = _counted(problem)
        again = problem.estimate(start, full_opts, widen=widen, extrapolate=extrapolate)
        assert fresh.ok and short.ok and again.ok
        _same(again, fresh)
        if len(set(fresh.stage_trace)) == 1:
            # One stage: only the rounds after the short run's stop are iterated (and the
            # polish, as in any run).
            assert calls[0] == fresh_calls[0] - short.iterations
        assert calls[0] <= fresh_calls[0]
        went_on += fresh.iterations > short.iterations
        saved += calls[0] < fresh_calls[0]
    assert went_on >= 3 and saved >= 3  # short runs stopped early; the rounds were re-used


def test_a_larger_tolerance_or_other_settings_run_afresh():
    scene, start = _scene(3)
    fresh = TwoStep.from_features(scene.left, scene.right).estimate(start, SHORT, widen=False)
    problem = TwoStep.from_features(scene.left, scene.right)
    problem.estimate(start, FULL, widen=False)
    _same(problem.estimate(start, SHORT, widen=False), fresh)
    other = replace(FULL, threshold_px=2.0)
    fresh_other = TwoStep.from_features(scene.left, scene.right).estimate(start, other,
                                                                          widen=False)
    _same(problem.estimate(start, other, widen=False), fresh_other)
    with pytest.raises(ValueError, match='extrapolate needs widen'):
        problem.estimate(start, FULL, extrapolate=True)
    # A plain run's stop is not an extrapolated run's (and the other way round).
    fresh_x = TwoStep.from_features(scene.left, scene.right).estimate(start, FULL, widen=False,
                                                                      extrapolate=True)
    _same(problem.estimate(start, FULL, widen=False, extrapolate=True), fresh_x)


def test_the_same_candidates_are_screened_once(monkeypatch):
    scene, _ = _scene(5)
    candidates = swapped_candidates(prior_candidates(PriorConfig(), 640, 480))
    problem = TwoStep.from_features(scene.left, scene.right)
    first = problem.screening_energy(candidates, 4.0)
    calls = [0]
    screen = estimator.screen_candidates

    def counting(*args):
        calls[0] += 1
        return screen(*args)
    monkeypatch.setattr(estimator, 'screen_candidates', counting)
    first[:] = -1.0  # the caller's copy; the kept energies must not change with it
    again = problem.screening_energy(candidates, 4.0)
    fresh = TwoStep.from_features(scene.left, scene.right).screening_energy(candidates, 4.0)
    assert again.tobytes() == fresh.tobytes() and calls[0] == 1
    problem.screening_energy(candidates, 3.0)  # another truncation is screened
    assert calls[0] == 2
