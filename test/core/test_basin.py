"""The warm-start basin's multi-start (core/basin.py): which result it returns."""

from __future__ import annotations

from domplane_ros.config import EstimatorConfig
from domplane_ros.core import basin
from domplane_ros.core.estimator import FailedEstimate, TwoStep
from domplane_ros.sim.synthetic import displace_homography, plane_error_px, point_scene
import numpy as np


def _scene(seed=30_000):
    rng = np.random.default_rng(seed)
    scene = point_scene(rng, 300)
    return TwoStep.from_features(scene.left, scene.right), scene, rng


def test_every_start_failing_gives_the_first_failure_the_start_s_own():
    # The run from the start itself comes first; a failure is false in a boolean context, so
    # keeping it must not depend on truthiness (it once returned the last moved start's).
    problem, scene, rng = _scene()
    h0 = displace_homography(scene.homography, 20.0, rng)
    starts = []

    def failing(start):
        starts.append(start)
        return FailedEstimate(f'run {len(starts)}')

    result = basin.far_start(problem, h0, failing, EstimatorConfig())
    assert not result.ok and len(starts) == 5
    assert result.reason == 'run 1' and np.array_equal(starts[0], h0)


def test_a_successful_plain_run_stands_when_every_graduated_run_fails():
    problem, scene, rng = _scene(30_001)
    h0 = displace_homography(scene.homography, 2.0, rng)
    options = EstimatorConfig()
    plain = problem.estimate(h0, options, widen=False)
    assert plain.ok
    assert plane_error_px(plain.homography, scene.homography, scene.left[scene.on_plane]) < 1.0
    result = basin.far_start(problem, h0, lambda start: FailedEstimate('no'), options, plain)
    assert result is plain
